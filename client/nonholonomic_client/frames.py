"""Results as labelled arrays and tables: the API's JSON turned into xarray and pandas objects.

Every value is the JSON's float, unchanged (``float64`` holds a JSON number exactly as Python parses
it), so a Dataset or a DataFrame equals the JSON bit for bit. pandas and xarray are the client's
``[notebook]`` extra and are imported only here, when first asked for.

Column names are those of the CSV downloads without the unit: ``t``, ``tau``, then each vector's
components ``M1 M2 M3 gamma1 ...``; units go to ``attrs["units"]`` (xarray: each variable's
``units`` attribute).
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    import pandas
    import xarray

#: How to install what this module needs.
EXTRA_HINT = "pip install 'nonholonomic-client[notebook]' (pandas, xarray and tqdm)"


def _pandas() -> Any:
    try:
        import pandas
    except ImportError as exc:
        raise ImportError(f"tables need pandas: {EXTRA_HINT}") from exc
    return pandas


def _xarray() -> Any:
    try:
        import xarray
    except ImportError as exc:
        raise ImportError(f"labelled arrays need xarray: {EXTRA_HINT}") from exc
    return xarray


def component_name(names: Mapping[str, Sequence[str]] | None, vector: str, k: int) -> str:
    """The name of component ``k`` (from 0) of ``vector``: as the result names it (``system.components``: ``x``,
    ``theta_dot`` ...), else the vector's name and the number from 1 (``M1``), as the service's exports do."""
    own = (names or {}).get(vector, ())
    return own[k] if k < len(own) else f"{vector}{k + 1}"


def _vectors_of(names: Mapping[str, Sequence[str]] | None) -> dict[str, tuple[str, int]]:
    """Each named component's (vector, number from 1)."""
    return {c: (vector, k + 1) for vector, own in (names or {}).items() for k, c in enumerate(own)}


def components(samples: Mapping[str, Any], skip: Iterable[str] = ("t", "tau", "units"),
               names: Mapping[str, Sequence[str]] | None = None) -> dict[str, np.ndarray]:
    """Each vector of ``samples`` split into its components, in order: ``{"M1": ..., "gamma3": ...}``.

    Parameters
    ----------
    samples : mapping
        ``{"M": [[M1, M2, M3], ...], "gamma": [...], ...}`` (a trajectory, or a section's ``points``).
    skip : iterable of str
        Keys that are not vectors.
    names : mapping, optional
        Each vector's components by name (a result's ``system.components``: a system's own coordinates
        ``x``, ``theta`` ...); default ``M1`` ...

    Returns
    -------
    dict of str to numpy.ndarray
        One float64 array per component.
    """
    out: dict[str, np.ndarray] = {}
    for name, values in samples.items():
        if name in skip or values is None:
            continue
        array = np.asarray(values, dtype=np.float64)
        if array.ndim == 1:  # JSON: no rows says nothing of the width (a section without crossings)
            if array.size == 0:
                continue
            array = array.reshape(len(array), -1)
        for k in range(array.shape[1]):
            out[component_name(names, name, k)] = array[:, k]
    return out


def _unit_of(column: str, units: Mapping[str, str], names: Mapping[str, Sequence[str]] | None = None) -> str:
    """The unit of ``t``, ``tau`` or a component: its vector's (``M2`` → ``units["M"]``, ``theta`` →
    ``units["q"]`` by ``names``), never a parameter's of the same name."""
    if column in ("t", "tau"):
        return units.get(column, "")
    vector = _vectors_of(names).get(column, (column.rstrip("0123456789"), 0))[0]
    return units.get(vector, "")


def evidence(result: Mapping[str, Any]) -> dict[str, Any]:
    """The evidence of a job's result in short: each integral's drift and verdict, each check's verdict.

    Parameters
    ----------
    result : mapping
        A job's ``result``.

    Returns
    -------
    dict
        ``{"integrals": {name: {"max_rel_drift", "tolerance", "passed"}}, "checks": {name: passed}}``.
    """
    return {"integrals": {i["name"]: {"max_rel_drift": i["max_rel_drift"], "tolerance": i["tolerance"],
                                      "passed": i["passed"]} for i in result.get("integrals", [])},
            "checks": {c["name"]: c["passed"] for c in result.get("checks", [])}}


