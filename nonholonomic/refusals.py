"""The one exception for a request field the core refuses: its ``field`` and the ``reason``.

The grid of a chaos map, a level to sample, a periodic-orbit request and a user's generalized Chaplygin system
refuse their fields with subclasses of :class:`RefusedField`; the API names the field in its 422.
"""

from __future__ import annotations


class RefusedField(ValueError):
    """A refused request field (a dotted path relative to the block the caller names) and why, in words."""

    def __init__(self, field: str, reason: str) -> None:
        super().__init__(f"{field}: {reason}")
        self.field, self.reason = field, reason
