"""Pictures that say something (issue 21, item 7): a trajectory plot draws the integrator's dense output,
not the job's few samples (the curve passes through the stored samples and has no visible corners);
the Lyapunov plots say that they show finite-time estimates and which have not converged."""

from __future__ import annotations

import copy
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from service import plot_ensemble, plot_orbit, plot_trajectory, plots
from tests.api.conftest import BALL, STATE
from workers.jobs import run_job

#: A ball orbit of many turns stored at the default 201 samples: drawn through them it is all chords.
LONG = {"system": {**BALL, "potential": {"kind": "linear", "a": [0.3, -0.2, 0.5]}}, "initial_state": dict(STATE),
        "t_final": 300.0, "samples": 201, "checks": ["integrals"], "lyapunov": {"interval": 1.0}}
#: The whole run as the window (LONG makes about 23 turns: by default only its last stretch is drawn).
WHOLE = (0.0, 300.0)


@pytest.fixture(scope="module")
def long_job() -> tuple[dict, dict]:
    return run_job(LONG), LONG


@pytest.fixture(autouse=True)
def _fresh_cache():
    plot_orbit._cache.clear()
    yield
    plot_orbit._cache.clear()


def _svg_texts(data: bytes) -> str:
    root = ET.fromstring(data)
    return "\n".join("".join(e.itertext()) for e in root.iter() if e.tag.endswith("text"))


def _turning_angles(curve: np.ndarray) -> np.ndarray:
    """Angle (degrees) between consecutive segments of a polyline."""
    d = np.diff(curve, axis=0)
    d = d[np.linalg.norm(d, axis=1) > 0]
    cos = np.einsum("ij,ij->i", d[:-1], d[1:]) / (np.linalg.norm(d[:-1], axis=1) * np.linalg.norm(d[1:], axis=1))
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def _visible(curve: np.ndarray, length: float) -> np.ndarray:
    """Which turning angles of :func:`_turning_angles` sit between two segments longer than ``length``."""
    d = np.linalg.norm(np.diff(curve, axis=0), axis=1)
    d = d[d > 0]
    return np.minimum(d[:-1], d[1:]) > length


def test_the_dense_curve_passes_through_the_stored_samples(long_job):
    result, request = long_job
    orbit = plot_orbit.dense_orbit(result, request, ["gamma", "M"])
    assert orbit.dense and "dense output" in orbit.note
    stored_t = np.asarray(result["trajectory"]["t"])
    at = np.searchsorted(orbit.t, stored_t)
    np.testing.assert_array_equal(orbit.t[at], stored_t)  # every stored time is on the grid
    for name in ("gamma", "M"):
        np.testing.assert_allclose(orbit.vectors[name][at], np.asarray(result["trajectory"][name]), rtol=0, atol=1e-9)
    assert orbit.stored_deviation <= 1e-9
    # between the samples: on the sphere, energy kept (the orbit, not an interpolation)
    np.testing.assert_allclose(np.linalg.norm(orbit.vectors["gamma"], axis=1), 1.0, atol=1e-12)


def test_the_plotted_orbit_has_no_chords(long_job):
    result, request = long_job
    fig = plot_trajectory.trajectory_figure(result, request, WHOLE)  # the whole run, asked for
    curve = np.vstack(fig.axes[0].get_lines()[0].get_data_3d()).T
    stored = np.asarray(result["trajectory"]["gamma"])
    before, after = _turning_angles(stored), _turning_angles(curve)
    assert len(stored) == 201 and before.max() > 60  # the samples alone: chords with sharp corners
    assert len(curve) > 10 * len(stored) and len(curve) <= plot_orbit.MAX_POINTS
    # at least 72 points per full turn of the tangent wherever the segments are visible (longer than
    # about a pixel, 1/400 of the extent 2); γ may nearly stop and turn on a hairpin smaller than a pixel
    # (the sagitta below bounds the corners a reader could see)
    visible = _visible(curve, 2 / 400)
    assert visible.mean() > 0.95 and after[visible].max() < 5.0, after[visible].max()
    assert np.median(before) > 10 * np.median(after)
    assert plot_orbit.sagitta(curve) <= plot_orbit.SAGITTA_TARGET
    assert plot_orbit.sagitta(stored) > 100 * plot_orbit.SAGITTA_TARGET
    # the momentum against t is as smooth
    for line in fig.axes[1].get_lines():
        assert len(line.get_xdata()) == len(curve)
    texts = _svg_texts(plots.job_plot("trajectory", result, request, "svg", WHOLE))
    assert f"dense output at {len(curve)} times" in texts and "201 stored samples" in texts


def test_dense_plots_are_deterministic_and_cached(long_job, monkeypatch):
    result, request = long_job
    first = plot_orbit.dense_orbit(result, request, ["gamma", "M"])
    assert plot_orbit.dense_orbit(result, request, ["gamma", "M"]) is first  # cached
    plot_orbit._cache.clear()
    again = plot_orbit.dense_orbit(result, request, ["gamma", "M"])
    assert again is not first
    np.testing.assert_array_equal(again.t, first.t)
    for name in first.vectors:
        np.testing.assert_array_equal(again.vectors[name], first.vectors[name])
    assert plots.job_plot("trajectory", result, request, "svg") == plots.job_plot("trajectory", result, request, "svg")


