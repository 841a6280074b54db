"""Validate submitted TDs (WoT Discovery "Minimal Validation") and parse request bodies.

A TD is checked against the TD 1.1 JSON Schema and the Discovery schema of the
``registration`` block, both shipped with the package, plus what the schemas
declare as formats but jsonschema only checks with optional packages: the
``id`` is an absolute URI and the registration times are RFC 3339. Each problem
becomes one ``{field, description}`` entry of ``validationErrors``; ``field``
is the JSON path of the failing member (``$.properties.status.forms[0].href``).

Checking a valid TD with the pure-Python validator costs ~5 ms (the TD schema
is deep); jsonschema-rs answers "valid?" in ~0.02 ms, so it decides first and
the Python validator only runs to explain a TD that failed. If the two ever
disagree on a TD, the Python validator's answer (the reference) stands.

Bounds (issue 16): a TD is at most ``MAX_TD_DEPTH`` levels of objects/arrays
deep (checked iteratively, before the recursive schema validators and before
a merge patch is applied), so no stored TD can overflow the stack of a search,
a merge patch or a diff; ``registration.ttl`` is at most ``MAX_TTL_S``; numbers
must be finite (``1e400`` parses to ``inf``, which is not JSON and would be
served as ``Infinity``).
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Callable
from datetime import UTC, datetime
from functools import cache
from importlib import resources
from typing import Any, cast

import jsonschema
import jsonschema_rs
from jsonschema.exceptions import ValidationError, best_match

from .errors import BadRequest, DirectoryError, ValidationFailed
from .mergepatch import apply_merge_patch

__all__ = [
    "MAX_TD_DEPTH", "MAX_TTL_S", "check_depth", "check_td", "json_depth", "load_data", "parse_json_body",
    "parse_rfc3339", "schema_problems", "td_problems",
]

MAX_TD_DEPTH = 64
"""Levels of nested objects/arrays in a TD (``{}`` is 1); real TDs stay under 15."""
MAX_TTL_S = 10 * 366 * 86400
"""Ten years: a longer registration is a mistake (and ``1e20`` s overflows any date)."""

_URI_SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.\-]*:\S*$")
_RFC3339 = re.compile(
    r"^\d{4}-\d{2}-\d{2}[Tt]\d{2}:\d{2}:\d{2}(\.\d+)?([Zz]|[+-]\d{2}:\d{2})$")
_MAX_ERRORS = 50


@cache
def load_data(name: str) -> Any:
    """One of the W3C documents shipped in ``wott_directory/data``."""
    return json.loads(resources.files("wott_directory").joinpath("data", name).read_text("utf-8"))


@cache
def _td_validator() -> jsonschema.protocols.Validator:
    return jsonschema.Draft7Validator(load_data("td-1.1-json-schema.json"))


@cache
def _fast_td_validator() -> Any:
    return jsonschema_rs.Draft7Validator(load_data("td-1.1-json-schema.json"))


@cache
def _registration_validator() -> jsonschema.protocols.Validator:
    schema = {k.strip(): v for k, v in load_data("td-discovery-extensions-json-schema.json").items()}
    schema.pop("$schema", None)  # the original's key has a stray space; we validate as 2019-09 anyway
    return jsonschema.Draft201909Validator(schema)


def parse_rfc3339(text: str) -> datetime | None:
    """An RFC 3339 date-time (always with an offset), or None if it is not one."""
    if not isinstance(text, str) or not _RFC3339.match(text):
        return None
    try:  # in UTC: an offset can push year 9999 past what datetime holds (OverflowError)
        return datetime.fromisoformat(text.upper().replace("Z", "+00:00")).astimezone(UTC)
    except (ValueError, OverflowError):
        return None


def _join(path: str, key: str) -> str:
    return f"{path}.{key}" if re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", key) else f"{path}[{json.dumps(key)}]"


def schema_problems(validator: jsonschema.protocols.Validator, doc: Any, *,
                    join: Callable[[str, str], str] = _join) -> list[tuple[str, str]]:
    """``(JSON path, description)`` of each schema error in ``doc``, in path order, without repeats.

    A missing required member is named by ``join(path of its object, its key)``, by
    default ``$.a.b`` or ``$.a["@b"]`` when the key is not an identifier.
    """
    out: list[tuple[str, str]] = []
    for err in sorted(validator.iter_errors(doc), key=lambda e: [str(p) for p in e.absolute_path]):
        if err.context:  # anyOf/oneOf: report the branch that came closest
            err = best_match(err.context)
        if err.validator == "required" and isinstance(err.instance, dict):
            out += [(join(err.json_path, k), "required field is missing")
                    for k in cast(list[str], err.validator_value) if k not in err.instance]
        else:
            out.append((err.json_path, _message(err)))
    return list(dict.fromkeys(out))  # the TD schema's anyOf branches repeat some errors


def _schema_problems(validator: jsonschema.protocols.Validator, doc: Any) -> list[dict[str, str]]:
    return [{"field": field, "description": text} for field, text in schema_problems(validator, doc)]


def _message(err: ValidationError) -> str:
    """jsonschema's message without pasting a whole sub-document into it."""
    text = repr(err.instance)
    if len(text) <= 80:
        return err.message
    return err.message.replace(text, text[:60] + "…") if text in err.message else f"{err.validator} failed"