def provenance(view: Mapping[str, Any]) -> dict[str, str]:
    """The attributes that say where numbers come from: the job, its request, versions and evidence.

    Strings only (JSON where structured), so that ``Dataset.to_netcdf`` keeps them.

    Parameters
    ----------
    view : mapping
        The job's view (``GET /v1/jobs/{id}``, the summary is enough).

    Returns
    -------
    dict of str to str
    """
    result = view.get("result") or {}
    system = result.get("system") or {}
    integration = result.get("integration") or {}
    return {"job": str(view.get("id", "")), "system": str(system.get("kind", "")),
            "title": str(system.get("title", "")), "equation": str(system.get("equation", "")),
            "request": json.dumps(view.get("request"), sort_keys=True),
            "versions": json.dumps(integration.get("versions", {}), sort_keys=True),
            "evidence": json.dumps(evidence(result), sort_keys=True),
            "source": "nonholonomic (Borisov & Mamaev, 'Hamiltonization of nonholonomic systems')"}


def trajectory_columns(trajectory: Mapping[str, Any],
                       names: Mapping[str, Sequence[str]] | None = None) -> dict[str, np.ndarray]:
    """``t``, ``tau`` (when there is one) and every component of a trajectory's JSON, as arrays.

    Parameters
    ----------
    trajectory : mapping
        ``GET /v1/jobs/{id}/trajectory`` (format json).
    names : mapping, optional
        The components' names (:func:`components`).

    Returns
    -------
    dict of str to numpy.ndarray
    """
    columns = {"t": np.asarray(trajectory["t"], dtype=np.float64)}
    if trajectory.get("tau") is not None:
        columns["tau"] = np.asarray(trajectory["tau"], dtype=np.float64)
    return {**columns, **components(trajectory, names=names)}


def trajectory_dataset(trajectory: Mapping[str, Any], view: Mapping[str, Any]) -> xarray.Dataset:
    """A job's trajectory as an :class:`xarray.Dataset` over the dimension ``t``.

    Parameters
    ----------
    trajectory : mapping
        ``GET /v1/jobs/{id}/trajectory`` (format json): ``units``, ``t``, ``tau`` and each vector.
    view : mapping
        The job's (summary) view: request, versions and evidence go to ``attrs``.

    Returns
    -------
    xarray.Dataset
        One variable per component (``M1`` ... ``gamma3``) and ``tau``, each with ``units`` and
        ``long_name``; the coordinate ``t`` in the unit of ``units["t"]``.
    """
    xr = _xarray()
    units = trajectory.get("units", {})
    names = result_components(view)
    columns = trajectory_columns(trajectory, names)
    t = columns.pop("t")
    data = {name: ("t", values, {"units": _unit_of(name, units, names), "long_name": _long_name(name, view, names)})
            for name, values in columns.items()}
    coords = {"t": ("t", t, {"units": units.get("t", "s"), "long_name": "physical time t"})}
    return xr.Dataset(data, coords=coords, attrs=provenance(view))


def result_components(view: Mapping[str, Any]) -> dict[str, list[str]] | None:
    """The components' names of a job's result (``result.system.components``), or None (a result without them:
    ``M1`` ...)."""
    return ((view.get("result") or {}).get("system") or {}).get("components")


def _long_name(column: str, view: Mapping[str, Any], names: Mapping[str, Sequence[str]] | None = None) -> str:
    if column == "tau":
        time = ((view.get("result") or {}).get("time") or {})
        return str(time.get("tau") or "reduced time tau")
    named = _vectors_of(names).get(column)
    if named is not None:
        return f"{column}: component {named[1]} of {named[0]}"
    vector = column.rstrip("0123456789")
    return f"{vector} component {column[len(vector):]}"


def trajectory_frame(trajectory: Mapping[str, Any], view: Mapping[str, Any]) -> pandas.DataFrame:
    """A job's trajectory as a :class:`pandas.DataFrame`, one row per sample, indexed by ``t``.

    Parameters
    ----------
    trajectory, view : mapping
        As for :func:`trajectory_dataset`.

    Returns
    -------
    pandas.DataFrame
        Columns ``tau``, ``M1`` ...; ``attrs`` holds ``units`` and the provenance.
    """
    pd = _pandas()
    columns = trajectory_columns(trajectory, result_components(view))
    frame = pd.DataFrame(columns).set_index("t")
    frame.attrs = {"units": dict(trajectory.get("units", {})), **provenance(view)}
    return frame


