"""darkread: read text in the dark with a foveated event camera.

The top-level folders ``edge/``, ``cloud/``, ``proto/``, ``stitch/`` and ``models/`` are installed as
``darkread.edge``, ``darkread.cloud``, ``darkread.proto``, ``darkread.stitch`` and ``darkread.models``.
"""

__version__ = "0.1.0"
