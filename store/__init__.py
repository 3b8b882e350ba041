"""Job records and results in a database through SQLAlchemy (SQLite file in embedded mode).

``models`` holds the tables, ``jobs`` the :class:`~store.jobs.JobStore` the API uses, ``migrations``
the Alembic scripts (applied by :meth:`~store.jobs.JobStore.migrate` when the API starts).
"""
