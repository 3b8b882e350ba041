"""The HTTP layer (FastAPI): routes, job backends (embedded or Celery queue), problem+json errors."""
