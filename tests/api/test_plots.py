"""Plots of results (service layer, :mod:`service.plots`): real job results made in-process, an ensemble
through the API in embedded mode; PNG and SVG bytes, what each figure draws, and the integrals' drift
against an independent numpy computation."""

from __future__ import annotations

import io
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from matplotlib.image import imread

from nonholonomic.systems import SYSTEMS, get_system
from service import plot_branch, plot_ensemble, plot_orbit, plot_periodic, plot_trajectory, plots
from service.plots import PNG_DPI, PlotUnavailable, ensemble_plot, job_plot
from tests.api.conftest import BALL, STATE
from tests.support import poll_job
from workers.jobs import run_job

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"

#: The ball with a linear potential, a section and the spectrum (like a researcher's first job).
BALL_JOB = {
    "system": {**BALL, "potential": {"kind": "linear", "a": [0.3, -0.2, 0.5]}},
    "initial_state": dict(STATE), "t_final": 200.0, "samples": 401, "checks": ["integrals"],
    "poincare": {"surface": "gamma3", "value": 0.0, "direction": "increasing", "coordinates": ["gamma1", "M3"]},
    "lyapunov": {"interval": 1.0},
    "periodic_orbit": {"surface": "gamma3", "coordinates": ["gamma1", "M3"]},
}
#: The island's centre (tests/api/test_periodic_orbits_api.py) followed in energy: a short branch.
BRANCH_JOB = {
    "system": {**BALL, "potential": {"kind": "linear", "a": [0.3, -0.2, 0.5]}},
    "initial_state": {"M": [-3.436852983, -0.7015446800, 0.0], "gamma": [-0.2, 0.9797958971, 0.0]},
    "project_initial_state": True, "t_final": 20.0, "samples": 11,
    "periodic_orbit": {"surface": "gamma3", "coordinates": ["gamma1", "M3"],
                       "branch": {"in": "energy", "to": 2.3, "max_points": 6}},
}


def _example(kind: str, **overrides) -> dict:
    body = {**SYSTEMS[kind].EXAMPLE, "t_final": 200.0, "checks": ["integrals"]}
    body.update(overrides)
    return body


@pytest.fixture(scope="module")
def ball() -> tuple[dict, dict]:
    return run_job(BALL_JOB), BALL_JOB


@pytest.fixture(scope="module")
def veselova() -> tuple[dict, dict]:
    body = _example("veselova")
    return run_job(body), body


@pytest.fixture(scope="module")
def quadric() -> tuple[dict, dict]:
    body = _example("ball_on_quadric")
    return run_job(body), body


def _png_size(data: bytes) -> tuple[int, int]:
    assert data.startswith(PNG_SIGNATURE)
    image = imread(io.BytesIO(data), format="png")
    return image.shape[1], image.shape[0]


def _svg_texts(data: bytes) -> str:
    root = ET.fromstring(data)  # well-formed XML
    assert root.tag.endswith("svg")
    return "\n".join("".join(e.itertext()) for e in root.iter() if e.tag.endswith("text"))


def _expected_size(fig) -> tuple[int, int]:
    w, h = fig.get_size_inches() * PNG_DPI
    return round(w), round(h)


@pytest.mark.parametrize("name", plots.JOB_PLOTS)
def test_every_job_plot_renders_png_of_its_size_and_svg_with_labels(ball, name):
    result, request = (run_job(BRANCH_JOB), BRANCH_JOB) if name == "bifurcation" else ball
    png = job_plot(name, result, request, "png")
    figures = {**plots._JOB_FIGURES, "periodic_orbit": plot_periodic.periodic_orbit_figure,
               "bifurcation": plot_branch.bifurcation_figure,
               "trajectory": plot_trajectory.trajectory_figure}
    assert _png_size(png) == _expected_size(figures[name](result, request))
    texts = _svg_texts(job_plot(name, result, request, "svg"))
    assert "t [s]" in texts or name in ("poincare", "periodic_orbit", "bifurcation")  # time axis with its unit
    assert "Chaplygin's ball" in texts and "chaplygin_ball" in texts  # the title names the system
    expected = {"trajectory": ["γ₁ [1]", "γ₃ [1]", "M [kg m^2/s]", "eq. 2604-1", "|gamma| = 1"],
                "integrals": ["H = (M, omega)/2 + U(gamma)", "c = (M, gamma)", "verdict tolerance 1e-10"],
                "poincare": ["γ₁ [1]", "M₃ [kg m^2/s]", "gamma3 = 0", "increasing"],
                "lyapunov": ["λ₁ = ", "1/s", "[1/s]"],
                "periodic_orbit": ["Re μ", "Im μ", "unit circle", "period-1 orbit", "gamma3 = 0"],
                "bifurcation": ["energy [J]", "γ₁ [1] of x0 on the section", "period 1, stable",
                                "trace of the section map", "branch of the period-1 orbit in energy"]}[name]
    for label in expected:
        assert label in texts, (label, texts)