def json_depth(doc: Any, stop_after: int | None = None) -> int:
    """Levels of nested containers in ``doc`` (a scalar is 0, ``{}`` is 1), without recursion;
    stops counting once past ``stop_after``."""
    deepest = 0
    stack: list[tuple[Any, int]] = [(doc, 1)]
    while stack:
        node, depth = stack.pop()
        if isinstance(node, dict):
            children: Any = node.values()
        elif isinstance(node, list):
            children = node
        else:
            continue
        if depth > deepest:
            deepest = depth
            if stop_after is not None and deepest > stop_after:
                return deepest
        stack.extend((child, depth + 1) for child in children if isinstance(child, dict | list))
    return deepest


def check_depth(doc: Any, what: str = "The body") -> None:
    """400 naming the limit if ``doc`` nests deeper than ``MAX_TD_DEPTH``."""
    if json_depth(doc, MAX_TD_DEPTH) > MAX_TD_DEPTH:
        problem = {"field": "$", "description": f"nested more than {MAX_TD_DEPTH} levels deep"}
        raise ValidationFailed([problem], f"{what} nests objects/arrays more than {MAX_TD_DEPTH} levels deep "
                               f"(the directory's max_depth)")


def td_problems(td: Any) -> list[dict[str, str]]:
    """All validation problems of a TD (enriched or not); empty when valid."""
    if not isinstance(td, dict):
        return [{"field": "$", "description": f"a TD must be a JSON object, not {_json_type(td)}"}]
    if json_depth(td, MAX_TD_DEPTH) > MAX_TD_DEPTH:  # before the (recursive) schema validators
        return [{"field": "$", "description": f"a TD may nest objects/arrays at most {MAX_TD_DEPTH} "
                                              "levels deep (max_depth)"}]
    problems = [] if _fast_td_validator().is_valid(td) else _schema_problems(_td_validator(), td)
    problems += _schema_problems(_registration_validator(), td)
    td_id = td.get("id")
    if isinstance(td_id, str) and not _URI_SCHEME.match(td_id):
        problems.append({"field": "$.id", "description": f"{td_id!r} is not an absolute URI"})
    reg = td.get("registration")
    if isinstance(reg, dict):
        for key in ("created", "modified", "expires", "retrieved"):
            if isinstance(reg.get(key), str) and parse_rfc3339(reg[key]) is None:
                problems.append({"field": f"$.registration.{key}",
                                 "description": f"{reg[key]!r} is not an RFC 3339 date-time"})
        ttl = reg.get("ttl")
        if isinstance(ttl, int | float) and not isinstance(ttl, bool):
            if ttl <= 0:
                problems.append({"field": "$.registration.ttl", "description": "ttl must be positive"})
            elif not ttl <= MAX_TTL_S:
                problems.append({"field": "$.registration.ttl",
                                 "description": f"ttl must be at most {MAX_TTL_S} s (ten years), "
                                                f"not {repr(ttl):.30}"})
    return problems[:_MAX_ERRORS]


def check_td(td: Any) -> dict[str, Any]:
    problems = td_problems(td)
    if problems:
        raise ValidationFailed(problems)
    valid: dict[str, Any] = td
    return valid


def json_bytes(doc: Any) -> int:
    """Bytes of ``doc``'s compact UTF-8 JSON (what it costs the directory's byte budgets)."""
    return len(json.dumps(doc, ensure_ascii=False, separators=(",", ":")).encode("utf-8"))


def patched(thing_id: str, td: dict[str, Any], patch: dict[str, Any], max_bytes: int) -> dict[str, Any]:
    """``td`` with the merge ``patch`` applied, checked as a whole TD: its id unchanged, at most
    ``max_bytes`` (413: a patch cannot grow a TD past what a PUT may send), valid."""
    candidate = apply_merge_patch(td, patch)
    if candidate.get("id") != thing_id:
        raise ValidationFailed([{"field": "$.id",
                                 "description": "the id of a TD cannot be changed or removed"}])
    size = json_bytes({k: v for k, v in candidate.items() if k != "registration"})
    if size > max_bytes:
        raise DirectoryError(413, f"The patched TD would be {size} bytes, more than the {max_bytes} a TD may "
                                  "have (max_body_bytes)")
    return check_td(candidate)


def _json_type(value: Any) -> str:
    return {dict: "an object", list: "an array", str: "a string", bool: "a boolean",
            type(None): "null"}.get(type(value), "a number")


def _no_constants(name: str) -> Any:
    raise ValueError(f"{name} is not valid JSON")


def _finite(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"the number {text[:40]} is out of range (not a finite double)")
    return value


def parse_json_body(body: bytes) -> Any:
    """Strict JSON (no NaN/Infinity), or a 400 that says where it broke."""
    try:
        text = body.decode("utf-8")
    except UnicodeDecodeError as e:
        raise BadRequest(f"The body is not UTF-8: {e}") from None
    if not text.strip():
        raise BadRequest("The body is empty; a JSON document was expected")
    try:
        return json.loads(text, parse_constant=_no_constants, parse_float=_finite)
    except json.JSONDecodeError as e:
        raise BadRequest(f"Invalid JSON: {e.msg} at line {e.lineno} column {e.colno}") from None
    except RecursionError:
        raise BadRequest(f"The body nests objects/arrays far deeper than the {MAX_TD_DEPTH} levels a TD may "
                         "have (the directory's max_depth)") from None
    except ValueError as e:
        raise BadRequest(f"Invalid JSON: {e}") from None
