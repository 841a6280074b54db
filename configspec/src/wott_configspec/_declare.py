"""Declaring a table: the base ``Model``, the words and bounds of a field, tables derived from dataclasses."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Annotated, Any, cast, get_type_hints

import msgspec

__all__ = ["Flag", "Model", "bounded", "doc", "says", "table_of"]


class Model(msgspec.Struct, kw_only=True, forbid_unknown_fields=True):
    """Base of a declared table: keyword-only, and a key it does not declare is an error."""


def says(phrase: str, **meta: Any) -> msgspec.Meta:
    """msgspec constraints ``meta`` plus the ``phrase`` an error says is expected, for ``Annotated``:
    ``Annotated[int, says("a port number (0: any free port)", ge=0, le=65535)]``."""
    return msgspec.Meta(**meta, extra={"expects": phrase})


Flag = Annotated[bool, says("true or false")]
"""A yes/no setting (TOML ``true``/``false``)."""


def bounded(phrase: str, *, ge: float | None = None, gt: float | None = None,
            le: float | None = None, lt: float | None = None, **meta: Any) -> msgspec.Meta:
    """``says`` for a number: an upper bound is required, so neither NaN nor infinity gets in."""
    if le is None and lt is None:
        raise TypeError("a bounded number needs an upper bound (le or lt)")
    given = {"ge": ge, "gt": gt, "le": le, "lt": lt}
    return says(phrase, **{k: v for k, v in given.items() if v is not None}, **meta)


def doc(text: str) -> dict[str, str]:
    """Field metadata: the description a derived table (``table_of``) shows in its JSON Schema."""
    return {"doc": text}


def table_of(cls: type[Any], name: str, *, exclude: tuple[str, ...] = (),
             types: Mapping[str, Any] | None = None) -> type[Model]:
    """The ``Model`` of a config table, derived from the frozen dataclass ``cls`` its values live in.

    Why derived: the dataclass is what a program builds and ``dataclasses.replace``s;
    declaring its fields (type with bounds, default, ``doc``) once and deriving the reader
    keeps the two from disagreeing. ``types`` gives a field another type in the file
    (``register_to``: a URL or a table).
    """
    hints = get_type_hints(cls, include_extras=True)
    fields: list[tuple[str, Any, Any]] = []
    for f in dataclasses.fields(cls):
        if f.name in exclude:
            continue
        tp = (types or {}).get(f.name, hints[f.name])
        if "doc" in f.metadata:
            tp = Annotated[tp, msgspec.Meta(description=f.metadata["doc"])]
        if f.default is not dataclasses.MISSING:
            default: Any = f.default
        elif f.default_factory is not dataclasses.MISSING:
            default = msgspec.field(default_factory=f.default_factory)
        else:
            default = msgspec.NODEFAULT
        fields.append((f.name, tp, default))
    return cast("type[Model]", msgspec.defstruct(name, fields, bases=(Model,), module=cls.__module__))
