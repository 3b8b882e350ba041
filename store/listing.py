"""Listing jobs and ensembles: pages newest first (keyset pagination on ``(created, id)``), and finding one by
the first characters of its id (the client's progress bar shows 8). Both tables share the columns used here:
``id``, ``created`` and ``owner``."""

from __future__ import annotations

import re
from typing import Any

from sqlalchemy import Select, and_, or_, select

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
    query = visible_to(select(row.id).where(row.id.like(prefix + "%")), row, owner)
    with session_factory() as session:
        return list(session.scalars(query.order_by(row.id).limit(limit)))


def visible_to(query: Select[Any], row: Any, owner: str | None) -> Select[Any]:
    """``query`` limited to what ``owner`` may see: its own rows and those without an owner (all when None)."""
    return query if owner is None else query.where(or_(row.owner == owner, row.owner.is_(None)))


def newest_first(query: Select[Any], row: Any, after: tuple[float, str] | None, owner: str | None,
                 limit: int) -> Select[Any]:
    """``query`` as a page: rows newest first by ``(created, id)``, strictly after ``after`` (a previous page's
    last pair), only what ``owner`` may see, ``limit + 1`` of them (the extra one says whether more follow)."""
    if after is not None:
        score, last = after
        query = query.where(or_(row.created < score, and_(row.created == score, row.id < last)))
    return visible_to(query, row, owner).order_by(row.created.desc(), row.id.desc()).limit(limit + 1)
