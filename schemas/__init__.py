"""pydantic v2 models of the API: system specs, job requests and views, results, problems, settings."""
