"""The one exception tree of darkread, drawn once.

Every error darkread raises on purpose derives from ``DarkreadError``, so a caller (the command
line, the daemon, a test) can tell "darkread refused this input or could not do this" from a bug.
The base lives here, in the top package, because every component may import it: ``proto/`` and
``stitch/`` stay pure (this module imports nothing), and neither depends on ``edge/`` or ``cloud/``.
Each component keeps its own errors in its own ``errors.py``::

    DarkreadError                      darkread/core/errors.py
     ├── RecordingError                edge/errors.py: a recording (directory or file) cannot be used
     │    ├── RawFormatError           RAW header unknown or inconsistent
     │    ├── CorruptRawError          bytes that cannot be decoded (names file and byte offset)
     │    ├── GazeCsvError             eye-gaze CSV missing columns or malformed (names file and line)
     │    ├── ImuCsvError              head-motion (IMU) CSV missing columns or malformed (names file and line)
     │    └── CalibrationError         calibration.json missing keys or impossible values
     ├── DeviceError                   edge/errors.py: the event camera cannot be opened or answers wrongly
     │    └── TreuzellError            edge/sources/evk4/treuzell.py: the EVK4's control protocol failed
     │         └── CommandFailedError  the camera answered a command with an error status
     ├── CloudRefusedError             edge/errors.py: the cloud refused the uplink (also a ConnectionError)
     ├── ModelError                    edge/errors.py: the ONNX model is missing or has the wrong shape
     ├── RunError                      edge/errors.py: the edge ran but failed (cloud refused the stream,
     │    │                            the replay crashed, a replay made no frames)
     │    └── UndeliveredError         the run ended with messages the cloud never took (exit 3)
     ├── SpoolError                    edge/errors.py: the spool cannot be opened or written: read-only or
     │                                 full disk, held by another edge (names the spool and the cause; exit 4)
     ├── ImageCodecError               darkread/core/image_codec.py: an image that cannot be encoded or decoded
     ├── ProtocolError                 proto/errors.py: a wire message that cannot be accepted (close 4400)
     │    ├── MessageTooLargeError     more bytes than the receiver allows (1009)
     │    ├── MalformedMessageError    not msgpack, trailing bytes, or not a map (4400)
     │    ├── UnknownMessageTypeError  ``type`` missing or not one we know (4400)
     │    ├── InvalidFieldError        a field missing, of the wrong type or out of range (4400)
     │    │    └── BadMaskError        mask ``shape``/``bits`` inconsistent (4422)
     │    ├── VersionMismatchError     ``hello.v`` is not a protocol version we speak (4409)
     │    ├── UnexpectedMessageError   valid, but not allowed now, e.g. frame before hello (4401)
     │    ├── AuthenticationError      missing or wrong API key in ``hello.token`` (1008)
     │    ├── ForbiddenError           the key lacks the scope, or names another device or stream (4403)
     │    ├── SessionMismatchError     hello changes an existing session's mode or geometry (4412)
     │    ├── SeqGapError              seq not contiguous after the last one (4416)
     │    └── SessionBusyError         another stream is connected to the session (4423)
     └── CloudError                    cloud/errors.py: the cloud service could not do what was asked
          ├── StoreError               a session's frames or pages could not be stored or read
          │    ├── UnknownSessionError a write named a session never opened (or deleted)
          │    ├── SessionOwnedError   the session belongs to another device or stream
          │    └── SessionShapeError   a hello with another mode or geometry than the session's
          ├── NoPageError              the session has nothing to read yet (or not the page asked for)
          ├── DataDirError             the data directory is unusable or held by another process
          ├── ConfidenceModelError     the line-confidence model file is unreadable or not one
          ├── ServiceStartError        the service did not come up
          ├── OcrError                 an OCR engine failed (``retryable`` says whether to try again)
          │    └── OcrUnavailableError the engine is not installed or not configured
          └── SpeechError              the speech engine failed or timed out (spoken answers)
               └── SpeechUnavailableError  espeak-ng is not installed

The lab's own errors (``darkread.lab``: fixtures, evaluation) are not the product's and stay in its
modules, e.g. ``PostgresUnavailable`` in ``lab/fixtures/pg_server.py``.

Built-in exceptions are used where their meaning fits: ``FileNotFoundError``/``OSError`` for files
and sockets, ``ValueError`` for bad arguments. The ``darkread`` command turns all of these into one
line on stderr and a non-zero exit (``darkread/cli.py``): 1, or the error's ``exit_code``.
"""

from __future__ import annotations


class DarkreadError(Exception):
    """Base of every error darkread raises on purpose."""

    exit_code: int = 1  # the ``darkread`` command's exit status for this error (a subclass may say more)