def test_the_work_is_bounded_and_the_samples_are_drawn_otherwise(long_job, monkeypatch):
    result, request = long_job
    longer = {**request, "t_final": 3000.0}
    del longer["lyapunov"]
    long_result = run_job(longer)  # several segments: the budget is checked between them
    assert long_result["integration"]["steps"] > 2000
    monkeypatch.setattr(plot_orbit, "TIME_BUDGET_S", 0.0)
    slow = plot_orbit.dense_orbit(long_result, longer, ["gamma", "M"])
    assert not slow.dense and "took more than 0 s" in slow.note and len(slow.t) == 201 and slow.cut_short
    assert not plot_orbit._cache  # a fallback the budget caused is not remembered ...
    image = plots.job_plot("trajectory", long_result, longer, "png")
    assert isinstance(image, plot_orbit.TransientImage)  # ... nor is its image (the route's cache skips it)
    from service.routes.pages import _PlotCache

    cache = _PlotCache(4)
    cache.get(("job", "x"), lambda: image, keep=True)
    assert not cache.items
    monkeypatch.setattr(plot_orbit, "TIME_BUDGET_S", 5.0)
    assert type(plots.job_plot("trajectory", long_result, longer, "png")) is bytes  # dense again: kept
    broken = copy.deepcopy(request)
    broken["system"]["inertia"] = "not numbers"
    orbit = plot_orbit.dense_orbit(result, broken, ["gamma", "M"])
    assert not orbit.dense and orbit.note.startswith("201 stored samples (no dense output:")
    # a result that does not come out of its request again is drawn from its samples
    moved = copy.deepcopy(result)
    moved["trajectory"]["gamma"][100][0] += 1e-6
    orbit = plot_orbit.dense_orbit(moved, request, ["gamma", "M"])
    assert not orbit.dense and "off the stored samples" in orbit.note


def test_scipy_jobs_are_drawn_densely_through_their_samples():
    body = {**LONG, "t_final": 40.0, "integrator": {"engine": "scipy"}}
    del body["lyapunov"]
    result = run_job(body)
    orbit = plot_orbit.dense_orbit(result, body, ["gamma", "M"])
    assert orbit.dense and len(orbit.t) > 2000
    at = np.searchsorted(orbit.t, result["trajectory"]["t"])
    np.testing.assert_allclose(orbit.vectors["gamma"][at], result["trajectory"]["gamma"], rtol=0, atol=1e-9)


def test_the_lyapunov_plot_says_finite_time_and_not_converged(long_job):
    result, request = long_job
    spectrum = result["lyapunov"]
    assert plots.not_converged(spectrum), spectrum["warnings"]
    texts = _svg_texts(plots.job_plot("lyapunov", result, request, "svg"))
    assert "finite-time estimates at t = 300 s" in texts and "not converged" in texts
    settled = copy.deepcopy(result)
    settled["lyapunov"]["warnings"] = []
    texts = _svg_texts(plots.job_plot("lyapunov", settled, request, "svg"))
    assert "not converged" not in texts and "converged to within 5 %" in texts


def _members(spectrum: dict, flags: list[bool]) -> list[dict]:
    out = []
    for i, loose in enumerate(flags):
        s = copy.deepcopy(spectrum)
        s["exponents"][0] += 0.01 * i
        s["warnings"] = ["not converged: exponent 1 still moves"] if loose else []
        out.append({"index": i, "status": "succeeded", "label": {"parameter": "D", "value": 0.1 * (i + 1)},
                    "lyapunov": s})
    return out


def test_the_exponent_histogram_says_finite_time_and_which_have_not_converged(long_job):
    result, _ = long_job
    view = {"request": {"system": dict(BALL), "t_final": 300.0,
                        "members": {"sample": {"count": 6, "seed": 1, "level": {"energy": 1.0}}}}}
    members = _members(result["lyapunov"], [True, False, True, False, False, False])
    fig = plot_ensemble._ensemble_exponents_figure(view, members)
    ax = fig.axes[0]
    assert sum(p.get_height() for p in ax.patches) == len(members)
    labels = ax.get_legend_handles_labels()[1]
    assert "converged (4)" in labels and "not converged (2)" in labels
    # where a regular orbit's finite-time exponent still is at T: ln T / T (issue 35, item 6)
    reference = [line for line in ax.get_lines() if line.get_label().startswith("ln T / T")]
    assert len(reference) == 1 and reference[0].get_xdata()[0] == pytest.approx(np.log(300.0) / 300.0, rel=1e-12)
    texts = _svg_texts(plots.ensemble_plot("exponents", view, members, "svg"))
    assert "finite-time estimates at t = 300 s" in texts and "2 of 6 not converged" in texts
    settled = _members(result["lyapunov"], [False] * 6)
    texts = _svg_texts(plots.ensemble_plot("exponents", view, settled, "svg"))
    assert "not converged" not in texts.replace("not converged (0)", "") and "all 6 converged" in texts
    # a sweep: the points not converged are drawn apart
    sweep = {"request": {"system": dict(BALL), "t_final": 300.0,
                         "members": {"sweep": {"parameter": "D", "values": [0.1 * (i + 1) for i in range(6)]}}}}
    ax = plot_ensemble._ensemble_exponents_figure(sweep, members).axes[0]
    marked = {line.get_label(): len(line.get_xdata()) for line in ax.get_lines()}
    assert marked["not converged"] == 2 and marked["converged"] == 4
    texts = _svg_texts(plots.ensemble_plot("exponents", sweep, members, "svg"))
    assert "finite-time estimates at t = 300 s" in texts and "2 of 6 not converged" in texts


