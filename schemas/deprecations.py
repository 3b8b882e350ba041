"""Old spellings the API still accepts, each answered with a note in the answer's ``deprecations``.

One vocabulary for the systems a user writes: the Lagrangian is ``L`` and the state is ``q`` and ``q_dot``,
for a generalized Chaplygin system (``POST /v1/jobs``, ``POST /v1/hamiltonize``) as for a Lagrangian one.
A generalized Chaplygin system called them ``lagrangian`` and ``qdot`` until 2026-11; requests with those
names are read as the new ones (stored, and answered, in the new names) and the answer says so.
"""

from __future__ import annotations

from typing import Any, ClassVar

from pydantic import BaseModel, ModelWrapValidatorHandler, PrivateAttr, model_validator

#: The request fields renamed: old name → new name.
RENAMED_FIELDS = {"lagrangian": "L"}
#: The state vectors renamed: old name → new name.
RENAMED_STATE = {"qdot": "q_dot"}
#: When the old names stop being accepted.
REMOVAL = "the old name will no longer be accepted after 2027-06"


def renamed(data: Any, renames: dict[str, str], where: str) -> tuple[Any, list[str]]:
    """``data`` (a request's JSON object) with each old key of ``renames`` given its new name, and the notes
    saying so; ``where`` is the object's path in the request (``system.``, ``initial_state.``).

    Raises
    ------
    ValueError
        If ``data`` has both an old name and its new one (which to read would be a guess).
    """
    if not isinstance(data, dict):
        return data, []
    notes = []
    for old, new in renames.items():
        if old not in data:
            continue
        if new in data:
            raise ValueError(f"{where}{old} is the old name of {where}{new}: send {new} only")
        data = {new if key == old else key: value for key, value in data.items()}
        notes.append(f"{where}{old} is deprecated: it is now {where}{new}, as for every system written by the "
                     f"user (L, q, q_dot); {REMOVAL}")
    return data, notes


class FormerFieldNames(BaseModel):
    """A request model that still reads the former names of some of its fields: ``former_fields`` (old → new),
    at ``former_fields_at`` in the request (``system.``); the notes are kept for the answer."""

    former_fields: ClassVar[dict[str, str]] = {}
    former_fields_at: ClassVar[str] = ""
    _deprecations: list[str] = PrivateAttr(default_factory=list)

    @model_validator(mode="wrap")
    @classmethod
    def _former_names(cls, data: Any, handler: ModelWrapValidatorHandler[FormerFieldNames]) -> Any:
        notes: list[str] = []
        if cls.former_fields:
            data, notes = renamed(data, cls.former_fields, cls.former_fields_at)
        model = handler(data)
        model._deprecations = notes
        return model

    def deprecations(self) -> list[str]:
        """Notes on the deprecated names this model was sent with (empty if none)."""
        return list(self._deprecations)
