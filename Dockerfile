# One image for both sides of darkread: the cloud service and (for demos) a replaying edge.
#
#   docker build -t darkread .
#   docker compose up            # cloud + an edge replaying the shipped sample recording
#
# The container listens on 0.0.0.0, so it needs a key: without DARKREAD_API_KEY (or a keys file
# in /data, `darkread cloud keys add`) the service refuses to start and says so.
#   docker run -e DARKREAD_API_KEY=$(openssl rand -hex 16) -p 127.0.0.1:8000:8000 darkread
#
# CPU only; no PyTorch (training is not part of the image). espeak-ng speaks the answers (ask with
# Accept: audio/wav). Tesseract is optional: build with --build-arg WITH_TESSERACT=1 to add it
# (DARKREAD_OCR_BACKEND=tesseract).
FROM python:3.11-slim-bookworm

ARG WITH_TESSERACT=0
ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    OMP_THREAD_LIMIT=1

RUN apt-get update && apt-get install -y --no-install-recommends espeak-ng \
    && if [ "$WITH_TESSERACT" = "1" ]; then \
        apt-get install -y --no-install-recommends tesseract-ocr tesseract-ocr-eng; \
    fi \
    && rm -rf /var/lib/apt/lists/*

WORKDIR /app
# The source tree (see .dockerignore) stays in /app: the edge replays
# /app/darkread/data/sample_recording from it.
COPY . .
RUN pip install "setuptools>=69" wheel \
    && pip install ".[cloud,edge]" \
    && useradd --create-home --uid 10001 darkread \
    && mkdir -p /data /spool && chown darkread /data /spool
USER darkread

EXPOSE 8000
VOLUME ["/data"]
HEALTHCHECK --interval=10s --timeout=5s --start-period=30s --retries=3 \
    CMD python -c "import urllib.request,sys; sys.exit(urllib.request.urlopen('http://127.0.0.1:8000/healthz', timeout=4).status != 200)"
CMD ["darkread", "cloud", "serve", "--host", "0.0.0.0", "--port", "8000", "--data-dir", "/data"]