def test_plots_drawn_from_threads_are_the_bytes_drawn_alone(ball):
    from concurrent.futures import ThreadPoolExecutor

    result, request = ball
    alone = {fmt: job_plot("poincare", result, request, fmt) for fmt in plots.FORMATS}
    with ThreadPoolExecutor(4) as pool:
        drawn = list(pool.map(lambda fmt: (fmt, job_plot("poincare", result, request, fmt)), list(plots.FORMATS) * 3))
    assert all(data == alone[fmt] for fmt, data in drawn)


def test_unknown_plot_or_format_is_a_value_error(ball):
    result, request = ball
    for call in (lambda: job_plot("phase", result, request, "png"),
                 lambda: job_plot("trajectory", result, request, "pdf"),
                 lambda: ensemble_plot("trajectory", {}, [], "png")):
        with pytest.raises(ValueError) as info:
            call()
        assert not isinstance(info.value, PlotUnavailable)


def test_plots_a_job_did_not_ask_for_are_unavailable(veselova):
    result, request = veselova
    with pytest.raises(PlotUnavailable, match="asked for no poincare section"):
        job_plot("poincare", result, request, "png")
    with pytest.raises(PlotUnavailable, match="no Lyapunov spectrum"):
        job_plot("lyapunov", result, request, "svg")
    with pytest.raises(PlotUnavailable, match="no simulation result"):
        job_plot("trajectory", {"claims": []}, {"job": "paper_report"}, "png")


def test_integral_drifts_equal_an_independent_numpy_computation(ball):
    """H = ½(M, ω) + (a, γ), (γ, γ), c = (M, γ) from the sampled trajectory; drift over the job's reference."""
    result, request = ball
    tr = result["trajectory"]
    M, gamma, omega = (np.asarray(tr[k]) for k in ("M", "gamma", "omega"))
    a = np.asarray(request["system"]["potential"]["a"])
    numpy_integrals = {"energy": 0.5 * np.sum(M * omega, axis=1) + gamma @ a,
                       "geometric": np.sum(gamma * gamma, axis=1), "area": np.sum(M * gamma, axis=1)}
    fig = plots._integrals_figure(result, request)
    ax = fig.axes[0]
    assert ax.get_yscale() == "log"
    lines = {line.get_label().split(":")[0]: line for line in ax.get_lines()}
    tolerance = next(line for line in ax.get_lines() if line.get_label().startswith("verdict"))
    assert tolerance.get_linestyle() == "--" and tolerance.get_ydata()[0] == pytest.approx(1e-10)
    for item in result["integrals"]:
        line = lines[item["name"]]
        assert np.array_equal(line.get_xdata(), tr["t"])  # 401 samples: nothing thinned
        I = numpy_integrals[item["name"]]
        independent = np.maximum(np.abs(I - I[0]) / item["reference"], plots.DRIFT_FLOOR)
        # the compiled integrals and numpy round differently: a few units of 1e-16 in a drift
        np.testing.assert_allclose(line.get_ydata(), independent, rtol=0, atol=1e-15)
        plotted_max = float(np.max(line.get_ydata()))
        # the reported max also covers every accepted step: ours (samples only) is at most it, same order
        assert plotted_max <= item["max_rel_drift"] + 4.5e-16
        assert plotted_max >= item["max_rel_drift"] / 10
        assert plotted_max < item["tolerance"]


def test_integral_series_agrees_with_the_job_report(ball):
    from nonholonomic.evidence.integrals import integral_series
    from schemas.jobs import JobRequest

    result, request = ball
    job = JobRequest.model_validate(request)
    system = job.system.definition()
    states = np.hstack([np.asarray(result["trajectory"][v.name]) for v in system.state])
    series = integral_series(system, job.system.parameter_values(), states)
    assert list(series) == [i["name"] for i in result["integrals"]]
    for item in result["integrals"]:
        values, scales = series[item["name"]]
        assert values.shape == scales.shape == (len(states),)
        assert values[0] == pytest.approx(item["initial"], rel=1e-14, abs=1e-15)
        assert values[-1] == pytest.approx(item["final"], rel=1e-14, abs=1e-15)
        assert np.max(np.abs(scales)) <= item["reference"] * (1 + 1e-12)


