"""The darkread cloud service: websocket ingest, durable storage, stitching and OCR (FastAPI)."""
