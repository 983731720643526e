"""The lab's train."""