def test_integrals_heyoka_cannot_compile_come_from_the_numpy_kernels():
    """Neumann's scales hold |c| (no Abs in heyoka's from_sympy): the series falls back to numpy, same drifts."""
    body = _example("neumann", t_final=50.0, samples=101)
    result = run_job(body)
    lines = {line.get_label().split(":")[0]: line for line in plots._integrals_figure(result, body).axes[0].get_lines()}
    for item in result["integrals"]:
        plotted_max = float(np.max(lines[item["name"]].get_ydata()))
        assert item["max_rel_drift"] / 10 <= plotted_max <= item["max_rel_drift"] + 4.5e-16


def test_poincare_plot_draws_every_crossing(ball):
    result, _ = ball
    section = result["poincare"]
    assert section["count"] > 5
    ax = plots._poincare_figure(result, {}).axes[0]
    offsets = ax.collections[0].get_offsets()
    assert len(offsets) == section["count"]
    np.testing.assert_array_equal(np.asarray(offsets), np.asarray(section["coordinates"]))
    assert ax.get_xlabel() == "γ₁ [1]" and ax.get_ylabel() == "M₃ [kg m^2/s]"


def test_lyapunov_plot_one_line_per_exponent_on_log_time(ball):
    result, _ = ball
    spectrum = result["lyapunov"]
    ax = plots._lyapunov_figure(result, {}).axes[0]
    assert ax.get_xscale() == "log"
    lines = [line for line in ax.get_lines() if line.get_label().startswith("λ")]
    assert len(lines) == len(spectrum["exponents"])
    for line, final in zip(lines, spectrum["exponents"]):
        assert line.get_ydata()[-1] == pytest.approx(final)
        assert f"{final:+.4g} 1/s" in line.get_label()


def test_geometric_and_momentum_vectors_come_from_the_definitions():
    found = {}
    for kind, module in SYSTEMS.items():
        system = get_system(kind, next(iter(module.POTENTIALS)))
        geometric, constraint = plots._geometric_vector(system)
        momentum = plots._momentum_vector(system, geometric)
        found[kind] = (geometric.name, momentum.name, constraint is not None)
    assert found == {"chaplygin_ball": ("gamma", "M", True), "veselova": ("gamma", "omega", True),
                     "chaplygin_ball_veselova": ("gamma", "omega", True), "rubber_ball": ("gamma", "omega", True),
                     "ball_on_quadric": ("x", "omega", True), "ball_on_surface": ("x", "omega", True),
                     "neumann": ("s", "L", True),
                     "clebsch": ("s", "L", True), "veselova_e3": ("Gamma", "M", True)}


def _mesh(result: dict) -> np.ndarray:
    """The points of the wireframe a trajectory plot draws, one per row."""
    _, constraint = plots._geometric_vector(get_system(result["system"]["kind"], result["system"]["potential"]))
    mesh = plots._surface_mesh(constraint, result["system"]["parameters"])
    return np.stack([m.ravel() for m in mesh], axis=1)


def test_veselova_trajectory_gamma_on_the_unit_sphere_and_omega(veselova):
    result, request = veselova
    whole = (0.0, result["t_final"])  # the example's run is long enough to be drawn as its last stretch by default
    fig = plot_trajectory.trajectory_figure(result, request, whole)
    ax3, ax = fig.axes
    assert ax3.name == "3d" and ax3.get_xlabel() == "γ₁ [1]" and ax.get_ylabel() == "ω [rad/s]"
    assert len(ax3.collections) == 1  # the wireframe
    np.testing.assert_allclose(np.linalg.norm(_mesh(result), axis=1), 1.0, atol=1e-12)
    curve = ax3.get_lines()[0].get_data_3d()
    np.testing.assert_allclose(np.linalg.norm(np.vstack(curve), axis=0), 1.0, atol=1e-12)
    assert [line.get_label() for line in ax.get_lines()] == ["ω₁", "ω₂", "ω₃"]
    assert _png_size(job_plot("trajectory", result, request, "png", whole)) == _expected_size(fig)


def test_ball_on_quadric_trajectory_x_on_the_ellipsoid(quadric):
    result, request = quadric
    B = np.diag(request["system"]["B"])
    fig = plot_trajectory.trajectory_figure(result, request)
    ax3 = fig.axes[0]
    assert ax3.get_zlabel() == "x₃ [m]" and fig.axes[1].get_ylabel() == "ω [rad/s]"

    def on_quadric(x: np.ndarray) -> np.ndarray:
        return np.einsum("ni,ij,nj->n", x, np.linalg.inv(B), x)

    assert len(ax3.collections) == 1  # the wireframe
    np.testing.assert_allclose(on_quadric(_mesh(result)), 1.0, atol=1e-12)
    np.testing.assert_allclose(on_quadric(np.vstack(ax3.get_lines()[0].get_data_3d()).T), 1.0, atol=1e-9)
    texts = _svg_texts(job_plot("trajectory", result, request, "svg"))
    assert "x₁ [m]" in texts and "(x, B^-1 x) - 1 = 0" in texts
    assert _svg_texts(job_plot("integrals", result, request, "svg")).count("eq. 2804") >= 1


