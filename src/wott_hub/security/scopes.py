"""The three scopes a credential grants, ordered: each implies the ones below it.

``read``: TDs, property values, event and property streams, the directory's
listing and search. ``control``: device and hub actions (``replay``,
``stopReplay``), property writes; implies ``read``. ``admin``: directory writes
and fleet management; implies everything.
"""

from __future__ import annotations

from enum import IntEnum

from wott_hub.errors import InvalidInput

__all__ = ["Scope"]


class Scope(IntEnum):
    READ = 1
    CONTROL = 2
    ADMIN = 3

    @classmethod
    def parse(cls, text: str) -> Scope:
        try:
            return cls[text.strip().upper()]
        except (KeyError, AttributeError):
            raise InvalidInput(f"scope: expected read, control or admin, got {text!r}") from None

    def grants(self, required: Scope) -> bool:
        return self >= required

    def __str__(self) -> str:
        return self.name.lower()
