import json

import jsonschema
import numpy as np
import pytest
from typer.testing import CliRunner

from wott_hub.cli import app
from wott_hub.examples import example_device
from wott_hub.sim.playback import play
from wott_hub.td.builder import build_tactile_td, static_property_values, tactile_context
from wott_hub.td.validate import validate_payload, validate_td
from wott_hub.td.vocabulary import EVENTS, PROPERTIES

SHAPES = ["barrel", "flat", "cylinder"]


@pytest.fixture(scope="module", params=SHAPES)
def device(request):
    return example_device(request.param)


def test_shipped_td_schema_is_the_reference(shared_data):
    from importlib import resources

    shipped = resources.files("wott_directory").joinpath("data/td-1.1-json-schema.json").read_text()
    assert json.loads(shipped) == json.loads((shared_data / "w3c/td-1.1-json-schema.json").read_text())


def test_td_validates_against_reference_schema(device, shared_data):
    td = build_tactile_td(device)
    schema = json.loads((shared_data / "w3c/td-1.1-json-schema.json").read_text())
    jsonschema.Draft7Validator(schema).validate(td)  # the file in ../shared, not our copy
    assert validate_td(td) == []


def test_td_has_the_vocabulary_and_interop_rules(device):
    td = build_tactile_td(device, base="http://127.0.0.1:9999/")
    assert set(td["properties"]) == set(PROPERTIES) and set(td["events"]) == set(EVENTS)
    assert td["@context"][:2] == ["https://www.w3.org/2019/wot/td/v1", "https://www.w3.org/2022/wot/td/v1.1"]
    assert td["@context"][2] == "http://127.0.0.1:9999/contexts/tactile-v1.jsonld"
    assert "oneOf" not in json.dumps(td)
    for kind in ("properties", "events"):
        for aff in td[kind].values():
            for form in aff["forms"]:
                if form["href"].startswith("ws://"):  # skinDisplacement's binary form over WebSocket
                    assert form["contentType"] == "application/vnd.wott.skin-displacement"
                    continue
                assert form["op"] and form["htv:methodName"] == "GET"
                if kind == "events":  # SSE for JSON; the binary form: one endless response
                    binary = form["contentType"] != "application/json"
                    assert form["subprotocol"] == ("stream" if binary else "sse")
    assert td["properties"]["contactInformation"]["properties"]["contactForces"]["items"][
        "properties"]["x"]["unit"] == "N"
    assert td["tac:epsilon"] == device.epsilon_mm


def test_static_values_validate_against_declared_schemas(device):
    td = build_tactile_td(device)
    values = static_property_values(device)
    assert set(values) == set(PROPERTIES)
    for name, value in values.items():
        assert validate_payload(td, "property", name, value) == [], name
    nodes = values["skinNodes"]
    assert nodes["numOfNodes"] == device.mesh.n_nodes == len(nodes["arrayOfNodes"])
    assert values["skinCells"]["numOfCells"] == device.mesh.n_cells


def test_event_payloads_validate_against_declared_schemas():
    dev = example_device("barrel")
    td = build_tactile_td(dev)
    results = play(dev.mesh, [dict(kind="pinch", at=[0, 53, 80], to=[0, 53, 180], approach_mm=50,
                                   depth_mm=2.0, radius_mm=8.0, start_s=0.1, duration_s=0.8)])
    packets = [r.skin_deformed_detection() for r in results if r.packet_due]
    assert packets and packets[-1]["arrayOfDeformedNodes"][0]["deformedNodeIntensity"] == 0
    for p in packets:
        assert validate_payload(td, "event", "skinDeformedDetection", p) == []
    for r in results:
        assert validate_payload(td, "property", "contactInformation", r.contact_information()) == []
        for a in r.actions:
            assert validate_payload(td, "event", "actionDetection", a) == []


def test_bad_payload_names_the_field():
    td = build_tactile_td(example_device("flat"))
    bad = {"timeStamp": 1, "numOfDeformedNodes": 1,
           "arrayOfDeformedNodes": [{"deformedNodeID": 3, "deformedNodeIntensity": -1.0}]}
    problems = validate_payload(td, "event", "skinDeformedDetection", bad)
    assert [p.path for p in problems] == ["$.arrayOfDeformedNodes[0].deformedNodeIntensity"]
    assert validate_payload(td, "event", "actionDetection", "wave")[0].path == "$"


