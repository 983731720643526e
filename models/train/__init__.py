"""Training, export and evaluation of the binary reconstruction network (needs the `train` extra: torch)."""
