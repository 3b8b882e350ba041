"""The notebook tutorials (``docs/tutorials/*.ipynb``) run as a researcher runs them: from a fresh venv
holding only the client (``pip install './client[notebook]'``: httpx, numpy, pandas, xarray, tqdm; none
of the server's stack), then Jupyter and matplotlib, each notebook top to bottom in a fresh kernel of
that venv against a live embedded API, by ``scripts/tutorials.py`` (what a maintainer runs with
``--write`` to store their outputs for the docs). The notebooks assert their own numbers (drifts, the
spectrum's sum against the measure, a verdict), so a change that breaks the physics or the client
fails here. The cells not tagged ``plot`` need nothing beyond the client: every module they import is
imported in the venv before Jupyter and matplotlib are added."""

from __future__ import annotations

import ast
import json
import subprocess
import venv
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.support import ROOT, embedded_api

pytestmark = pytest.mark.integration

TUTORIALS = sorted((ROOT / "docs" / "tutorials").glob("*.ipynb"))
#: Distributions the client must not bring (the server's stack).
SERVER_DISTRIBUTIONS = ("heyoka", "sympy", "celery", "fastapi", "sqlalchemy", "uvicorn", "redis", "scipy",
                        "matplotlib", "alembic", "psycopg", "nonholonomic")
#: What a notebook adds to the client: a kernel, the runner and the plots.
NOTEBOOK_TOOLS = ("ipykernel", "nbclient", "nbformat", "matplotlib")


@pytest.fixture(scope="module")
def base(tmp_path_factory) -> Iterator[str]:
    with embedded_api(tmp_path_factory.mktemp("tutorials-api")) as url:
        yield url


def test_there_are_the_eight_tutorials_the_docs_list():
    names = [p.stem for p in TUTORIALS]
    assert names == ["branches", "chaos-map", "ensemble", "first-job", "paper-report", "section-and-exponents",
                     "theorem-1", "your-own-lagrangian"]
    nav = (ROOT / "mkdocs.yml").read_text()
    assert all(f"tutorials/{p.name}" in nav for p in TUTORIALS)


def _read(path: Path):  # type: ignore[no-untyped-def]
    """A notebook; nbformat is imported here, not at the top: its JSON Schema formats take about a second
    to import, which every pytest-xdist process would pay while collecting."""
    import nbformat

    return nbformat.read(path, as_version=4)


def _client_cell_imports() -> list[str]:
    """The top-level modules imported by the tutorials' cells not tagged ``plot``."""
    found: set[str] = set()
    for path in TUTORIALS:
        for cell in _read(path).cells:
            if cell.cell_type != "code" or "plot" in cell.metadata.get("tags", []):
                continue
            for node in ast.walk(ast.parse(cell.source)):
                if isinstance(node, ast.Import):
                    found |= {a.name.split(".")[0] for a in node.names}
                elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
                    found.add(node.module.split(".")[0])
    return sorted(found)