def test_broken_td_gives_readable_errors_naming_the_field():
    td = build_tactile_td(example_device("barrel"))
    del td["security"]
    td["title"] = 42
    td["properties"]["skinNodes"]["forms"][0]["op"] = "explode"
    td["properties"]["skinNodes"]["properties"]["arrayOfNodes"]["items"]["properties"]["nodeLocation"][
        "properties"]["x"]["unit"] = "inch"
    del td["events"]["actionDetection"]
    td["properties"]["contactInformation"]["oneOf"] = []
    td["events"]["skinDeformedDetection"]["forms"][0].pop("subprotocol")
    problems = {(p.rule, p.path) for p in validate_td(td)}
    expected = {
        ("td-1.1", "$.security"),
        ("td-1.1", "$.title"),
        ("td-1.1", "$.properties.skinNodes.forms[0].op"),
        ("tactile", "$.properties.skinNodes.properties.arrayOfNodes.items.properties.nodeLocation"
                    ".properties.x.unit"),
        ("tactile", "$.events.actionDetection"),
        ("interop", "$.properties.contactInformation.oneOf"),
        ("interop", "$.events.skinDeformedDetection.forms[0].subprotocol"),
    }
    assert expected <= problems
    for p in validate_td(td):
        assert len(str(p)) < 300  # readable: no whole sub-documents pasted into messages


@pytest.mark.parametrize(("where", "value"), [
    ("properties", [1, 2]), ("properties", {"skinNodes": "a string"}),
    ("events", {"skinDeformedDetection": {"forms": 7}}), ("actions", {"a": {"forms": ["href", 3]}}),
])
def test_malformed_affordances_are_reported_not_crashed_on(where, value):
    td = build_tactile_td(example_device("flat"))
    td[where] = value
    problems = validate_td(td)
    assert any(p.rule == "td-1.1" and p.path.startswith(f"$.{where}") for p in problems)


def test_context_defines_every_vocabulary_term():
    ctx = tactile_context()["@context"]
    assert ctx["tac"].startswith("https://")

    def terms(schema):
        for key, sub in schema.get("properties", {}).items():
            yield key
            yield from terms(sub)
        if "items" in schema:
            yield from terms(schema["items"])
        if "data" in schema:
            yield from terms(schema["data"])

    used = set(PROPERTIES) | set(EVENTS)
    for aff in [*PROPERTIES.values(), *EVENTS.values()]:
        used |= set(terms(aff))
        used.add(aff["@type"].removeprefix("tac:"))
        for unit in _units(aff):
            used.add(unit)
    missing = used - set(ctx)
    assert not missing


def _units(node):
    if isinstance(node, dict):
        if "unit" in node:
            yield node["unit"]
        for v in node.values():
            yield from _units(v)


runner = CliRunner()


@pytest.mark.parametrize("shape", SHAPES)
def test_cli_show_prints_a_valid_td(shape, tmp_path):
    res = runner.invoke(app, ["td", "show", "--shape", shape])
    assert res.exit_code == 0, res.output
    f = tmp_path / "td.json"
    f.write_text(res.output)
    res = runner.invoke(app, ["td", "validate", str(f)])
    assert res.exit_code == 0 and "valid" in res.output


def test_cli_validate_reports_paths_and_exits_1(tmp_path):
    td = build_tactile_td(example_device("flat"))
    td["properties"]["skinShape"]["properties"]["shapeType"]["type"] = "number"
    f = tmp_path / "bad.json"
    f.write_text(json.dumps(td))
    res = runner.invoke(app, ["td", "validate", str(f)])
    assert res.exit_code == 1
    assert "$.properties.skinShape.properties.shapeType.type" in res.output


def test_cli_validate_rejects_non_json(tmp_path):
    f = tmp_path / "x.json"
    f.write_text("{nope")
    res = runner.invoke(app, ["td", "validate", str(f)])
    assert res.exit_code == 2 and "not JSON" in res.output  # bad input (InvalidInput), not a TD with problems


def test_cli_show_values_includes_mesh():
    res = runner.invoke(app, ["td", "show", "--shape", "flat", "--values"])
    out = json.loads(res.output)
    assert out["values"]["skinNodes"]["numOfNodes"] == 256
    assert np.isfinite([n["nodeLocation"]["x"] for n in out["values"]["skinNodes"]["arrayOfNodes"]]).all()
