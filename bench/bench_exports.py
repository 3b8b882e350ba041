"""Benchmark: taking a large result away, over HTTP, against writing the same arrays in-process.

Run from the repository root::

    .venv/bin/python bench/bench_exports.py [--samples 100001] [--repeat 3]

The API runs under uvicorn in embedded mode. One ball job with ``--samples`` samples (the service's
maximum by default) is run once; then, each ``--repeat`` times (median reported):

- ``GET /v1/jobs/{id}`` (the whole job JSON), ``GET .../trajectory?format=json|csv|npz|netcdf``: bytes
  and seconds to the last byte (streamed by httpx, not kept);
- references measured in this process on the same arrays: ``json.dumps`` of the job view,
  ``numpy.savetxt`` of the CSV columns (``%.17g``), ``numpy.savez`` of the arrays, xarray's
  ``to_netcdf`` of the bare arrays (no attributes). The ratio
  ``HTTP / reference`` is the cost of serving it (HTTP, the backend, streaming) over writing it;
- the client's ``trajectory(format="xarray"|"pandas")`` against fetching and parsing the JSON alone;
- every plot of the job as PNG and SVG (the trajectory drawn from dense output): the first request
  (drawn) and the second (cached), with the drawn time against ``Figure.savefig`` of the same plot in
  this process;
- the peak resident memory of the API process while the CSV streams (``/proc``): streaming should
  not add a second copy of the result.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import argparse  # noqa: E402
import io  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import tempfile  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402

import httpx  # noqa: E402
import numpy as np  # noqa: E402

from tests.support import free_port, poll_job, start_api, stop, wait_healthy  # noqa: E402

JOB = {"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7,
                  "potential": {"kind": "linear", "a": [0.3, -0.2, 0.5]}},
       "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]}, "t_final": 1000.0}


def _median_time(fn: Callable[[], object], repeat: int) -> tuple[float, object]:
    times, out = [], None
    for _ in range(repeat):
        start = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times), out


def _download(client: httpx.Client, url: str) -> int:
    size = 0
    with client.stream("GET", url) as r:
        r.raise_for_status()
        for chunk in r.iter_bytes():
            size += len(chunk)
    return size


def _rss_kib(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    return 0


def _peak_rss_during(pid: int, fn: Callable[[], object]) -> tuple[int, int]:
    """(RSS before, peak RSS while ``fn`` runs) of process ``pid``, in KiB."""
    before, peak, done = _rss_kib(pid), 0, threading.Event()

    def sample() -> None:
        nonlocal peak
        while not done.is_set():
            peak = max(peak, _rss_kib(pid))
            time.sleep(0.005)

    thread = threading.Thread(target=sample)
    thread.start()
    try:
        fn()
    finally:
        done.set()
        thread.join()
    return before, peak


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=100001)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()

    port = free_port()
    log = Path(tempfile.mkdtemp()) / "api.log"
    proc = start_api(port, log, {"NONHOLONOMIC_WARM_UP": "false", "NONHOLONOMIC_MAX_SAMPLES": str(args.samples)})
    base = f"http://127.0.0.1:{port}"
    try:
        wait_healthy(base, timeout=60)
        with httpx.Client(base_url=base, timeout=300) as client:
            r = client.post("/v1/jobs", json={**JOB, "samples": args.samples})
            r.raise_for_status()
            location = r.headers["location"]
            view = poll_job(client, location, timeout=600, interval=0.1)
            assert view["status"] == "succeeded", view
            traj = view["result"]["trajectory"]
            columns = [np.asarray(traj["t"]), np.asarray(traj["tau"])] + [
                np.asarray(traj[name])[:, k] for name in ("M", "gamma", "omega") for k in range(3)]
            table = np.column_stack(columns)
            print(f"job: chaplygin_ball, {args.samples} samples, {table.shape[1]} columns; median of {args.repeat}")
            print(f"{'export':34s} {'bytes':>12s} {'HTTP s':>8s} {'ref s':>8s} {'HTTP/ref':>9s}  reference")

            def ref_json() -> int:
                return len(json.dumps(view).encode())

            def ref_csv() -> int:
                buffer = io.StringIO()
                np.savetxt(buffer, table, fmt="%.17g", delimiter=",")
                return len(buffer.getvalue().encode())

            def ref_npz() -> int:
                buffer = io.BytesIO()
                np.savez(buffer, **{f"c{i}": c for i, c in enumerate(columns)})
                return len(buffer.getvalue())

            def ref_netcdf() -> int:
                import xarray as xr

                names = ["tau"] + [f"{v}{k + 1}" for v in ("M", "gamma", "omega") for k in range(3)]
                ds = xr.Dataset({n: ("t", c) for n, c in zip(names, columns[1:], strict=True)},
                                coords={"t": columns[0]})
                return len(ds.to_netcdf(engine="netcdf4"))

            rows = [("GET /v1/jobs/{id} (job JSON)", location, ref_json, "json.dumps in-process"),
                    ("trajectory?format=json", f"{location}/trajectory?format=json", ref_json, "json.dumps of the job"),
                    ("trajectory?format=csv", f"{location}/trajectory?format=csv", ref_csv, "numpy.savetxt %.17g"),
                    ("trajectory?format=npz", f"{location}/trajectory?format=npz", ref_npz, "numpy.savez"),
                    ("trajectory?format=netcdf", f"{location}/trajectory?format=netcdf", ref_netcdf,
                     "xarray to_netcdf, bare arrays")]
            for label, url, ref, what in rows:
                http_s, size = _median_time(lambda url=url: _download(client, url), args.repeat)
                ref_s, _ = _median_time(ref, args.repeat)
                print(f"{label:34s} {size:12,d} {http_s:8.3f} {ref_s:8.3f} {http_s / ref_s:9.2f}  {what}")

            # The client's arrays: the JSON fetched and turned into an xarray Dataset / a DataFrame, against
            # the JSON fetched and parsed alone (the ratio is the cost of the labelled arrays).
            from nonholonomic_client import Client

            job_id = location.rsplit("/", 1)[-1]
            with Client(base, timeout=300) as api:
                def fetch_json() -> int:
                    return len(api.trajectory(job_id)["t"])

                ref_s, _ = _median_time(fetch_json, args.repeat)
                for fmt in ("xarray", "pandas"):
                    took, _ = _median_time(lambda fmt=fmt: api.trajectory(job_id, format=fmt), args.repeat)
                    print(f"{'Client.trajectory(' + fmt + ')':34s} {'':12s} {took:8.3f} {ref_s:8.3f} "
                          f"{took / ref_s:9.2f}  the JSON fetched and parsed")

            before, peak = _peak_rss_during(proc.pid, lambda: _download(client, f"{location}/trajectory?format=csv"))
            json_size = len(json.dumps(view).encode())
            print(f"API RSS while the CSV streams: {before / 1024:.0f} MiB before, peak {peak / 1024:.0f} MiB "
                  f"(+{(peak - before) / 1024:.0f} MiB; the job JSON is {json_size / 2**20:.0f} MiB)")

            from service.plots import _render, job_plot  # noqa: F401  (the reference draws in this process)
            print(f"\n{'plot':22s} {'bytes':>10s} {'drawn s':>8s} {'cached s':>9s} {'in-process s':>13s} "
                  f"{'drawn/in-proc':>14s}")
            for name in ("trajectory", "integrals"):
                for fmt in ("png", "svg"):
                    url = f"{location}/plots/{name}.{fmt}"
                    start = time.perf_counter()
                    size = _download(client, url)
                    drawn = time.perf_counter() - start
                    cached, _ = _median_time(lambda url=url: _download(client, url), args.repeat)
                    local, _ = _median_time(lambda name=name, fmt=fmt: job_plot(name, view["result"], view["request"],
                                                                                fmt), args.repeat)
                    print(f"{name + '.' + fmt:22s} {size:10,d} {drawn:8.3f} {cached:9.4f} {local:13.3f} "
                          f"{drawn / local:14.2f}")
    finally:
        stop(proc)


if __name__ == "__main__":
    main()
