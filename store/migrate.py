"""``python -m store.migrate``: bring the job store to the newest schema, then exit.

The store is the one the API and the workers use (:attr:`schemas.settings.Settings.store_url`:
``DATABASE_URL``, else queue mode's local PostgreSQL, else embedded mode's SQLite file), unless
``--url`` names another. The API and the workers migrate on their own when they start (under
PostgreSQL's advisory lock, so at once is safe); this command is for a deployment's migrations step
(the Kubernetes Job in ``deploy/k8s/base/migrate-job.yaml``), so that a schema change fails there,
visibly, before the new pods start.

Exit status 0 when the schema is at the newest revision, 1 when the migration failed (the error is
printed, without the URL's password).
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence

from sqlalchemy.engine import make_url

from schemas.settings import Settings


def current_revision(url: str) -> str | None:
    """The Alembic revision of the store at ``url`` (None: not migrated yet).

    Parameters
    ----------
    url
        The store's SQLAlchemy URL.

    Returns
    -------
    str or None
        The revision in the store's ``alembic_version`` table.
    """
    from alembic.runtime.migration import MigrationContext

    from store.jobs import make_engine

    engine = make_engine(url)
    try:
        with engine.connect() as connection:
            revision: str | None = MigrationContext.configure(connection).get_current_revision()
            return revision
    finally:
        engine.dispose()


def migrate(url: str, ttl_s: int) -> str | None:
    """Create the database if missing (PostgreSQL) and upgrade its schema to the newest revision.

    Parameters
    ----------
    url
        The store's SQLAlchemy URL.
    ttl_s
        The store's record lifetime (seconds); unused by the migration, required by the store.

    Returns
    -------
    str or None
        The store's revision afterwards.
    """
    from store.jobs import JobStore

    store = JobStore(url, ttl_s)
    try:
        store.migrate()
    finally:
        store.close()
    return current_revision(url)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command.

    Parameters
    ----------
    argv
        The arguments (default: ``sys.argv[1:]``).

    Returns
    -------
    int
        The exit status: 0 migrated, 1 failed.
    """
    parser = argparse.ArgumentParser(prog="python -m store.migrate", description=__doc__.split("\n\n")[0])
    parser.add_argument("--url", help="the store's SQLAlchemy URL (default: the settings' store, DATABASE_URL)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    logging.getLogger("alembic").setLevel(logging.WARNING)  # its set-up lines; store.jobs says what changed
    settings = Settings()
    url = args.url or settings.store_url
    shown = make_url(url).render_as_string(hide_password=True)
    try:
        revision = migrate(url, settings.job_ttl_s)
    except Exception as exc:  # noqa: BLE001 - the command's answer: a message and status 1, not a traceback
        print(f"store.migrate: migrating {shown} failed: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 1
    print(f"store.migrate: {shown} is at revision {revision}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
