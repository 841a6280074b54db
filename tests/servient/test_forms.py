"""TD forms and the TD clean-up adapter (the interop rules of DESIGN.md section 2)."""

from __future__ import annotations

import copy

from wotpy.wot.dictionaries.thing import ThingFragment
from wotpy.wot.td import ThingDescription
from wotpy.wot.thing import Thing

from wott_hub.examples import example_device
from wott_hub.servient import FormLayout, clean_td, hub_td, with_forms
from wott_hub.td.builder import build_tactile_td
from wott_hub.td.validate import validate_td

LAYOUT = FormLayout("http://127.0.0.1:8080", "ws://127.0.0.1:8081")


def _find(node, key, value):
    if isinstance(node, dict):
        return any((k == key and v == value) or _find(v, key, value) for k, v in node.items())
    if isinstance(node, list):
        return any(_find(v, key, value) for v in node)
    return False


def test_clean_td_removes_the_placeholders_wotpy_writes():
    td = build_tactile_td(example_device("flat"))
    for aff in [*td["properties"].values(), *td["events"].values()]:
        aff.pop("forms")
    wotpy_doc = ThingDescription.from_thing(Thing(thing_fragment=ThingFragment(td))).to_dict()
    assert _find(wotpy_doc, "oneOf", [])  # what node-wot rejects
    cleaned = clean_td(copy.deepcopy(wotpy_doc))
    assert not _find(cleaned, "oneOf", []) and not _find(cleaned, "enum", [])
    assert cleaned["properties"]["skinShape"]["properties"]["shapeType"]["enum"] == [
        "rectangularPrism", "cylinder", "barrel"]  # real keywords stay


def test_device_forms_state_op_method_subprotocol_and_come_http_first():
    td = build_tactile_td(example_device("barrel"), base="http://127.0.0.1:8080/",
                          forms=LAYOUT.factory("barrel-1"), context_url=LAYOUT.context_url)
    td["forms"] = LAYOUT.thing_forms("barrel-1")
    assert validate_td(td) == []
    nodes = td["properties"]["skinNodes"]["forms"]
    assert [f["op"] for f in nodes] == [["readproperty"], ["observeproperty", "unobserveproperty"],
                                       ["readproperty", "observeproperty", "unobserveproperty"]]
    assert nodes[0]["href"] == "http://127.0.0.1:8080/wot/barrel-1/properties/skinNodes"
    # SSE: the subprotocol says it; contentType is the data's, which node-wot decodes by
    assert nodes[1]["subprotocol"] == "sse" and nodes[1]["contentType"] == "application/json"
    assert nodes[2]["href"] == "ws://127.0.0.1:8081/barrel-1"
    event = td["events"]["skinDeformedDetection"]["forms"]
    assert event[0] == {"href": "http://127.0.0.1:8080/wot/barrel-1/events/skinDeformedDetection",
                        "op": ["subscribeevent", "unsubscribeevent"], "htv:methodName": "GET",
                        "subprotocol": "sse", "contentType": "application/json"}
    assert {op for f in td["forms"] for op in f["op"]} == {"readallproperties", "subscribeallevents",
                                                           "unsubscribeallevents"}


def test_with_forms_rebases_a_recorded_td_on_another_server():
    td = build_tactile_td(example_device("flat"), forms=LAYOUT.factory("pad-1"))
    other = FormLayout("http://10.0.0.2:9000", None)
    moved = with_forms(td, "replay-pad-1", other)
    assert moved["base"] == "http://10.0.0.2:9000/"
    hrefs = [f["href"] for a in moved["properties"].values() for f in a["forms"]]
    assert all(h.startswith("http://10.0.0.2:9000/wot/replay-pad-1/") for h in hrefs)
    assert validate_td(moved) == []
    assert td["base"] == "http://127.0.0.1:8080/"  # the original is untouched


def test_hub_td_is_a_valid_td_with_interop_forms():
    assert validate_td(hub_td("lab", LAYOUT), tactile=False) == []
