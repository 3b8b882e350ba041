"""Finding a job or an ensemble by the first characters of its id (the client's progress bar shows 8)."""

from __future__ import annotations

import re
from typing import Any

from sqlalchemy import or_, select

#: What a prefix may hold: a UUID's characters only (so LIKE's ``%`` and ``_`` never reach the query).
PREFIX = re.compile(r"[0-9a-f-]{6,35}")


def is_prefix(text: str) -> bool:
    """Whether ``text`` may be an id's prefix: 6 to 35 hex digits and dashes (a whole id has 36)."""
    return PREFIX.fullmatch(text) is not None


def ids_with_prefix(session_factory: Any, row: Any, prefix: str, owner: str | None, limit: int) -> list[str]:
    """Ids of ``row``'s table starting with ``prefix`` that ``owner`` may see (its own and those without an
    owner; every one when ``owner`` is None), in order, at most ``limit``; none for a text that is not a prefix."""
    if not is_prefix(prefix):
        return []
    query = select(row.id).where(row.id.like(prefix + "%"))
    if owner is not None:
        query = query.where(or_(row.owner == owner, row.owner.is_(None)))
    with session_factory() as session:
        return list(session.scalars(query.order_by(row.id).limit(limit)))
