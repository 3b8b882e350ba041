"""The ``nonholonomic`` command line.

Commands: ``systems``, ``run``, ``ensemble``, ``report`` (clients of the API at ``--url``) and
``serve``, ``worker`` (start the API or a Celery worker).

Exit codes: 0 success; 1 the job or ensemble failed or was cancelled; 2 a usage error or a request
the service refused (4xx; each offending field is printed); 3 the service cannot be reached (or
answered 5xx); 130 interrupted.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence

from nonholonomic_client import commands
from nonholonomic_client.api import default_url
from nonholonomic_client.errors import ApiError, JobFailed
from nonholonomic_client.processes import execute, serve_command, worker_command

EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_UNREACHABLE, EXIT_INTERRUPTED = 0, 1, 2, 3, 130


def _serve(args: argparse.Namespace) -> int:
    execute(*serve_command(args.host, args.port, args.queue, os.environ))


def _worker(args: argparse.Namespace) -> int:
    execute(*worker_command(args.concurrency, os.environ))


def _positive(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, not {value}")
    return value


def _port(text: str) -> int:
    value = int(text)
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"not a port: {value}")
    return value


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``nonholonomic``.

    Returns
    -------
    argparse.ArgumentParser
    """
    parser = argparse.ArgumentParser(
        prog="nonholonomic", description="Client and launcher of the nonholonomic computation service.",
        epilog="exit codes: 0 ok, 1 job failed or cancelled, 2 usage or invalid request, 3 service unreachable")
    parser.add_argument("--url", default=default_url(),
                        help="the API's address (default $NONHOLONOMIC_URL, else http://127.0.0.1:8000; "
                             "now %(default)s)")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("systems", help="list the systems of the catalog")
    p.add_argument("--json", action="store_true", help="print the raw catalog")
    p.set_defaults(func=commands.systems)

    p = sub.add_parser("run", help="submit a simulation job (SPEC: a JSON request; - reads stdin)")
    p.add_argument("spec", metavar="SPEC")
    p.add_argument("--wait", action="store_true", help="wait with a progress bar, then print a summary")
    p.add_argument("--out", metavar="FILE", help="write the trajectory (.csv, .npz, .nc or .json; implies --wait)")
    p.add_argument("--result", metavar="FILE", help="write the result as JSON (implies --wait)")
    p.set_defaults(func=commands.run)

    p = sub.add_parser("ensemble", help="submit an ensemble (SPEC: a JSON request; - reads stdin)")
    p.add_argument("spec", metavar="SPEC")
    p.add_argument("--wait", action="store_true", help="wait with a progress bar, then print a summary")
    p.add_argument("--out", metavar="FILE", help="write the Poincare section (.csv, .npz or .nc), or a chaos map's "
                                                 "cells (.csv or .nc); implies --wait")
    p.set_defaults(func=commands.ensemble)

    p = sub.add_parser("get", help="save an existing job's or ensemble's results (ID: the id or its first "
                                   "characters)")
    p.add_argument("ident", metavar="ID")
    p.add_argument("--out", metavar="FILE", required=True,
                   help="where to write; the suffix names the format: a job's trajectory or section (.csv, .npz, "
                        ".nc, .json), a job's branch (.csv, .nc, .json), an ensemble's section (.csv, .npz, .nc), a "
                        "chaos map (.csv, .nc, .json), an "
                        "ensemble's members table (.csv, .nc)")
    p.add_argument("--what", choices=("trajectory", "section", "branch", "map", "members", "result"),
                   help="what to save (default: a job's trajectory, an ensemble's section, a chaos map's map; "
                        "branch: a job's branch of periodic orbits, one row per orbit and bifurcation; "
                        "members: an ensemble's table, one row per member; "
                        "result: the job's whole result, or the ensemble's view, as .json)")
    p.set_defaults(func=commands.get)

    p = sub.add_parser("list", help="list your jobs or ensembles, newest first")
    p.add_argument("what", choices=("jobs", "ensembles"))
    p.add_argument("--status", choices=("queued", "running", "succeeded", "failed", "cancelled"),
                   help="only those in this status")
    p.add_argument("--limit", type=_positive, default=20, help="at most this many (default %(default)s)")
    p.set_defaults(func=commands.listing)

    p = sub.add_parser("report", help="run the paper report and save its HTML page")
    p.add_argument("--claims", metavar="IDS", help="comma-separated claim ids (GET /v1/paper/claims); default all")
    p.add_argument("--out", metavar="FILE", required=True, help="where to write the HTML page")
    p.set_defaults(func=commands.report)

    p = sub.add_parser("serve", help="run the API (embedded mode unless --queue)")
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default %(default)s)")
    p.add_argument("--port", type=_port, default=8000, help="port (default %(default)s; 0 picks a free one)")
    p.add_argument("--queue", action="store_true",
                   help="queue mode: send jobs to Celery workers through $REDIS_URL (default redis://127.0.0.1:6379/0)")
    p.set_defaults(func=_serve)

    p = sub.add_parser("worker", help="run a Celery worker on $NONHOLONOMIC_QUEUE through $REDIS_URL")
    p.add_argument("--concurrency", type=_positive, help="worker processes (default: one per core)")
    p.set_defaults(func=_worker)
    return parser


def _say(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def _report(exc: ApiError) -> None:
    """The problem on stderr: its title and, field by field, its errors (a 422's detail only joins them:
    printed too, each error came out twice), else its detail."""
    if exc.errors:
        _say(f"error: {exc.title}")
        for e in exc.errors:
            _say(f"  {e['field']}: {e['reason']}")
    else:
        _say(f"error: {exc.title}: {exc.detail}" if exc.detail else f"error: {exc.title}")
    if (exc.status or 0) >= 500 and exc.request_id:  # the service's fault: the id finds it in its logs
        _say(f"  request id: {exc.request_id} (the service's logs carry it)")


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``nonholonomic`` with ``argv`` (default ``sys.argv[1:]``).

    Parameters
    ----------
    argv : sequence of str, optional

    Returns
    -------
    int
        The exit code (see the module's docstring); errors are printed on stderr, never as a
        traceback.
    """
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help (0) or a usage error (2)
        return exc.code if isinstance(exc.code, int) else EXIT_USAGE
    try:
        return int(args.func(args))
    except JobFailed as exc:
        _report(exc)
        return EXIT_FAILED
    except ApiError as exc:
        _report(exc)
        if exc.unreachable or (exc.status or 0) >= 500:
            return EXIT_UNREACHABLE
        return EXIT_USAGE
    except commands.UsageError as exc:
        _say(f"error: {exc}")
        return EXIT_USAGE
    except commands.Interrupted as exc:
        _say(str(exc))
        return EXIT_INTERRUPTED
    except KeyboardInterrupt:
        _say("interrupted")
        return EXIT_INTERRUPTED
    except OSError as exc:  # writing an output file
        _say(f"error: {exc}")
        return EXIT_USAGE


if __name__ == "__main__":
    sys.exit(main())
