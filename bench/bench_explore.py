"""The section explorer: from a click on the ball's section to 100 crossings drawn, in headless Chromium,
against the core computing the same 100 crossings alone, measured in the same run.

Chaplygin's ball in a linear field (a = (0.3, -0.2, 0.5)), H = 2, (M, γ) = 0, section γ3 = 0 in (γ1, M3), the
page /explore of an embedded service (uvicorn, warmed by a first click). For each of ``--clicks`` points on a
grid over the island and the sea:

A. **The page**: the time from Playwright's click to the canvas counting 100 more crossings (the POST, the
   completion of the point, the service's first piece of 100 crossings, the page's polls and drawing).
B. **The reference**: the core's :func:`~nonholonomic.analysis.poincare.section` from the same state to its
   100th crossing, in this process.

Printed: the median and the largest of A (target: ≤ 1 s, the issue's figure), the median of B, and the ratio
A / B: what the HTTP round trips, the polling and the drawing add.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import argparse  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from playwright.sync_api import sync_playwright  # noqa: E402

from nonholonomic.analysis.chaos_map.grid import Grid, complete  # noqa: E402
from nonholonomic.analysis.poincare import section  # noqa: E402
from nonholonomic.numerics.kernels import parameter_vector  # noqa: E402
from nonholonomic.systems import get_system  # noqa: E402
from tests.support import embedded_api  # noqa: E402

CHROMIUM = "/usr/bin/chromium"
POINTS = "Number(document.getElementById('plane').dataset.points)"


def until(page, expression: str, timeout: float = 30.0) -> float:
    start = time.perf_counter()
    while not page.evaluate(expression):
        if time.perf_counter() - start > timeout:
            raise TimeoutError(expression)
        page.wait_for_timeout(5)
    return time.perf_counter() - start


def click(page, u: float, v: float) -> None:
    x, y = page.evaluate(f"window.explorer.pixelOf({u}, {v})")
    scale = page.evaluate("(c => c.clientWidth / c.width)(document.getElementById('plane'))")
    page.locator("#plane").click(position={"x": x * scale + 1, "y": y * scale + 1})


def core_time(u: float, v: float) -> float:
    system = get_system("chaplygin_ball", "linear")
    p = parameter_vector(system, {"inertia": [2.0, 3.0, 4.5], "D": 0.7, "a": [0.3, -0.2, 0.5]})
    grid = Grid("gamma3", 0.0, ("gamma1", "M3"), {"energy": 2.0, "area": 0.0}, (1, 1))
    x = complete(system, p, grid, ((u - 1e-9, u + 1e-9), (v - 1e-9, v + 1e-9))).states[0]
    section(system, p, x, 2000.0, "gamma3", max_points=101)  # warm
    start = time.perf_counter()
    section(system, p, x, 2000.0, "gamma3", coordinates=("gamma1", "M3"), max_points=101)
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clicks", type=int, default=12)
    args = parser.parse_args()
    load = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    print(f"the explorer, click to 100 crossings drawn; load: {load}")
    grid = [(u, v) for u in np.linspace(-0.7, 0.5, 4) for v in np.linspace(-2.0, 2.0, 3)][: args.clicks]
    with tempfile.TemporaryDirectory() as logs, embedded_api(Path(logs)) as base, sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, headless=True, args=["--no-sandbox"])
        page = browser.new_page(viewport={"width": 1300, "height": 1100})
        page.goto(f"{base}/explore?kind=chaplygin_ball&potential=linear", wait_until="networkidle")
        until(page, "document.getElementById('plane').dataset.ready === '1'")
        click(page, -0.2, 0.0)  # warm: the service compiles or loads its integrators
        until(page, f"{POINTS} >= 100", timeout=120)
        page.wait_for_timeout(1000)
        page_times, core_times = [], []
        for u, v in grid:
            before = int(page.evaluate(POINTS))
            start = time.perf_counter()
            click(page, u, v)
            until(page, f"{POINTS} >= {before + 100}")
            page_times.append(time.perf_counter() - start)
            page.wait_for_timeout(600)  # let the rest of the orbit stream in
            core_times.append(core_time(u, v))
            print(f"  click ({u:+.3f}, {v:+.3f}): page {page_times[-1] * 1e3:6.1f} ms, "
                  f"core {core_times[-1] * 1e3:5.1f} ms")
        browser.close()
    a, b = statistics.median(page_times), statistics.median(core_times)
    print("SUMMARY")
    print(f"  click to 100 crossings drawn: median {a * 1e3:.1f} ms, largest {max(page_times) * 1e3:.1f} ms "
          f"({len(page_times)} clicks)  {'OK' if max(page_times) <= 1.0 else 'MISS'} (target <= 1 s)")
    print(f"  the core's 100 crossings alone: median {b * 1e3:.1f} ms; ratio page / core {a / b:.1f}")


if __name__ == "__main__":
    main()
