"""The client-side commands of ``nonholonomic``: ``systems``, ``run``, ``ensemble``, ``get``, ``list``,
``report`` (``serve`` and ``worker`` start the server's processes: :mod:`nonholonomic_client.processes`).

Each takes the parsed arguments and returns an exit code; errors are raised (:class:`UsageError`,
:class:`nonholonomic_client.errors.ApiError`) and turned into messages and exit codes by
:func:`nonholonomic_client.cli.main`.
"""

from __future__ import annotations

import argparse
import functools
import json
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from nonholonomic_client.api import Client, Progress
from nonholonomic_client.errors import ApiError
from nonholonomic_client.progress import ProgressBar
from nonholonomic_client.summaries import (
    ensemble_summary,
    job_summary,
    listing_table,
    report_summary,
    systems_table,
)


class UsageError(Exception):
    """A mistake in the command line or its input files (exit code 2)."""


class Interrupted(Exception):
    """Ctrl-C while waiting; the job keeps running on the service (exit code 130)."""


def read_spec(source: str) -> Any:
    """Read a JSON request from a file, or from stdin for ``-``.

    Parameters
    ----------
    source : str
        A path or ``-``.

    Returns
    -------
    Any
        The parsed JSON.

    Raises
    ------
    UsageError
        If the file cannot be read or is not JSON (with the line, column and character position).
    """
    name = "stdin" if source == "-" else source
    try:
        text = sys.stdin.read() if source == "-" else Path(source).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise UsageError(f"cannot read {name}: {exc}") from exc
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise UsageError(f"{name} is not JSON: {exc.msg} at line {exc.lineno} column {exc.colno} "
                         f"(character {exc.pos})") from exc


def out_format(out: str | None, allowed: Sequence[str]) -> str | None:
    """The export format named by an output file's suffix.

    Parameters
    ----------
    out : str, optional
        The ``--out`` path.
    allowed : sequence of str
        Formats this command can write.

    Returns
    -------
    str or None
        The suffix without its dot; None without ``out``.

    Raises
    ------
    UsageError
        For any other suffix.
    """
    if out is None:
        return None
    suffix = Path(out).suffix.lower().lstrip(".")
    if suffix not in allowed:
        raise UsageError(f"--out {out}: the suffix must be one of {', '.join('.' + a for a in allowed)}")
    return suffix


def served(suffix: str | None) -> str | None:
    """The service's ``format`` for a file suffix from :func:`out_format` (``nc`` is ``netcdf``; the others
    are their own)."""
    return "netcdf" if suffix == "nc" else suffix


def _client(args: argparse.Namespace) -> Client:
    return Client(args.url)


def _wait(waiter: Callable[..., dict[str, Any]], ident: str, label: str) -> dict[str, Any]:
    bar: Progress
    with ProgressBar(sys.stderr, label=label) as bar:
        try:
            return waiter(ident, progress=bar)
        except KeyboardInterrupt:
            raise Interrupted(f"interrupted; {label} keeps running on the service") from None


def systems(args: argparse.Namespace) -> int:
    """``nonholonomic systems [--json]``: the catalog as a table, or raw."""
    with _client(args) as api:
        catalog = api.systems()
    print(json.dumps(catalog, indent=2, ensure_ascii=False) if args.json else systems_table(catalog))
    return 0


def run(args: argparse.Namespace) -> int:
    """``nonholonomic run SPEC [--wait] [--out FILE] [--result FILE]``: submit a job, maybe wait for it."""
    fmt = out_format(args.out, ("csv", "npz", "json", "nc"))
    spec = read_spec(args.spec)
    with _client(args) as api:
        job_id = api.submit(spec)
        print(f"job {job_id}\nlocation {api.url(f'/v1/jobs/{job_id}')}", flush=True)
        if not (args.wait or args.out or args.result):
            return 0
        # the samples only when the result is written whole (--out downloads them in their own format)
        view = _wait(functools.partial(api.wait, trajectory=bool(args.result)), job_id, f"job {job_id}")
        print(job_summary(view))
        if args.result:
            Path(args.result).write_text(json.dumps(view["result"], indent=1) + "\n", encoding="utf-8")
            print(f"result written to {args.result}")
        if args.out:
            path = api.trajectory(job_id, served(fmt), out=args.out)  # type: ignore[arg-type]  # a suffix allowed
            assert isinstance(path, Path)  # with out: the file written
            print(f"trajectory written to {path}")
    return 0


def ensemble(args: argparse.Namespace) -> int:
    """``nonholonomic ensemble SPEC [--wait] [--out section.csv|.npz]``: submit an ensemble, maybe wait; a
    chaos map's ``--out`` writes the map (``map.csv`` or ``map.nc``).

    Exit code 1 when every member failed (an ensemble whose members fail alone still succeeds).
    """
    spec = read_spec(args.spec)
    chaos_map = isinstance(spec, dict) and bool(spec.get("indicators"))
    fmt = out_format(args.out, ("csv", "nc") if chaos_map else ("csv", "npz", "nc"))
    if fmt and not chaos_map and isinstance(spec, dict) and not spec.get("poincare"):
        raise UsageError("--out writes the Poincare section: the spec asks for none (add \"poincare\")")
    with _client(args) as api:
        ensemble_id = api.submit_ensemble(spec)
        print(f"ensemble {ensemble_id}\nlocation {api.url(f'/v1/ensembles/{ensemble_id}')}", flush=True)
        if not (args.wait or args.out):
            return 0
        view = _wait(api.wait_ensemble, ensemble_id, f"ensemble {ensemble_id}")
        print(ensemble_summary(view))
        if args.out and chaos_map:
            path = api.chaos_map(ensemble_id, "netcdf" if fmt == "nc" else "csv", out=args.out)
            assert isinstance(path, Path)  # with out: the file written
            print(f"map written to {path}")
        elif args.out:
            path = api.section(ensemble_id, served(fmt), out=args.out)  # type: ignore[arg-type]  # a suffix allowed
            assert isinstance(path, Path)  # with out: the file written
            print(f"section written to {path}")
    summary = view.get("summary") or {}
    return 1 if summary.get("members") and not summary.get("succeeded") else 0


