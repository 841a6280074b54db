"""JSON Merge Patch (RFC 7396): apply one, and compute the one that turns a TD into another.

Small enough to own: applying is the RFC's ten-line algorithm, and the diff is
its inverse, used for ``thing_updated`` events with ``diff=true``.
"""

from __future__ import annotations

import copy
from typing import Any

__all__ = ["apply_merge_patch", "merge_diff", "same_json"]


def apply_merge_patch(target: Any, patch: Any) -> Any:
    """RFC 7396 section 2; returns a new document and leaves ``target`` untouched."""
    if not isinstance(patch, dict):
        return copy.deepcopy(patch)
    result = dict(target) if isinstance(target, dict) else {}
    for key, value in patch.items():
        if value is None:
            result.pop(key, None)
        else:
            result[key] = apply_merge_patch(result.get(key), value)
    return result


def merge_diff(old: dict[str, Any], new: dict[str, Any]) -> dict[str, Any]:
    """The merge patch P with apply_merge_patch(old, P) == new.

    Arrays are replaced whole (merge patch cannot address their items); a
    ``null`` value in ``new`` cannot be expressed and is reported as removal,
    which is RFC 7396's own limit.
    """
    out: dict[str, Any] = {}
    for key in old.keys() - new.keys():
        out[key] = None
    for key, value in new.items():
        if key not in old:
            out[key] = value
        elif not same_json(old[key], value):
            if isinstance(old[key], dict) and isinstance(value, dict):
                out[key] = merge_diff(old[key], value)
            else:
                out[key] = value
    return out


def same_json(a: Any, b: Any) -> bool:
    """Equality as JSON texts see it: ``True`` is not ``1`` and ``1`` is not ``1.0``."""
    if type(a) is not type(b):
        return False
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(same_json(v, b[k]) for k, v in a.items())
    if isinstance(a, list):
        return len(a) == len(b) and all(map(same_json, a, b))
    return bool(a == b)
