"""The lab's synth."""
