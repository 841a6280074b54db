"""The media types a Thing Description travels as (TD 1.1 section 8.3: ``application/td+json``)."""

from __future__ import annotations

__all__ = ["TD_ACCEPT", "TD_MEDIA_TYPE"]

TD_MEDIA_TYPE = "application/td+json"

TD_ACCEPT = f"{TD_MEDIA_TYPE}, application/json;q=0.9"
"""What the hub asks a foreign Thing or directory for (the explorer, ``wot-remote`` devices): a TD,
or plain JSON from servers that label their TDs so."""
