"""Reading an ensemble's record: its view (status, progress, summary), pages of members, and every
member's section points as rows for the exports. The same for both modes
(:class:`store.ensembles.EnsembleStore`)."""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Iterator
from typing import Any

import numpy as np

from nonholonomic.analysis.chaos_map import map_summary
from nonholonomic.analysis.chaos_map.indicators import thresholds_for
from nonholonomic.analysis.ensemble import summarize
from schemas.results import system_units
from schemas.systems import definition_of
from service.exports import point_array, section_columns, vector_components
from store.ensembles import EnsembleStore


def view(ensemble_id: str, record: dict[str, Any]) -> dict[str, Any]:
    """``GET /v1/ensembles/{id}``: status, progress = members done / members, the summary so far."""
    chunks = record["chunks"]
    total = sum(stop - start for start, stop in chunks)
    done = record["done"]
    members_done = sum(stop - start if i in done else min(record["progress"].get(i, 0), stop - start)
                       for i, (start, stop) in enumerate(chunks))
    if record["cancelled"] and len(done) < len(chunks):
        status = "cancelled"
    elif len(done) == len(chunks):
        status = "succeeded"
    elif done or record["progress"]:
        status = "running"
    else:
        status = "queued"
    digests = [d for i in sorted(record["digests"]) for d in record["digests"][i]]
    workers: dict[str, int] = {}
    for name in record["workers"].values():
        workers[name] = workers.get(name, 0) + 1
    return {"id": ensemble_id, "status": status, "progress": members_done / total if total else 1.0,
            "created_at": record["created_at"], "request": record["request"], "members": total,
            "members_done": members_done,
            "chunks": {"total": len(chunks), "done": len(done), "size": chunks[0][1] - chunks[0][0],
                       "workers": workers,
                       "reruns": sum(max(0, n - 1) for n in record.get("starts", {}).values())},
            "summary": _summary(record["request"], digests) if digests else None}


def members_label(request: dict[str, Any]) -> str:
    """What varies across an ensemble's members, in a few words (the list's ``label``)."""
    members = request.get("members") or {}
    if members.get("sweep"):
        return f"sweep of {members['sweep'].get('parameter')}"
    if members.get("grid"):
        return f"grid (chaos map) of {', '.join(members['grid'].get('coordinates') or [])}"
    if members.get("sample"):
        return "level set"
    return "list"


def list_item(record: dict[str, Any]) -> dict[str, Any]:
    """An ensemble of ``GET /v1/ensembles``: its view's status and progress, without request or summary."""
    shown = view(record["id"], record)
    system = record["request"].get("system") or {}
    return {"id": record["id"], "status": shown["status"], "progress": shown["progress"],
            "created_at": record["created_at"], "kind": system.get("kind"), "members": shown["members"],
            "members_done": shown["members_done"], "label": members_label(record["request"]),
            "location": f"/v1/ensembles/{record['id']}"}


def _summary(request: dict[str, Any], digests: list[dict[str, Any]]) -> dict[str, Any]:
    """The members' summary, with the map's (counts per status, chaotic fraction, thresholds) for a map."""
    summary = summarize(digests)
    if request.get("indicators"):
        summary["map"] = map_summary(digests, request["indicators"],
                                     thresholds_for(request["t_final"], request.get("thresholds")))
    return summary


def members_page(store: EnsembleStore, ensemble_id: str, record: dict[str, Any], offset: int,
                 limit: int) -> list[dict[str, Any]]:
    """Members ``offset .. offset + limit − 1`` of the finished chunks (members of unfinished chunks
    are left out; the view's progress says how many are done)."""
    out: list[dict[str, Any]] = []
    for i, (start, stop) in enumerate(record["chunks"]):
        if stop <= offset or start >= offset + limit or i not in record["done"]:
            continue
        members = store.chunk_members(ensemble_id, i) or []
        out.extend(m for m in members if offset <= m["index"] < offset + limit)
    return sorted(out, key=lambda m: m["index"])


def all_members(store: EnsembleStore, ensemble_id: str, record: dict[str, Any]) -> Iterator[dict[str, Any]]:
    """Every member of the finished chunks, chunk by chunk."""
    for i in sorted(record["done"]):
        yield from store.chunk_members(ensemble_id, i) or []


def section_members(store: EnsembleStore, ensemble_id: str,
                    record: dict[str, Any]) -> Iterator[tuple[int, dict[str, Any]]]:
    """(member index, its ``poincare`` block) of every member done that has one, in index order."""
    for i in sorted(record["done"]):
        for member in store.chunk_members(ensemble_id, i) or []:
            if member.get("poincare"):
                yield member["index"], member["poincare"]


def request_units(request: dict[str, Any]) -> dict[str, str]:
    """Units of a job's or an ensemble's system (its members are not revalidated)."""
    return system_units(definition_of(request["system"]))


def section_csv(store: EnsembleStore, ensemble_id: str, record: dict[str, Any]) -> Iterator[str]:
    """Every member's crossings as CSV, one row per crossing, the member index first, a header naming
    each column and its unit (streamed a member at a time)."""
    header_written = False
    units = request_units(record["request"])
    names = vector_components(record["request"]["system"])
    for index, section in section_members(store, ensemble_id, record):
        cols = section_columns(section, units, names)
        buffer = io.StringIO()
        writer = csv.writer(buffer)
        if not header_written:
            writer.writerow(["member", *[c[0] for c in cols]])
            header_written = True
        for row in range(section["count"]):
            writer.writerow([index, *[repr(float(section[key][row] if k is None else section["points"][key][row][k]))
                                      for _, key, k in cols]])
        yield buffer.getvalue()
    if not header_written:
        yield f"member,t [{units['t']}]\n"


def section_npz(store: EnsembleStore, ensemble_id: str, record: dict[str, Any]) -> bytes:
    """Every member's crossings as NPZ arrays (``member``, ``t``, ``tau``, each point vector ``(n, k)``, k its
    components), with the request, the units and the components' names as JSON in ``request_json``, ``units_json``
    and ``components_json``."""
    parts: dict[str, list[np.ndarray]] = {"member": []}
    names = vector_components(record["request"]["system"])
    for index, section in section_members(store, ensemble_id, record):
        parts["member"].append(np.full(section["count"], index, dtype=np.int64))
        for key in ("t", "tau"):
            if section.get(key) is not None:
                parts.setdefault(key, []).append(np.asarray(section[key], dtype=float))
        for name, values in section["points"].items():
            parts.setdefault(name, []).append(point_array(values, section["count"], len(names[name])))
    arrays = {k: np.concatenate(v) if v else np.zeros(0) for k, v in parts.items()}
    buffer = io.BytesIO()
    texts = {"request_json": np.array(json.dumps(record["request"])),
             "units_json": np.array(json.dumps(request_units(record["request"]))),
             "components_json": np.array(json.dumps(names))}
    np.savez(buffer, **arrays, **texts)  # type: ignore[arg-type]  # numpy's stub: a **name may bind allow_pickle
    return buffer.getvalue()


def section_netcdf(store: EnsembleStore, ensemble_id: str, record: dict[str, Any]) -> bytes:
    """Every member's crossings as NetCDF-4 (:func:`service.exports_netcdf.ensemble_section_netcdf`), the
    ensemble's summary as the evidence."""
    from service.exports_netcdf import ensemble_section_netcdf

    summary = view(ensemble_id, record)["summary"]
    members = sorted(section_members(store, ensemble_id, record), key=lambda item: item[0])
    return ensemble_section_netcdf(ensemble_id, record, summary, members, request_units(record["request"]))
