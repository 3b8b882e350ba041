"""A job's sampled trajectory and Poincaré section as files: CSV (one header row naming each column and its
unit, t and τ first) streamed row by row, NPZ (the arrays, with the request and the library versions as
JSON) or NetCDF-4 (:mod:`service.exports_netcdf`), and how a download route answers and declares them.

Every download may also be asked for as ``application/octet-stream`` (``Accept``); its OpenAPI ``200``
lists that media type first (:func:`download_responses`) so that a generated client reads the bytes.
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Iterable, Iterator, Mapping, Sequence
from typing import Any

import numpy as np
from fastapi import Request, Response
from fastapi.responses import JSONResponse, StreamingResponse

from service.security import content_disposition

#: CSV rows written per streamed piece.
ROWS_PER_PIECE = 2000
#: The media type of each file format (``?format=``).
MEDIA_TYPES = {"csv": "text/csv", "npz": "application/octet-stream", "netcdf": "application/x-netcdf"}
#: The file name suffix of each format.
SUFFIXES = {"csv": "csv", "npz": "npz", "netcdf": "nc", "json": "json"}
BINARY = "application/octet-stream"
#: The schema of a body that is bytes (a generated client reads it as a file).
_BYTES_SCHEMA = {"type": "string", "format": "binary"}

Column = tuple[str, str, "int | None"]


def _vectors(samples: Mapping[str, Any]) -> list[str]:
    return [k for k in samples if k not in ("t", "tau")]


def vector_components(system_json: Mapping[str, Any]) -> dict[str, list[str]]:
    """The names of the components of every state and derived vector of a request's system
    (:func:`schemas.results.component_names`: ``M1`` ..., a user's ``x``, ``theta``, ``x_dot`` ...); their
    number is the shape of a section's points when there are no rows to read it from."""
    from schemas.results import component_names
    from schemas.systems import definition_of

    return component_names(definition_of(dict(system_json)))


def result_components(result: Mapping[str, Any], request: Mapping[str, Any]) -> dict[str, list[str]]:
    """A job's component names: its result's (``system.components``), or its request's for a result stored
    before results carried them."""
    return dict(result["system"].get("components") or vector_components(request["system"]))


def point_array(values: Any, count: int, width: int) -> np.ndarray:
    """A section's vector as a ``(count, width)`` float64 array (``width``: its components' number)."""
    return np.asarray(values, dtype=np.float64).reshape(count, width)


def component_name(names: Mapping[str, Sequence[str]] | None, vector: str, k: int) -> str:
    """The name of component ``k`` (from 0) of ``vector``: its name in ``names`` (``x``, ``theta`` ...), else
    the vector's name and the component's number from 1 (``M1``)."""
    own = (names or {}).get(vector, ())
    return own[k] if k < len(own) else f"{vector}{k + 1}"


def columns(times: Mapping[str, Any], vectors: Mapping[str, Any], units: Mapping[str, str],
            names: Mapping[str, Sequence[str]] | None = None) -> list[Column]:
    """(header ``name [unit]``, key, component or None) for t, τ (when ``times`` has one) and every
    component of every vector, named by ``names`` (:func:`component_name`: ``M1``, ``x``, ``theta_dot`` ...);
    a vector without rows has ``len(names[vector])`` components."""
    cols: list[Column] = [(f"t [{units.get('t', 's')}]", "t", None)]
    if times.get("tau") is not None:
        cols.append((f"tau [{units.get('tau', '')}]", "tau", None))
    for name, values in vectors.items():
        width = len(values[0]) if len(values) else len((names or {}).get(name, ())) or 3
        cols += [(f"{component_name(names, name, k)} [{units.get(name, '')}]", name, k) for k in range(width)]
    return cols


def trajectory_columns(result: dict[str, Any], names: Mapping[str, Sequence[str]]) -> list[Column]:
    """(header ``name [unit]``, trajectory key, component or None) for t, τ and every vector's components
    (``names``: :func:`result_components`)."""
    trajectory = result["trajectory"]
    return columns(trajectory, {name: trajectory[name] for name in _vectors(trajectory)}, result["system"]["units"],
                   names)


def section_columns(section: dict[str, Any], units: Mapping[str, str],
                    names: Mapping[str, Sequence[str]] | None = None) -> list[Column]:
    """The same for a section (``poincare`` block): t, τ, every point vector's components."""
    return columns(section, section["points"], units, names)


def _csv_rows(cols: Sequence[Column], times: Mapping[str, Any], vectors: Mapping[str, Any], count: int,
              first: Sequence[Any] = ()) -> Iterator[list[Any]]:
    for row in range(count):
        yield [*first, *[repr(float(times[key][row] if k is None else vectors[key][row][k])) for _, key, k in cols]]


def _streamed(header: Sequence[str], rows: Iterable[list[Any]]) -> Iterator[str]:
    """CSV text a piece of :data:`ROWS_PER_PIECE` rows at a time (floats as ``repr``: they read back exactly)."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(header)
    for n, row in enumerate(rows, 1):
        writer.writerow(row)
        if n % ROWS_PER_PIECE == 0:
            yield buffer.getvalue()
            buffer.seek(0)
            buffer.truncate()
    yield buffer.getvalue()


def trajectory_csv(result: dict[str, Any], names: Mapping[str, Sequence[str]]) -> Iterator[str]:
    """The samples as CSV, a piece of :data:`ROWS_PER_PIECE` rows at a time (floats in full precision), the
    columns named by ``names`` (:func:`result_components`)."""
    cols = trajectory_columns(result, names)
    trajectory = result["trajectory"]
    return _streamed([c[0] for c in cols], _csv_rows(cols, trajectory, trajectory, len(trajectory["t"])))


def section_csv(section: dict[str, Any], units: Mapping[str, str],
                names: Mapping[str, Sequence[str]] | None = None) -> Iterator[str]:
    """A job's crossings as CSV: one row per crossing, t, τ and every state and derived component, a
    header naming each column (``names``: :func:`vector_components`) and its unit."""
    cols = section_columns(section, units, names)
    return _streamed([c[0] for c in cols], _csv_rows(cols, section, section["points"], len(section["t"])))


def _npz(arrays: dict[str, np.ndarray], **texts: Any) -> bytes:
    buffer = io.BytesIO()
    texts_json = {f"{name}_json": np.array(json.dumps(value)) for name, value in texts.items()}
    np.savez(buffer, **arrays, **texts_json)  # type: ignore[arg-type]  # numpy's stub: a **name may bind allow_pickle
    return buffer.getvalue()


def trajectory_npz(result: dict[str, Any], request: dict[str, Any]) -> bytes:
    """The samples as NPZ: ``t``, ``tau`` (when the system has one), each vector ``(n, 3)``, ``units_json``,
    ``components_json`` (each vector's components by name), ``request_json`` and ``versions_json`` (0-d
    strings)."""
    trajectory = result["trajectory"]
    arrays = {"t": np.asarray(trajectory["t"], dtype=float)}
    if trajectory.get("tau") is not None:
        arrays["tau"] = np.asarray(trajectory["tau"], dtype=float)
    arrays.update({name: np.asarray(trajectory[name], dtype=float) for name in _vectors(trajectory)})
    return _npz(arrays, units=result["system"]["units"], components=result_components(result, request), request=request,
                versions=result["integration"]["versions"])


def section_npz(result: dict[str, Any], request: dict[str, Any]) -> bytes:
    """A job's crossings as NPZ: ``t``, ``tau`` (when the system has one), each point vector ``(count, k)``,
    ``coordinates`` ``(count, 2)``; ``units_json``, ``components_json``, ``request_json``, ``versions_json`` and
    ``section_json`` (surface, value, direction, coordinate names, residual, drifts, warnings)."""
    section = result["poincare"]
    count = len(section["t"])
    arrays = {"t": np.asarray(section["t"], dtype=float)}
    if section.get("tau") is not None:
        arrays["tau"] = np.asarray(section["tau"], dtype=float)
    names = result_components(result, request)
    arrays.update({name: point_array(values, count, len(names[name])) for name, values in section["points"].items()})
    arrays["coordinates"] = np.asarray(section["coordinates"], dtype=float).reshape(count, 2)
    return _npz(arrays, units=result["system"]["units"], components=names, request=request,
                versions=result["integration"]["versions"], section=section_facts(section))


def section_facts(section: Mapping[str, Any]) -> dict[str, Any]:
    """A section's block without its arrays (what the files keep beside them)."""
    return {k: v for k, v in section.items() if k not in ("t", "tau", "points", "coordinates")}


# --------------------------------------------------------------------------------------------------
# answering and declaring a download


def wants_bytes(request: Request) -> bool:
    """The request's ``Accept`` names ``application/octet-stream`` (and no other media type, nor ``*/*``)."""
    accept = [part.split(";")[0].strip().lower() for part in request.headers.get("accept", "").split(",")]
    accept = [a for a in accept if a]
    return BINARY in accept and all(a == BINARY for a in accept)


def download(request: Request, body: bytes | Iterator[str], media_type: str, filename: str,
             disposition: str = "attachment") -> Response:
    """The answer of a download: ``body`` (streamed when an iterator) as ``media_type``, or as
    ``application/octet-stream`` when the request asks only for that (:func:`wants_bytes`)."""
    headers = content_disposition(disposition, filename)
    media = BINARY if wants_bytes(request) else media_type
    if isinstance(body, bytes):
        return Response(body, media_type=media, headers=headers)
    return StreamingResponse(body, media_type=media, headers=headers)


def json_download(request: Request, body: dict[str, Any], filename: str) -> Response:
    """A download's JSON form: ``application/json`` (inline), or the same bytes as
    ``application/octet-stream`` (an attachment) when the request asks only for that."""
    answer = JSONResponse(body)
    if wants_bytes(request):
        return download(request, bytes(answer.body), "application/json", filename)
    return answer


def download_responses(media_types: Iterable[str], description: str) -> dict[int | str, dict[str, Any]]:
    """The ``responses=`` entry of a download route's ``200``: ``application/octet-stream`` first, then every
    other media type the route answers, each a binary string. A client generated from the document (e.g.
    by openapi-python-client) reads the first media type it knows, so it gets the bytes whatever the format;
    :func:`service.openapi.finalize` keeps ``application/octet-stream`` first where FastAPI put a route's
    JSON model before it."""
    content: dict[str, Any] = {BINARY: {"schema": dict(_BYTES_SCHEMA)}}
    content.update({m: {"schema": dict(_BYTES_SCHEMA)} for m in media_types if m != BINARY})
    return {200: {"description": description + "; application/octet-stream when the request's Accept asks only "
                                               "for it", "content": content}}
