"""One declaration, one line per mistake: where (file, table, key), what is expected, what was given."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Annotated, Literal

import msgspec
import pytest
from wott_configspec import ConfigError, Flag, Model, bounded, check, doc, json_schema, read, says, table_of

Workers = Annotated[int, says("a whole number of processes", ge=0, le=64)]


class Inner(Model):
    url: Annotated[str, says("a URL", pattern=r"^https?://")]


class Table(Model):
    workers: Workers = 0
    ratio: Annotated[float, bounded("a fraction", gt=0, le=1)] = 0.5
    mode: Literal["fast", "committed"] = "fast"
    on: Flag = True
    point: Annotated[tuple[float, float, float], says("a point [x, y, z]")] = (0.0, 0.0, 0.0)
    names: list[Annotated[str, says("a name", min_length=1)]] = msgspec.field(default_factory=list)
    inner: Inner | None = None


def _message(data: object, where: str = "hub.toml: [hub]") -> str:
    with pytest.raises(ConfigError) as e:
        read(Table, data, where)
    assert "\n" not in str(e.value)
    return str(e.value)


@pytest.mark.parametrize(("data", "message"), [
    ({"workers": 100}, "hub.toml: [hub].workers: a whole number of processes, got 100; must be from 0 to 64"),
    ({"ratio": math.nan}, "hub.toml: [hub].ratio: a fraction, got nan; must be above 0 and at most 1"),
    ({"ratio": math.inf}, "hub.toml: [hub].ratio: a fraction, got inf; must be above 0 and at most 1"),
    ({"mode": "slow"}, "hub.toml: [hub].mode: 'slow' is not one of committed, fast"),
    ({"on": 1}, "hub.toml: [hub].on: true or false, got 1"),
    ({"point": [1, 2]}, "hub.toml: [hub].point: a point [x, y, z], got [1, 2]"),
    ({"names": ["a", ""]}, "hub.toml: [hub].names[1]: a name, got ''"),
    ({"inner": {"url": "ftp://x"}}, "hub.toml: [hub].inner.url: a URL, got 'ftp://x'"),
    ({"inner": {}}, "hub.toml: [hub].inner.url: required, missing"),
    ({"inner": 3}, "hub.toml: [hub].inner must be a table, got 3"),
    ({"wrokers": 1},
     "hub.toml: [hub].wrokers: unknown key (known: inner, mode, names, on, point, ratio, workers)"),
])
def test_a_wrong_value_is_one_line_naming_the_key(data, message):
    assert _message(data) == message


def test_where_names_a_table_a_file_or_nothing():
    assert _message({"workers": -1}, "scene.toml: ").startswith("scene.toml: workers: ")
    assert _message({"inner": {}}, "scene.toml: ") == "scene.toml: inner.url: required, missing"
    assert _message({"workers": -1}, "").startswith("workers: a whole number")


def test_a_bounded_number_needs_an_upper_bound():
    with pytest.raises(TypeError, match="upper bound"):
        bounded("a number", ge=0)


@dataclass(frozen=True)
class Settings:
    workers: Workers = field(default=0, metadata=doc("Processes."))
    name: str = "hub"


def test_a_table_derived_from_a_dataclass_checks_it_and_documents_it():
    table = table_of(Settings, "settings")
    assert read(table, {"workers": 3}, "x").workers == 3
    check(Settings(workers=3), table, "x")
    with pytest.raises(ConfigError, match=r"^<defaults>: \[settings\]\.workers: .*got 65; must be from 0 to"):
        check(Settings(workers=65), table, "<defaults>: [settings]")
    schema = json_schema(table)["$defs"]["settings"]["properties"]["workers"]
    assert schema == {"type": "integer", "minimum": 0, "maximum": 64, "description": "Processes.",
                      "default": 0}
    assert issubclass(ConfigError, ValueError)
