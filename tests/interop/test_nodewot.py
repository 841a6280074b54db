"""node-wot 0.9.2, the JavaScript reference client, against the demo hub: every Thing, every event.

The script (nodewot.mjs) fetches each TD through node-wot's own TD schema check,
reads every property, observes ``contactInformation``, subscribes to every
event, invokes the hub Thing's actions, tries a write to a read-only property
and explores the hub's directory; it prints what each operation gave. Before
this issue node-wot received 0 notifications: named SSE messages never reach
``EventSource.onmessage``, and ``text/event-stream`` as a form's contentType
made every value unreadable.
"""

from __future__ import annotations

import httpx
import pytest

TD_V1 = "https://www.w3.org/2019/wot/td/v1"


@pytest.fixture(scope="module")
def report(fleet, node_script, scripted_press, tare_every_device) -> dict:
    """The script's report, run once. Once its subscriptions are open a device joins, presses and
    ends, which makes the hub Thing emit ``healthChange``. Every device is tared first: the replay
    the script starts ends with a ``deviceAction`` whatever ran before this module."""
    tare_every_device()
    script = node_script("nodewot.mjs", fleet.url, "15")
    assert script.next(timeout=60)["ready"] is True
    scripted_press("late-press")
    return script.next(timeout=60)["report"]


def test_node_wot_consumes_every_thing_and_receives_every_event(demo_hub, report):
    things = report["things"]
    replay = report["hubActions"]["replay"]["value"]["thing"]  # served while the script ran
    served = set(httpx.get(f"{demo_hub.url}/wot").json()) - {"late-press"}
    assert set(things) == served | {replay} and replay.startswith("replay-")
    assert "hub" in things and len(served - {"hub"}) >= 3

    for thing_id, entry in things.items():
        assert entry["requestThingDescription"] == {"ok": True}, thing_id  # node-wot's TD check
        seen = entry["affordances"]
        if thing_id != replay:  # still served: node-wot saw every affordance of its TD
            td = httpx.get(f"{demo_hub.url}/wot/{thing_id}").json()
            assert seen == {"properties": sorted(td["properties"]), "events": sorted(td.get("events", {}))}
        assert entry["readAllProperties"] == {"ok": True, "value": seen["properties"]}, thing_id
        assert sorted(entry["read"]) == seen["properties"]
        assert all(r["ok"] for r in entry["read"].values()), (thing_id, entry["read"])
        assert sorted(entry["events"]) == seen["events"]
        for name, got in {**entry["events"], **entry["observe"]}.items():
            assert got["bad"] is None and got["n"] >= 1, (thing_id, name, got)
        if thing_id != "hub":
            assert entry["observe"]["contactInformation"]["n"] >= 1
    assert report["unsubscribe"]["errors"] == [] and report["unsubscribe"]["stopped"] == sum(
        len(e["events"]) + len(e["observe"]) for e in things.values())


def test_node_wot_reads_the_raw_image_property_through_its_image_forms(report):
    """Issue 29: each camera device's rawImage, read through its PNG and JPEG forms without error; the
    bytes are the image (its JSON form, a base64 PNG string, is read above with every property)."""
    raw = report["raw"]
    assert {"barrel-1", "flatpad-1"} <= set(raw)
    for thing_id, forms in raw.items():
        png, jpeg = forms["image/png"], forms["image/jpeg"]
        assert png["ok"] and jpeg["ok"], (thing_id, forms)
        assert png["value"]["head"] == "89504e47" and png["value"]["length"] > 1000  # \x89PNG
        assert jpeg["value"]["head"].startswith("ffd8ff") and jpeg["value"]["value"] == "string"


def test_node_wot_invokes_the_hub_things_actions(report):
    replay = report["hubActions"]["replay"]
    assert replay["ok"] and replay["value"]["thing"] in report["things"], replay
    stop = report["hubActions"]["stopReplay"]
    assert stop["ok"] and stop["value"]["stopped"] is True and stop["value"]["emitted"] > 0, stop


def test_node_wot_is_refused_a_write_to_a_read_only_property(report):
    # no writeproperty form: node-wot refuses before sending; the hub refuses a PUT, naming it
    refused = report["readOnlyWrite"]
    assert not refused["nodewot"]["ok"] and "did not get suitable form" in refused["nodewot"]["error"]
    put = refused["http"]["value"]
    assert put["status"] == 405 and put["contentType"] == "application/problem+json"
    assert "'skinShape'" in put["body"] and "read-only" in put["body"]


def test_node_wot_requests_and_explores_the_hubs_directory(demo_hub, report):
    directory = report["directory"]
    got = directory["requestThingDescription"]
    assert got["ok"], got
    assert got["value"]["context"][:2] == [TD_V1, "https://www.w3.org/2022/wot/td/v1.1"]
    assert directory["consume"] == {"ok": True, "value": ["things"]}
    listed = {td["id"] for td in httpx.get(f"{demo_hub.url}/things").json()}
    explored = directory["explore"]
    assert explored["ok"] and explored["value"]["error"] is None, explored
    assert set(explored["value"]["ids"]) <= listed and len(explored["value"]["ids"]) >= 5


def test_node_wot_writes_to_the_directory_through_its_td(report):
    # each answer has the Content-Type the directory's TD declares (text/plain for 201 and 204):
    # node-wot threw after a successful write on tornado's text/html, or on no type at all (204)
    writes = report["directoryWrites"]
    for name in ("createThing", "deleteThing"):
        assert writes[name]["ok"], (name, writes[name])
    assert writes["updateThing"] == {"ok": True, "value": "updated"}
    assert writes["createAnonymousThing"] == {"ok": True, "value": 1}  # found, then deleted
    # no codec for application/merge-patch+json: an object goes out as "[object Object]" (400);
    # the patch as JSON text passes through as it is
    refused = writes["partiallyUpdateThing"]
    assert not refused["ok"] and "Bad Request" in refused["error"]
    assert writes["partiallyUpdateThingText"] == {"ok": True, "value": "patched"}


def test_node_wot_gets_the_history_outputs_as_bytes_only(report):
    history = report["history"]
    for name, media in (("historyRecords", "application/x-ndjson"), ("historyExport", "application/x-mcap")):
        assert history[name]["value"] == {"ok": False, "error": f"Content type {media} not supported"}
        assert history[name]["bytes"]["ok"] and history[name]["bytes"]["value"]["length"] > 0, history[name]
    assert history["historyRecords"]["bytes"]["value"]["firstLine"]["seq"] > 0  # JSON Lines: a record a line
    assert history["historyExport"]["bytes"]["value"]["magic"] == "\x89MCAP0\r\n"

