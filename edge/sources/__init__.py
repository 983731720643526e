"""Event sources: the live camera and recordings, all behind ``EventSource`` (see ``base``)."""
