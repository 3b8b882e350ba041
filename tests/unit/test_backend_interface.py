"""The job backend interface states everything the routes use: both backends implement every member of
service.backends.base.JobBackend with the same parameters, so the routes need no probing of attributes."""

from __future__ import annotations

import inspect

import pytest

from service.backends.base import JobBackend
from service.backends.embedded import EmbeddedBackend
from service.backends.queue import QueueBackend


def _members() -> list[str]:
    return [name for name, value in vars(JobBackend).items()
            if not name.startswith("_") and inspect.isfunction(value)]


def test_the_interface_names_what_the_routes_use() -> None:
    properties = {name for name, value in vars(JobBackend).items() if isinstance(value, property)}
    members = set(_members()) | set(JobBackend.__annotations__) | properties
    assert {"submit", "reserve_messages", "find", "get", "list_jobs", "redis", "ensembles"} <= members


@pytest.mark.parametrize("backend", [EmbeddedBackend, QueueBackend], ids=lambda b: b.__name__)
def test_each_backend_has_every_member_with_the_same_parameters(backend: type) -> None:
    for name in _members():
        implemented = getattr(backend, name, None)
        assert implemented is not None, f"{backend.__name__} lacks {name}"
        declared = list(inspect.signature(getattr(JobBackend, name)).parameters)
        got = list(inspect.signature(implemented).parameters)
        assert got == declared, f"{backend.__name__}.{name}{got} != JobBackend.{name}{declared}"
    assert "mode" in vars(backend) and backend.mode in ("embedded", "queue")
