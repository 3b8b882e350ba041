"""``/explore`` and ``/v1/explore``: a section you can click.

The page (``GET /explore``) draws a section plane of a system on a level; a click posts the point
(``POST /v1/explore/orbits``), the service completes it to a state on the level, integrates it in a thread
of its own (:mod:`service.explore`) and the page polls the crossings (``GET /v1/explore/orbits/{id}``) as
they come; a shift-click asks for the periodic orbit through the point (``POST /v1/explore/periodic-orbit``).
"""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Query, Request
from fastapi.responses import HTMLResponse, JSONResponse
from starlette.concurrency import run_in_threadpool

from nonholonomic.analysis.periodic_orbit import PeriodicOrbitError, find_periodic_orbit
from nonholonomic.numerics.integration import IntegrationError
from schemas.explore import (
    ExplorationAccepted,
    ExplorationView,
    ExploreOrbitRequest,
    ExplorePeriodicRequest,
    ExplorePlaneRequest,
    clicked_state,
    plane_problems,
    plane_ranges,
)
from schemas.periodic_orbits import named_state, orbit_to_json
from schemas.problems import NOT_FOUND, FieldError
from schemas.results import system_units
from service.errors import INVALID, ProblemError, invalid_request, problem_responses
from service.explore import defaults, explorable, explorations, orbit_points
from service.openapi import operation_id
from service.pages import environment
from service.security import EXPLORE_POLICY

router = APIRouter(tags=["explore"], generate_unique_id_function=operation_id)


def _checked(body: ExplorePlaneRequest) -> tuple[Any, Any]:
    system, p, problems = plane_problems(body)
    if problems:
        raise invalid_request([FieldError(field=f.field, reason=f.reason) for f in problems])
    return system, p


def _state(body: ExploreOrbitRequest | ExplorePeriodicRequest, system: Any, p: Any) -> tuple[Any, int]:
    x, branches, problems = clicked_state(system, p, body.section, list(body.point))
    if problems:
        raise invalid_request([FieldError(field=f.field, reason=f.reason) for f in problems])
    return x, branches


@router.get("/explore", operation_id="explore-page", response_class=HTMLResponse,
            summary="A section you can click: pick a system and a level, click the plane to draw orbits")
def explore_page(kind: str = Query("chaplygin_ball"), potential: str = Query("linear")) -> HTMLResponse:
    """The page; ``kind`` and ``potential`` choose the system it starts with (the catalog links here)."""
    html = environment().get_template("explore.html").render(kinds=explorable(), kind=kind, potential=potential,
                                                             refresh=None)
    return HTMLResponse(html, headers={"Content-Security-Policy": EXPLORE_POLICY})


@router.get("/v1/explore/defaults", operation_id="explore-defaults",
            responses=problem_responses({404: "a kind or potential the explorer cannot draw"}),
            summary="The example system of a kind with a potential, and a section plane that works for it")
def explore_defaults(kind: str = Query(...), potential: str = Query("zero")) -> dict[str, Any]:
    try:
        return defaults(kind, potential)
    except KeyError as exc:
        raise ProblemError(404, "Not explorable", f"{exc.args[0]}; the explorer draws: "
                           + "; ".join(f"{k} ({', '.join(v)})" for k, v in explorable().items()), NOT_FOUND) from None


@router.post("/v1/explore/plane", operation_id="explore-plane",
             responses=problem_responses({422: INVALID}),
             summary="A section plane's extent on a level (the region the level allows, +2 %)")
async def explore_plane(body: ExplorePlaneRequest) -> dict[str, Any]:
    def work() -> dict[str, Any]:
        system, p = _checked(body)
        ranges, problems = plane_ranges(system, p, body.section)
        if problems:
            raise invalid_request([FieldError(field=f.field, reason=f.reason) for f in problems])
        return {"ranges": ranges, "coordinate_names": list(body.section.coordinates),
                "units": system_units(system), "section": body.section.model_dump(mode="json")}

    return await run_in_threadpool(work)


@router.post("/v1/explore/orbits", status_code=201, operation_id="explore-orbit", response_model=ExplorationAccepted,
             responses=problem_responses({422: INVALID}),
             summary="The orbit through a point of the plane: completed to a state on the level, integrated, its "
                     "crossings polled from the Location")
async def explore_orbit(body: ExploreOrbitRequest, request: Request) -> JSONResponse:
    def work() -> dict[str, Any]:
        system, p = _checked(body)
        x, branches = _state(body, system, p)
        run = explorations(request.app.state).start(system, p, x, branches, body.section, body.t_final,
                                                    body.max_points)
        return {"id": run.id, "location": f"/v1/explore/orbits/{run.id}", "initial_state": named_state(system, x),
                "branches": branches}

    out = await run_in_threadpool(work)
    return JSONResponse(out, status_code=201, headers={"Location": out["location"]})


@router.get("/v1/explore/orbits/{run_id}", operation_id="explore-orbit-get", response_model=ExplorationView,
            responses=problem_responses({404: "unknown or forgotten run (the last 64 are kept)"}),
            summary="A clicked orbit's crossings so far, from index since")
def explore_orbit_get(run_id: str, request: Request, since: int = Query(0, ge=0)) -> dict[str, Any]:
    run = explorations(request.app.state).get(run_id)
    if run is None:
        raise ProblemError(404, "Unknown run", f"no exploration {run_id} (the last 64 are kept)", NOT_FOUND)
    points = run.points[since:]
    return {"id": run.id, "coordinate_names": list(run.coordinates),
            "initial_state": named_state(run.system, run.state),
            "branches": run.branches, "since": since, "points": points, "count": since + len(points),
            "done": run.done and since + len(points) >= len(run.points), "error": run.error,
            "t_reached": run.t_reached, "t_final": run.t_final, "max_points": run.max_points}


@router.post("/v1/explore/periodic-orbit", operation_id="explore-periodic-orbit",
             responses=problem_responses({422: INVALID}),
             summary="The periodic orbit through (near) a point of the plane: Newton with the monodromy from the "
                     "point's state; its crossings")
async def explore_periodic(body: ExplorePeriodicRequest) -> dict[str, Any]:
    def work() -> dict[str, Any]:
        system, p = _checked(body)
        x, _ = _state(body, system, p)
        plane = body.section
        try:
            orbit = find_periodic_orbit(system, p, x, plane.surface, value=plane.value, direction=plane.direction,
                                        period=body.period, level=tuple(plane.level) if plane.level else None,
                                        coordinates=tuple(plane.coordinates), t_final=body.t_final)
        except PeriodicOrbitError as exc:
            raise exc.within("section") from None  # a 422 (service.errors)
        except IntegrationError as exc:
            raise invalid_request([FieldError(field="point", reason=f"the integration from this point failed: "
                                                                    f"{exc}")]) from None
        out = orbit_to_json(system, orbit)
        try:
            out["points"] = (orbit_points(system, p, orbit.initial_state, orbit.period_t, plane, body.period)
                             if orbit.closed else [])
        except IntegrationError:
            out["points"] = []
        return out

    return await run_in_threadpool(work)
