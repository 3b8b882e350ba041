"""The one exception for request fields the core refuses: each ``field`` and the ``reason``.

Every refusal of user input, in every layer, is a :class:`RefusedField` (or, for several fields at once,
:class:`RefusedFields`): a chaos map's grid, a level to sample, a periodic orbit, a section's surface, a
user's Lagrangian or generalized Chaplygin system, the states of a map, a symbolic request. The API answers
every one with the same 422 naming each field (``service.errors``); a layer that knows where the refused
block sits in the request names it with :meth:`RefusedField.within`. Refusals pickle, so that a worker or a
child process can raise them.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any


class RefusedField(ValueError):
    """A refused request field and why.

    Attributes
    ----------
    field : str
        A dotted path relative to the block the caller names (``coordinates[1]``, ``parameters.k``).
    reason : str
        What is wrong, in words (for an unknown name it lists the allowed ones).
    position : int or None
        0-based character offset in the field's text, when the refusal points into an expression.
    """

    def __init__(self, field: str, reason: str, position: int | None = None) -> None:
        self.field, self.reason, self.position = field, reason, position
        super().__init__(self._message())

    def _message(self) -> str:
        where = f" (at position {self.position})" if self.position is not None else ""
        return f"{self.field}: {self.reason}{where}"

    def __reduce__(self) -> tuple[Any, ...]:  # subclasses keep their class across processes
        return (_rebuild, (type(self), self.__dict__))

    def problems(self) -> list[tuple[str, str]]:
        """Every ``(field, reason)`` refused."""
        return [(self.field, self.reason)]

    def within(self, block: str) -> RefusedField:
        """The same refusal with its field named from ``block`` (``members.grid``: ``members.grid.shape``)."""
        return RefusedFields([(_join(block, f), r) for f, r in self.problems()], self.position)


class RefusedFields(RefusedField):
    """Several refused fields at once (each bad state of a list, say), in the order found."""

    def __init__(self, problems: Sequence[tuple[str, str]], position: int | None = None) -> None:
        if not problems:
            raise ValueError("a refusal names at least one field")
        self.all = list(problems)
        super().__init__(*problems[0], position)

    def _message(self) -> str:
        return "; ".join(f"{f}: {r}" for f, r in self.all)

    def problems(self) -> list[tuple[str, str]]:
        return list(self.all)


def _join(block: str, field: str) -> str:
    return field if not block else f"{block}{field}" if field.startswith("[") else f"{block}.{field}"


def _rebuild(cls: type[RefusedField], state: dict[str, Any]) -> RefusedField:
    refusal = cls.__new__(cls)
    refusal.__dict__.update(state)
    refusal.args = (refusal._message(),)
    return refusal
