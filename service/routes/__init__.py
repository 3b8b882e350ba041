"""HTTP routes: health, the systems catalog, jobs."""
