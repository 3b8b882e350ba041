#!/usr/bin/env python3
"""Run the notebook tutorials (``docs/tutorials/*.ipynb``) against a live API, so they cannot rot.

    .venv/bin/python scripts/tutorials.py --url http://127.0.0.1:8000            # execute, keep nothing
    .venv/bin/python scripts/tutorials.py --url http://127.0.0.1:8000 --write    # store the outputs (docs)
    .venv/bin/python scripts/tutorials.py --client-calls > calls.py               # the client's calls alone

Each notebook runs top to bottom in a fresh Jupyter kernel (nbclient, this interpreter's ipykernel) with
``NONHOLONOMIC_URL`` set; a cell that raises (the notebooks assert their numbers) fails the run, naming
the notebook and the cell. ``--client-calls`` prints every code cell not tagged ``plot`` as one Python
script (each notebook in a namespace of its own): what a venv with only the client installed
(``pip install './client[notebook]'``, no matplotlib, no Jupyter) must be able to run.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TUTORIALS = ROOT / "docs" / "tutorials"
#: Seconds a cell may take (a hang guard; the longest, the ensemble, takes a few seconds).
CELL_TIMEOUT_S = 600


def notebooks() -> list[Path]:
    """The tutorials, in name order."""
    return sorted(TUTORIALS.glob("*.ipynb"))


def client_calls() -> str:
    """Every code cell not tagged ``plot``, each notebook's in a namespace of its own."""
    import nbformat

    parts = ["# The notebook tutorials' client calls (scripts/tutorials.py --client-calls).", ""]
    for path in notebooks():
        cells = [c.source for c in nbformat.read(path, as_version=4).cells
                 if c.cell_type == "code" and "plot" not in c.metadata.get("tags", [])]
        source = "\n\n".join(cells)
        parts += [f"print({path.name!r}, flush=True)", f"exec(compile({source!r}, {path.name!r}, 'exec'), {{}})", ""]
    return "\n".join(parts)


def execute(path: Path, url: str, out: Path | None) -> float:
    """Run one notebook in a fresh kernel; write it with its outputs to ``out`` when given.

    Returns
    -------
    float
        Seconds it took.
    """
    import nbformat
    from jupyter_client.manager import KernelManager
    from nbclient import NotebookClient

    book = nbformat.read(path, as_version=4)
    os.environ["NONHOLONOMIC_URL"] = url
    start = time.monotonic()
    # IPC (Unix sockets in a folder of its own, by absolute path: the kernel runs in ROOT), not TCP: the kernel
    # is local, and ipykernel warns at every start that TCP is unencrypted
    with tempfile.TemporaryDirectory(prefix="nonholonomic-kernel-") as sockets:
        manager = KernelManager(kernel_name="python3", transport="ipc", ip=os.path.join(sockets, "kernel"))
        try:
            NotebookClient(book, km=manager, timeout=CELL_TIMEOUT_S, kernel_name="python3",
                           resources={"metadata": {"path": str(ROOT)}}, record_timing=False).execute()
        finally:  # a kernel manager given to nbclient is the caller's to stop
            if manager.has_kernel:
                manager.shutdown_kernel(now=True)
    if out is not None:
        nbformat.write(book, out)
    return time.monotonic() - start


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--url", default=os.environ.get("NONHOLONOMIC_URL", "http://127.0.0.1:8000"))
    parser.add_argument("--write", action="store_true", help="store the outputs in docs/tutorials")
    parser.add_argument("--out", type=Path, help="write the executed notebooks into this folder")
    parser.add_argument("--client-calls", action="store_true", help="print the client's calls as one script")
    parser.add_argument("names", nargs="*", help="only these notebooks (file names)")
    args = parser.parse_args(argv)
    if args.client_calls:
        print(client_calls())
        return 0
    chosen = [p for p in notebooks() if not args.names or p.name in args.names]
    for path in chosen:
        out = path if args.write else (args.out / path.name if args.out else None)
        if out is not None:
            out.parent.mkdir(parents=True, exist_ok=True)
        try:
            seconds = execute(path, args.url, out)
        except Exception as exc:  # noqa: BLE001 - report which notebook and cell failed
            print(f"FAILED {path.name}: {type(exc).__name__}: {str(exc)[-3000:]}", file=sys.stderr)
            return 1
        print(f"ok {path.name} {seconds:.1f} s", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
