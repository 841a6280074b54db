"""The fleet page in a real headless Chromium: the demo fleet found through the TD directory."""

from __future__ import annotations

from urllib.parse import quote

import httpx

from wott_hub.plugins.demo import demo_devices


def test_fleet_page_lists_every_demo_device_from_the_directory(fleet, page, screenshot, wait):
    demo = demo_devices()
    keys = sorted({d.id for d in demo} | {"barrel"})
    page.goto(f"{fleet.url}/")
    wait(page, "window.twin && window.twin.ready", timeout=20_000)
    assert page.evaluate("window.twin.source") == "directory"
    # every device listed with its health from the hub Thing; the busy barrel shows a rate and an action
    wait(page,
        """keys => {
          const rows = Object.values(window.twin.devices);
          const byKey = Object.fromEntries(rows.map(r => [r.key, r]));
          return keys.every(k => byKey[k] && byKey[k].health)
            && byKey.barrel.rate > 0 && byKey.barrel.lastAction;
        }""", arg=keys, timeout=15_000)
    rows = page.evaluate("Object.values(window.twin.devices)")
    assert sorted(r["key"] for r in rows) == keys, rows
    assert {r["family"] for r in rows} == {"scene", *(d.family for d in demo)}, rows
    assert all(r["health"] in ("ok", "degraded", "starting", "ended") for r in rows), rows
    assert page.locator("#fleet tbody tr").count() == len(keys)
    assert page.evaluate("window.twin.hubState") in ("ok", "degraded"), page.evaluate("window.twin")
    box = page.locator("#fleet").bounding_box()
    bottom = box["y"] + box["height"] + 24
    screenshot(page, "twin-fleet", clip={"x": 0, "y": 0, "width": 1280, "height": bottom})
    # a row links to the device page of that Thing, by the URL of its TD in the directory
    href = page.locator("#fleet tbody tr[data-key='barrel'] a").get_attribute("href")
    td_url = f"{fleet.url}/things/{quote(fleet.hub._identity.device_id('barrel'), safe='')}"
    assert href == f"/twin/device.html?td={quote(td_url, safe='')}"
    assert page.errors == []


def test_fleet_page_follows_the_directory_when_a_device_comes_and_goes(fleet, page, scene_barrel, wait):
    page.goto(f"{fleet.url}/")
    wait(page, "window.twin && window.twin.ready", timeout=20_000)
    fleet.call(fleet.hub.add_device, scene_barrel("late"))  # the hub's directory notifies the page
    wait(page, "Object.values(window.twin.devices).some(r => r.key === 'late' && r.health)",
                           timeout=10_000)
    fleet.call(fleet.hub.remove_device, "late")  # ... and deletes its TD: thing_deleted
    wait(page, "!Object.values(window.twin.devices).some(r => r.key === 'late')", timeout=10_000)
    assert page.errors == []


def test_fleet_page_falls_back_to_the_servient_catalogue_without_a_directory(tmp_path, hub_runner, page,
                                                                           scene_barrel, wait):
    hub = hub_runner(tmp_path / "hub.db", [scene_barrel("solo")], directory=False)
    try:
        assert httpx.get(f"{hub.url}/things").status_code == 404  # [directory] enabled = false
        page.goto(f"{hub.url}/")
        wait(page, "window.twin && window.twin.ready", timeout=20_000)
        wait(page, "Object.values(window.twin.devices).some(r => r.key === 'solo' && r.health)",
                               timeout=10_000)
        assert page.evaluate("window.twin.source") == "catalogue"
        href = page.locator("#fleet tbody tr[data-key='solo'] a").get_attribute("href")
        assert href == f"/twin/device.html?td={quote(f'{hub.url}/wot/solo', safe='')}"
        assert page.errors == []
    finally:
        hub.stop()
