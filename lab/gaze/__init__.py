"""Gaze on its own: real readers' data, line assignment of fixations, the ``darkread gaze`` command."""
