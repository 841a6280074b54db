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
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from datetime import datetime
from functools import cache
from importlib import resources
from typing import Any

import jsonschema
import jsonschema_rs
from jsonschema.exceptions import ValidationError, best_match

from .errors import BadRequest, ValidationFailed

__all__ = ["check_td", "load_data", "parse_json_body", "parse_rfc3339", "schema_problems", "td_problems"]

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
    try:
        return datetime.fromisoformat(text.upper().replace("Z", "+00:00"))
    except ValueError:
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
                    for k in err.validator_value if k not in err.instance]
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


def td_problems(td: Any) -> list[dict[str, str]]:
    """All validation problems of a TD (enriched or not); empty when valid."""
    if not isinstance(td, dict):
        return [{"field": "$", "description": f"a TD must be a JSON object, not {_json_type(td)}"}]
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
        if isinstance(ttl, int | float) and not isinstance(ttl, bool) and ttl <= 0:
            problems.append({"field": "$.registration.ttl", "description": "ttl must be positive"})
    return problems[:_MAX_ERRORS]


def check_td(td: Any) -> dict[str, Any]:
    problems = td_problems(td)
    if problems:
        raise ValidationFailed(problems)
    return td


def _json_type(value: Any) -> str:
    return {dict: "an object", list: "an array", str: "a string", bool: "a boolean",
            type(None): "null"}.get(type(value), "a number")


def _no_constants(name: str) -> Any:
    raise ValueError(f"{name} is not valid JSON")


def parse_json_body(body: bytes) -> Any:
    """Strict JSON (no NaN/Infinity), or a 400 that says where it broke."""
    try:
        text = body.decode("utf-8")
    except UnicodeDecodeError as e:
        raise BadRequest(f"The body is not UTF-8: {e}") from None
    if not text.strip():
        raise BadRequest("The body is empty; a JSON document was expected")
    try:
        return json.loads(text, parse_constant=_no_constants)
    except json.JSONDecodeError as e:
        raise BadRequest(f"Invalid JSON: {e.msg} at line {e.lineno} column {e.colno}") from None
    except (ValueError, RecursionError) as e:
        raise BadRequest(f"Invalid JSON: {e}") from None
