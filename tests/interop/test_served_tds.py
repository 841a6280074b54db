"""Every TD the demo hub serves passes the interop rules ``wott-hub td validate`` applies: the
context array node-wot 0.9 needs, a ``type`` on every data schema wotpy builds, SSE forms that
say ``subprotocol: "sse"`` with the data's media type."""

from __future__ import annotations

import httpx

from wott_hub.td.validate import validate_td

TD_CONTEXT = ["https://www.w3.org/2019/wot/td/v1", "https://www.w3.org/2022/wot/td/v1.1"]


def test_every_served_td_passes_the_interop_rules(fleet):
    with httpx.Client(base_url=fleet.url, timeout=10) as c:
        hub = c.get("/wot/hub").json()
        device = next(d["id"] for d in c.get("/wot/hub/properties/devices").json() if d["recorded"])
        r = c.post(hub["actions"]["replay"]["forms"][0]["href"], json={"device": device, "from": "-10s"})
        assert r.status_code == 200, r.text
        try:
            tds = {i: c.get(path).json() for i, path in c.get("/wot").json().items()}
            tds["directory"] = c.get("/.well-known/wot").json()
            tds.update({td["id"]: td for td in c.get("/things").json()})
        finally:
            c.post(hub["actions"]["stopReplay"]["forms"][0]["href"], json={"device": device})
    assert r.json()["thing"] in tds and len(tds) >= 10
    for key, td in tds.items():
        tactile = "skinNodes" in td.get("properties", {})
        assert validate_td(td, tactile=tactile) == [], key
        assert td["@context"][:2] == TD_CONTEXT, key
        for aff in [*td.get("properties", {}).values(), *td.get("events", {}).values()]:
            for form in aff["forms"]:
                if form.get("subprotocol") == "sse" and not key.startswith(("directory", "urn:uuid")):
                    assert form["contentType"] == "application/json", (key, form)


def test_the_rule_finds_a_data_schema_without_a_type():
    # the hub Thing's replay input as it was: wotpy raised "Unknown type: None" on it
    td = {"actions": {"replay": {"input": {"type": "object", "properties": {
        "from": {"oneOf": [{"type": "string"}, {"type": "number"}]}}}}},
          "properties": {"things": {"oneOf": [{"type": "array"}, {"type": "object"}], "forms": []}}}
    problems = validate_td({"@context": TD_CONTEXT, "title": "t", "securityDefinitions": {
        "nosec_sc": {"scheme": "nosec"}}, "security": "nosec_sc", **td}, tactile=False)
    assert {p.path for p in problems if p.rule == "interop"} == {
        "$.actions.replay.input.properties.from.type", "$.properties.things.type"}