#: A small job whose trajectory the client-only environment reads back from NetCDF.
NETCDF_JOB = {"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7},
              "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]}, "t_final": 5.0, "samples": 11}


def _run(args: list[str], cwd: Path, timeout: float = 900) -> subprocess.CompletedProcess:
    """A command in ``cwd`` (not the repository: its folders must not be what is imported)."""
    return subprocess.run(args, capture_output=True, text=True, timeout=timeout, check=False, cwd=cwd)


def _install(python: str, *specs: str, cwd: Path) -> None:
    """``pip install`` into the venv of ``python``, its bytecode compiled on every core afterwards (as
    scripts/_bootstrap.py does for .venv: pip alone compiles one file at a time)."""
    install = _run([python, "-m", "pip", "install", "-q", "--no-compile", *specs], cwd)
    assert install.returncode == 0, install.stderr[-3000:]
    site = _run([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], cwd, timeout=60)
    assert site.returncode == 0 and site.stdout.strip(), site.stderr[-3000:]
    _run([python, "-m", "compileall", "-qq", "-j", "0", site.stdout.strip()], cwd)


def test_the_client_installs_alone_and_every_tutorial_runs_from_it(base, tmp_path):
    env_dir = tmp_path / "venv"
    venv.EnvBuilder(with_pip=True).create(env_dir)
    python = str(env_dir / "bin" / "python")
    _install(python, f"{ROOT / 'client'}[notebook]", cwd=tmp_path)
    inventory = f"""
import importlib.metadata as md, importlib.util, json
names = sorted(d.metadata["Name"].lower() for d in md.distributions())
tops = [m for m in ("service", "schemas", "store", "workers", "client", "nonholonomic") if importlib.util.find_spec(m)]
print(json.dumps({{"names": names, "server": [n for n in {SERVER_DISTRIBUTIONS!r} if n in names], "tops": tops}}))
"""
    run = _run([python, "-c", inventory], tmp_path, timeout=120)
    assert run.returncode == 0, run.stderr[-3000:]
    out = json.loads(run.stdout.strip().splitlines()[-1])
    assert out["server"] == [] and out["tops"] == [], out
    assert {"httpx", "numpy", "pandas", "xarray", "tqdm", "netcdf4", "nonholonomic-client"} <= set(out["names"])
    assert "matplotlib" not in out["names"] and "ipykernel" not in out["names"]
    modules = _client_cell_imports()
    assert "nonholonomic_client" in modules and "matplotlib" not in modules, modules
    run = _run([python, "-c", f"import importlib; [importlib.import_module(m) for m in {modules!r}]"], tmp_path, 120)
    assert run.returncode == 0, run.stderr[-3000:]
    cli = str(env_dir / "bin" / "nonholonomic")
    systems = _run([cli, "--url", base, "systems"], tmp_path, timeout=60)
    assert systems.returncode == 0 and "chaplygin_ball" in systems.stdout, systems.stderr
    # NetCDF opens wherever the client is (issue 35, item 3): the CLI's .nc, read by xarray, equal to the JSON
    (tmp_path / "job.json").write_text(json.dumps(NETCDF_JOB))
    done = _run([cli, "--url", base, "run", "job.json", "--out", "traj.nc"], tmp_path, timeout=300)
    assert done.returncode == 0 and "trajectory written to traj.nc" in done.stdout, done.stderr[-3000:]
    job_id = done.stdout.split()[1]
    check = f"""
import numpy as np, xarray as xr
from nonholonomic_client import Client
with Client({base!r}) as api:
    reference = api.trajectory({job_id!r}, format="xarray")
with xr.open_dataset("traj.nc") as ds:
    assert ds["M1"].attrs["units"] == "kg m^2/s", ds["M1"].attrs
    for name in ("M1", "M2", "M3", "gamma1", "gamma2", "gamma3"):
        assert np.array_equal(ds[name].values, reference[name].values), name
    print("netcdf ok", ds.sizes["t"])
"""
    opened = _run([python, "-c", check], tmp_path, timeout=120)
    assert opened.returncode == 0 and "netcdf ok 11" in opened.stdout, opened.stderr[-3000:]
    serve = _run([cli, "serve"], tmp_path, timeout=60)
    assert serve.returncode == 2 and "needs the server" in serve.stderr and "pip install -e ." in serve.stderr

    _install(python, *NOTEBOOK_TOOLS, cwd=tmp_path)
    executed = tmp_path / "executed"
    run = _run([python, str(ROOT / "scripts" / "tutorials.py"), "--url", base, "--out", str(executed)], tmp_path,
               timeout=1200)
    assert run.returncode == 0, run.stderr[-4000:]
    assert ([line.split()[1] for line in run.stdout.splitlines() if line.startswith("ok ")]
            == [p.name for p in TUTORIALS])
    for path in TUTORIALS:
        book = _read(executed / path.name)
        outputs = [o for c in book.cells if c.cell_type == "code" for o in c.outputs]
        assert not [o for o in outputs if o.output_type == "error"], path.name
        assert any(o.output_type == "execute_result" for o in outputs), path.name
    # a wait's progress: one line updated in place (issue 35, item 5), not a stderr block of redraws
    first = _read(executed / "first-job.ipynb")
    waits = [c for c in first.cells if c.cell_type == "code" and "progress=True" in c.source]
    assert waits, "first-job.ipynb waits with progress=True"
    for cell in waits:
        assert not [o for o in cell.outputs if o.output_type == "stream" and o.name == "stderr"], cell.outputs
        lines = [o for o in cell.outputs if o.output_type == "display_data" and "100% succeeded" in
                 o.get("data", {}).get("text/plain", "")]
        assert len(lines) == 1, cell.outputs
    assert "without encryption" not in run.stderr  # the kernels run over IPC
    section = _read(executed / "section-and-exponents.ipynb")
    pictures = [o for c in section.cells for o in getattr(c, "outputs", []) if "image/png" in o.get("data", {})]
    assert len(pictures) == 2  # the section and the running estimates, drawn