#: What ``get`` writes, by what is asked for: the suffixes each takes.
GET_FORMATS = {("job", "trajectory"): ("csv", "npz", "nc", "json"), ("job", "section"): ("csv", "npz", "nc", "json"),
               ("job", "result"): ("json",), ("job", "branch"): ("csv", "nc", "json"),
               ("ensemble", "section"): ("csv", "npz", "nc"),
               ("ensemble", "map"): ("csv", "nc", "json"), ("ensemble", "members"): ("csv", "nc"),
               ("ensemble", "result"): ("json",)}


def get(args: argparse.Namespace) -> int:
    """``nonholonomic get ID --out FILE [--what W]``: an existing job's trajectory, section, branch or result, or an
    ensemble's section, map, members table or view, in the format the suffix names (issue 35, items 2 and 3)."""
    with _client(args) as api:
        try:
            view: dict[str, Any] = api.job(args.ident, trajectory=False)
            what_is = "job"
        except ApiError as exc:
            if exc.status != 404:
                raise
            view, what_is = api.ensemble(args.ident), "ensemble"
        ident = str(view["id"])  # the whole id, also when ID gave its first characters
        chaos_map = what_is == "ensemble" and bool((view.get("request") or {}).get("indicators"))
        what = args.what or ("trajectory" if what_is == "job" else "map" if chaos_map else "section")
        allowed = GET_FORMATS.get((what_is, what))
        if allowed is None:
            raise UsageError(f"a {what_is} has no {what}; a job: trajectory, section, branch, result; an ensemble: "
                             "section, map, members, result")
        fmt = out_format(args.out, allowed)
        server_format = served(fmt)
        if what == "result":
            body = api.job(ident)["result"] if what_is == "job" else api.ensemble(ident)
            Path(args.out).write_text(json.dumps(body, indent=1) + "\n", encoding="utf-8")
        elif what == "trajectory":
            api.trajectory(ident, server_format, out=args.out)  # type: ignore[arg-type]  # a suffix allowed
        elif what == "section":
            api.section(ident, server_format, out=args.out, of=what_is)  # type: ignore[arg-type]  # a suffix allowed
        elif what == "branch":
            if server_format == "json":
                Path(args.out).write_text(json.dumps(api.branch(ident, "json"), indent=1) + "\n", encoding="utf-8")
            else:
                api.branch(ident, server_format, out=args.out)  # type: ignore[arg-type]  # a suffix allowed
        elif what == "members":
            api.members(ident, format=server_format, out=args.out)  # type: ignore[arg-type]  # a suffix allowed
        else:
            api.chaos_map(ident, server_format, out=args.out)  # type: ignore[arg-type]  # a suffix allowed
    print(f"{what_is} {ident}: {what} written to {args.out}")
    return 0


def listing(args: argparse.Namespace) -> int:
    """``nonholonomic list jobs|ensembles [--status S] [--limit N]``: the newest first, whole ids (any unique
    first characters of one also name it)."""
    rows: list[tuple[str, ...]]
    header: tuple[str, ...]
    with _client(args) as api:
        if args.what == "jobs":
            page = api.jobs(status=args.status, limit=args.limit)
            rows = [(i["id"], i["status"], f"{i['progress']:.0%}", i["created_at"][:19], i["kind"] or "")
                    for i in page["items"]]
            header = ("id", "status", "progress", "created (UTC)", "kind")
        else:
            page = api.ensembles(status=args.status, limit=args.limit)
            rows = [(i["id"], i["status"], f"{i['members_done']}/{i['members']}", i["created_at"][:19],
                     i["kind"] or "", i["label"]) for i in page["items"]]
            header = ("id", "status", "members", "created (UTC)", "kind", "members are")
    print(listing_table(header, rows) if rows else f"no {args.what}")
    return 0


def report(args: argparse.Namespace) -> int:
    """``nonholonomic report [--claims a,b] --out report.html``: run the paper report, save its page."""
    claims = [c.strip() for c in args.claims.split(",") if c.strip()] if args.claims else None
    if args.claims is not None and not claims:
        raise UsageError("--claims names no claim")
    with _client(args) as api:
        job_id = api.paper_report(claims)
        print(f"job {job_id}\nlocation {api.url(f'/v1/paper/report/{job_id}')}", flush=True)
        view = _wait(api.wait, job_id, f"paper report {job_id}")
        Path(args.out).write_text(api.report_page(job_id), encoding="utf-8")
    print(report_summary(view))
    print(f"page written to {args.out}")
    return 0
