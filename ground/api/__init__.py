"""Ground app HTTP API (FastAPI): flight store, resumable checksummed upload, processing jobs, reports."""