def test_a_long_run_is_drawn_as_its_last_stretch_over_the_whole_runs_envelope(long_job):
    """Issue 35, item 6: past LONG_TURNS turns the plot draws a window, by default the last WINDOW_TURNS turns,
    densely (through the stored samples inside it), over the whole run in grey, with M's envelope below."""
    result, request = long_job
    whole = plot_orbit.dense_orbit(result, request, ["gamma", "M"])
    along = plot_trajectory.turns(whole.vectors["gamma"])
    assert along[-1] > plot_trajectory.LONG_TURNS
    start, end = plot_trajectory.default_window(whole.t, whole.vectors["gamma"])
    assert end == 300.0 and 0 < start < 300.0
    inside = along[whole.t >= start]
    assert abs((inside[-1] - inside[0]) - plot_trajectory.WINDOW_TURNS) < 0.05  # the last 4 turns, to a point
    fig = plot_trajectory.trajectory_figure(result, request)
    ax3, ax, strip = fig.axes
    context, drawn = ax3.get_lines()[0], ax3.get_lines()[1]
    assert context.get_label() == "whole run" and len(context.get_data_3d()[0]) > 2000
    curve = np.vstack(drawn.get_data_3d()).T
    t = ax.get_lines()[0].get_xdata()
    assert t[0] >= start and t[-1] == 300.0 and len(t) == len(curve)
    # the window is as dense as the whole run would be: no visible chords, and on the sphere
    assert plot_orbit.sagitta(curve) <= plot_orbit.SAGITTA_TARGET
    np.testing.assert_allclose(np.linalg.norm(curve, axis=1), 1.0, atol=1e-12)
    # through the stored samples inside the window, exactly at their times
    stored_t = np.asarray(result["trajectory"]["t"])
    mine = stored_t[(stored_t >= t[0]) & (stored_t <= t[-1])]
    at = np.searchsorted(t, mine)
    np.testing.assert_array_equal(t[at], mine)
    stored = np.asarray(result["trajectory"]["gamma"])[(stored_t >= t[0]) & (stored_t <= t[-1])]
    np.testing.assert_allclose(curve[at], stored, rtol=0, atol=1e-9)
    # the strip: each M component's range over the whole run (it holds every sample of the window), the window shaded
    m = whole.vectors["M"]
    bands = strip.collections[:3]
    for k, band in enumerate(bands):
        lows = band.get_paths()[0].vertices[:, 1]
        assert lows.min() == pytest.approx(m[:, k].min(), abs=1e-12) and lows.max() == pytest.approx(m[:, k].max(),
                                                                                                     abs=1e-12)
    assert strip.get_xlim() == (0.0, 300.0)
    texts = _svg_texts(plots.job_plot("trajectory", result, request, "svg"))
    assert f"window t in [{start:g}, 300] of [0, 300] s" in texts and "the last 4 of 23 turns" in texts


def test_the_readers_window_is_drawn_densely_even_between_two_stored_samples(long_job):
    result, request = long_job
    fig = plot_trajectory.trajectory_figure(result, request, (100.2, 101.2))  # the samples are 1.5 s apart:
    ax = fig.axes[1]  # one of them (t = 100.5) in the window
    t = ax.get_lines()[0].get_xdata()
    assert t[0] >= 100.2 and t[-1] <= 101.2 and len(t) > 500
    curve = np.vstack(fig.axes[0].get_lines()[1].get_data_3d()).T
    assert plot_orbit.sagitta(curve) <= plot_orbit.SAGITTA_TARGET
    np.testing.assert_allclose(np.linalg.norm(curve, axis=1), 1.0, atol=1e-12)  # the orbit, not an interpolation
    k = int(np.searchsorted(t, 100.5))
    assert t[k] == 100.5
    np.testing.assert_allclose(curve[k], result["trajectory"]["gamma"][67], rtol=0, atol=1e-9)  # stored sample 67
    texts = _svg_texts(plots.job_plot("trajectory", result, request, "svg", (100.2, 101.2)))
    assert "the reader's window" in texts