def section_frame(sections: Iterable[tuple[int | None, Mapping[str, Any]]], units: Mapping[str, str],
                  attrs: Mapping[str, Any], names: Mapping[str, Sequence[str]] | None = None) -> pandas.DataFrame:
    """Poincaré crossings as a table: one row per crossing, ``member`` (ensembles), ``t``, ``tau`` and
    every component of the state at the crossing.

    Parameters
    ----------
    sections : iterable of (member or None, section)
        Each section as the JSON has it: ``t``, ``tau``, ``points`` (``{"M": [[...]], ...}``).
    units : mapping
        The system's units (``t``, ``tau``, ``M``, ...).
    attrs : mapping
        Stored in ``frame.attrs`` with the units.
    names : mapping, optional
        The components' names (:func:`components`).

    Returns
    -------
    pandas.DataFrame
    """
    pd = _pandas()
    frames = []
    for member, section in sections:
        columns: dict[str, Any] = {}
        t = np.asarray(section["t"] if section.get("t") is not None else [], dtype=np.float64)
        if member is not None:
            columns["member"] = np.full(len(t), member, dtype=np.int64)
        columns["t"] = t
        if section.get("tau") is not None:
            columns["tau"] = np.asarray(section["tau"], dtype=np.float64)
        columns.update(components(section.get("points") or {}, names=names))
        frames.append(pd.DataFrame(columns))
    frame = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame({"t": np.zeros(0)})
    frame.index.name = "crossing"
    frame.attrs = {"units": dict(units), **attrs}
    return frame


def section_npz_frame(arrays: Mapping[str, np.ndarray], attrs: Mapping[str, Any]) -> pandas.DataFrame:
    """An ensemble's section NPZ (``member``, ``t``, ``tau``, each vector ``(n, 3)``) as a table.

    Parameters
    ----------
    arrays : mapping
        ``numpy.load`` of ``GET /v1/ensembles/{id}/poincare?format=npz``.
    attrs : mapping
        Stored in ``frame.attrs``.

    Returns
    -------
    pandas.DataFrame
    """
    units = json.loads(str(arrays["units_json"])) if "units_json" in arrays else {}
    names = json.loads(str(arrays["components_json"])) if "components_json" in arrays else None
    request = str(arrays["request_json"]) if "request_json" in arrays else ""
    section = {"t": arrays.get("t", np.zeros(0)), "tau": arrays.get("tau"),
               "points": {k: v for k, v in arrays.items()
                          if k not in ("member", "t", "tau") and not k.endswith("_json")}}
    frame = section_frame([(None, section)], units, {**attrs, "request": request}, names)
    if "member" in arrays:
        frame.insert(0, "member", np.asarray(arrays["member"], dtype=np.int64))
    return frame