def test_a_long_trajectory_is_plotted_from_capped_points():
    """A long run (10,001 samples and every step's state) draws at most MAX_POINTS and MAX_LINE_POINTS
    points, so each plot stays small. How long each takes is bench/bench_exports.py's (every plot of a long
    job, PNG and SVG, drawn and cached over HTTP against the same plot drawn in-process), not a test's."""
    body = {**BALL_JOB, "t_final": 1000.0, "samples": 10_001}
    del body["poincare"], body["lyapunov"]
    result = run_job(body)
    for name in ("trajectory", "integrals"):
        for fmt in plots.FORMATS:
            data = job_plot(name, result, body, fmt)
            assert len(data) < 3_000_000, (name, fmt, len(data))
    fig = plot_trajectory.trajectory_figure(result, body, (0.0, 1000.0))
    assert len(fig.axes[0].get_lines()[0].get_data_3d()[0]) <= plot_orbit.MAX_POINTS  # dense output, capped
    drift = plots._integrals_figure(result, body).axes[0].get_lines()[0]
    energy = result["integrals"][0]
    assert len(drift.get_ydata()) <= plots.MAX_LINE_POINTS
    assert energy["max_rel_drift"] / 10 <= drift.get_ydata().max() <= energy["max_rel_drift"] + 4.5e-16  # peaks kept


def _ensemble(client, body: dict) -> tuple[dict, list[dict]]:
    r = client.post("/v1/ensembles", json=body)
    assert r.status_code == 202, r.text
    view = poll_job(client, r.headers["location"])
    assert view["status"] == "succeeded", view
    page = client.get(f"{r.headers['location']}/members", params={"limit": 1000}).json()
    return view, page["members"]


def test_ensemble_section_and_exponents(client):
    level = {"energy": 1.0, "area": 0.0}
    sampled = {"system": dict(BALL), "members": {"sample": {"count": 5, "seed": 3, "level": level}},
               "t_final": 60.0, "samples": 3, "checks": ["integrals"],
               "poincare": {"surface": "gamma3", "coordinates": ["gamma1", "gamma2"]},
               "lyapunov": {"count": 1, "interval": 1.0}}
    view, members = _ensemble(client, sampled)
    ax = plot_ensemble._ensemble_poincare_figure(view, iter(members)).axes[0]
    drawn = ax.collections[0]
    assert len(drawn.get_offsets()) == sum(m["poincare"]["count"] for m in members)
    assert sorted(set(drawn.get_array().tolist())) == [m["index"] for m in members if m["poincare"]["count"]]
    assert drawn.get_rasterized() and ax.get_xlabel() == "γ₁ [1]"
    assert plots.ENSEMBLE_PLOTS == ("poincare", "exponents", "map", "orbit_diagram")  # the last two: their own tests
    with pytest.raises(PlotUnavailable, match="not a chaos map"):
        ensemble_plot("map", view, iter(members), "png")
    for name in ("poincare", "exponents"):
        assert _png_size(ensemble_plot(name, view, iter(members), "png"))[0] > 100
        texts = _svg_texts(ensemble_plot(name, view, members, "svg"))
        assert "chaplygin_ball" in texts and ("γ₂ [1]" in texts if name == "poincare" else "[1/s]" in texts)
    histogram = plot_ensemble._ensemble_exponents_figure(view, members).axes[0]
    assert sum(p.get_height() for p in histogram.patches) == len(members)

    no_analysis = [{k: v for k, v in m.items() if k not in ("poincare", "lyapunov")} for m in members]
    for name in ("poincare", "exponents"):
        with pytest.raises(PlotUnavailable, match="no member"):
            ensemble_plot(name, view, no_analysis, "png")

    values = [0.9, 0.3, 0.6]
    members = {"sweep": {"parameter": "D", "values": values, "initial_state": dict(STATE)}}
    sweep = {"system": dict(BALL), "members": members,
             "t_final": 30.0, "samples": 3, "checks": ["integrals"], "lyapunov": {"count": 1, "interval": 1.0}}
    view, members = _ensemble(client, sweep)
    ax = plot_ensemble._ensemble_exponents_figure(view, members).axes[0]
    line = ax.get_lines()[0]
    assert line.get_xdata().tolist() == sorted(values)
    largest = {m["label"]["value"]: m["lyapunov"]["exponents"][0] for m in members}
    assert line.get_ydata().tolist() == [largest[v] for v in sorted(values)]
    assert ax.get_xlabel() == "D [kg m^2]"
    with pytest.raises(PlotUnavailable, match="no member has a poincare section"):
        ensemble_plot("poincare", view, members, "svg")