def members_frame(members: Iterable[Mapping[str, Any]],
                  names: Mapping[str, Sequence[str]] | None = None) -> pandas.DataFrame:
    """An ensemble's members as a table, one row per member indexed by ``member``.

    Columns: ``status``; what sets the member apart: a sweep's value named after its parameter (``D``,
    ``inertia[1]``), a chaos map cell's ``cell_i``, ``cell_j``, its two coordinates (``gamma1``, ``M3``) and
    ``branches``; ``t_final``, ``tau_final``, ``initial_M1`` ... and ``final_M1`` ... (a system of one's
    own: ``initial_x``, ``final_theta_dot`` ..., by ``names``, the members page's ``components``),
    ``drift_<integral>`` (each integral's max relative drift), ``checks_passed``, ``exponent_1`` ...
    (the Lyapunov exponents asked for), ``section_points`` and ``error``.

    Parameters
    ----------
    members : iterable of mapping
        The ``members`` of ``GET /v1/ensembles/{id}/members`` pages.
    names : mapping, optional
        Each vector's component names (the pages' ``components``); default ``M1`` ...

    Returns
    -------
    pandas.DataFrame
    """
    pd = _pandas()
    rows = []
    for m in members:
        row: dict[str, Any] = {"member": m["index"], "status": m.get("status"), **_label_columns(m.get("label")),
                               "t_final": m.get("t_final"), "tau_final": m.get("tau_final")}
        for when in ("initial", "final"):
            state = {k: [v] for k, v in (m.get(f"{when}_state") or {}).items()}
            for name, value in components(state, names=names).items():
                row[f"{when}_{name}"] = value[0]
        for integral in m.get("integrals") or []:
            row[f"drift_{integral['name']}"] = integral["max_rel_drift"]
        checks = m.get("checks") or []
        row["checks_passed"] = all(c.get("passed") is not False for c in checks) if checks else None
        for k, value in enumerate((m.get("lyapunov") or {}).get("exponents") or []):
            row[f"exponent_{k + 1}"] = value
        if m.get("poincare") is not None:
            row["section_points"] = m["poincare"].get("count")
        row["error"] = m.get("error")
        rows.append(row)
    if not rows:  # no member done yet: the table's shape without rows
        return pd.DataFrame({"status": pd.Series(dtype=object)}, index=pd.Index([], name="member"))
    return pd.DataFrame(rows).set_index("member")


def _label_columns(label: Mapping[str, Any] | None) -> dict[str, Any]:
    """A member's label as columns: ``{parameter: value}`` of a sweep; a grid cell's indices, coordinates and
    branches (issue 35, item 2: the table carries what was swept, no join with the request needed)."""
    if not label:
        return {}
    if "parameter" in label:
        return {str(label["parameter"]): label.get("value")}
    out: dict[str, Any] = {}
    for key, value in label.items():
        if key == "cell" and isinstance(value, (list, tuple)) and len(value) == 2:
            out["cell_i"], out["cell_j"] = value
        else:
            out[str(key)] = value
    return out


def exponents_frame(lyapunov: Mapping[str, Any]) -> pandas.DataFrame:
    """A Lyapunov spectrum as a table, one row per exponent (``i`` = 1, 2, ..., descending).

    Columns: ``exponent`` (1/s), ``moved_last_20pct`` (how far the finite-time estimate still moved
    over the last fifth of the run) and ``expected_zero`` (whether a symmetry or an integral says it
    vanishes). ``attrs`` keeps the sum, its expected value and reason, and the warnings (e.g. "not
    converged").

    Parameters
    ----------
    lyapunov : mapping
        A result's ``lyapunov``.

    Returns
    -------
    pandas.DataFrame
    """
    pd = _pandas()
    exponents = np.asarray(lyapunov.get("all_exponents") or lyapunov.get("exponents") or [], dtype=np.float64)
    moved = np.full(len(exponents), np.nan)  # given for the `count` exponents asked for, NaN for the others
    given = np.asarray([np.nan if m is None else m for m in lyapunov.get("moved_last_20pct") or []], dtype=np.float64)
    moved[:min(len(given), len(moved))] = given[:len(moved)]
    zero = set(lyapunov.get("zero_indices") or [])
    frame = pd.DataFrame({"i": np.arange(1, len(exponents) + 1), "exponent": exponents,
                          "moved_last_20pct": moved,
                          "expected_zero": [k in zero for k in range(len(exponents))]}).set_index("i")
    frame.attrs = {k: lyapunov.get(k) for k in ("sum", "sum_expected", "sum_reason", "divergence_average",
                                                "measure_average", "t_final", "interval", "warnings")}
    frame.attrs["units"] = {"exponent": "1/s"}
    return frame


def convergence_frame(lyapunov: Mapping[str, Any]) -> pandas.DataFrame:
    """The running finite-time estimates of a spectrum, indexed by ``t``: column ``exponent_k``.

    Parameters
    ----------
    lyapunov : mapping
        A result's ``lyapunov``.

    Returns
    -------
    pandas.DataFrame
    """
    pd = _pandas()
    rows = np.asarray(lyapunov.get("convergence") or [], dtype=np.float64)
    rows = rows.reshape(len(rows), -1) if rows.size else np.zeros((0, len(lyapunov.get("exponents") or [])))
    frame = pd.DataFrame({f"exponent_{k + 1}": rows[:, k] for k in range(rows.shape[1])},
                         index=pd.Index(np.asarray(lyapunov.get("convergence_t") or [], dtype=np.float64),
                                        name="t"))
    frame.attrs["units"] = {"t": "s", "exponent": "1/s"}
    return frame


def map_dataset(data: Mapping[str, Any], view: Mapping[str, Any]) -> xarray.Dataset:
    """A chaos map's JSON (``GET /v1/ensembles/{id}/map?format=json``) as an ``xarray.Dataset``: dimensions
    the two coordinates (the cells' centres, with units); ``status`` (words), ``branches``, each indicator
    and ``drift_<integral>`` (NaN where a cell was not integrated); attrs the summary, thresholds and request."""
    xr = _xarray()
    names = list(data["coordinates"])
    coords = {c: (c, np.asarray(data["axes"][k], dtype=float), {"units": data["units"][c]})
              for k, c in enumerate(names)}

    def grid(values: Iterable[Iterable[float | None]]) -> np.ndarray:
        return np.array([[np.nan if v is None else v for v in row] for row in values], dtype=float)

    variables: dict[str, Any] = {"status": (names, np.array(data["status"], dtype=str)),
                                 "branches": (names, np.array(data["branches"], dtype=np.int64))}
    for name, values in data["indicators"].items():
        variables[name] = (names, grid(values))
    for name, values in data["integral_drift"].items():
        variables[f"drift_{name}"] = (names, grid(values), {"units": "1"})
    summary = data.get("summary") or {}
    attrs = {"ensemble": view.get("id", ""), "summary": json.dumps(summary),
             "thresholds": json.dumps(summary.get("thresholds", {})),
             "chaotic_fraction": summary.get("chaotic_fraction") if summary.get("chaotic_fraction") is not None
             else float("nan"),
             "request": json.dumps(view.get("request", {}))}
    return xr.Dataset(variables, coords=coords, attrs=attrs)


def periodic_orbit_frame(orbit: Mapping[str, Any]) -> pandas.DataFrame:
    """A job's periodic orbit and its continuation as a table, one row per parameter value (issue 35, item 4).

    The index is the continued parameter, named after it (``D``); without a continuation, one row at the
    orbit's own (index ``orbit``). Columns: ``status``, ``period_t`` [s], ``trace``, ``stability``,
    ``residual``, ``checks_passed``, each section multiplier's ``multiplier_k_re``, ``_im`` and
    ``_modulus``, and the bifurcations, each flagged on the first point past it: ``fold``,
    ``period_doubling``, ``lost``. ``attrs`` keeps the orbit (surface, period, level, multipliers, checks,
    reason), the events with their details and the values skipped after the branch was lost.

    Parameters
    ----------
    orbit : mapping
        A result's ``periodic_orbit``.

    Returns
    -------
    pandas.DataFrame
    """
    pd = _pandas()
    continuation = orbit.get("continuation")
    if continuation:
        points, name = list(continuation.get("points") or []), str(continuation.get("parameter"))
        events = list(continuation.get("events") or [])
    else:
        points, name, events = [{**orbit, "value": "orbit", "checks_passed": None}], "orbit", []
    rows = []
    for point in points:
        row: dict[str, Any] = {name: point.get("value")}
        for key in ("status", "period_t", "trace", "stability", "residual", "checks_passed"):
            row[key] = point.get(key)
        for k, m in enumerate(point.get("section_multipliers") or []):
            for part in ("re", "im", "modulus"):
                row[f"multiplier_{k + 1}_{part}"] = m.get(part)
        for kind in ("fold", "period_doubling", "lost"):
            row[kind] = any(e.get("kind") == kind and (e.get("between") or [None, None])[-1] == point.get("value")
                            for e in events)
        rows.append(row)
    frame = pd.DataFrame(rows).set_index(name)
    frame.attrs = {"orbit": {k: orbit.get(k) for k in ("status", "reason", "surface", "value", "direction", "period",
                                                       "level", "period_t", "period_tau", "multipliers", "trace",
                                                       "stability", "checks", "warnings")},
                   "events": events, "skipped": list((continuation or {}).get("skipped") or []),
                   "units": {"period_t": "s", **dict(orbit.get("units") or {})}}
    return frame

