"""The client a hub uses: DirectoryClient, EventStream and Registrar (ttl refresh, expiry when a hub dies),
and the standalone ``wott-directory`` command."""

from __future__ import annotations

import asyncio
import os
import re
import signal
import subprocess
import sys

import httpx
import pytest
from wott_directory import DirectoryClient, ProblemError, Registrar


def run(coro):
    return asyncio.run(asyncio.wait_for(coro, 30))


def test_client_round_trip(tdd, helpers):
    async def scenario():
        c = DirectoryClient(tdd.url, token=helpers.token)
        try:
            assert (await c.directory_description())["@type"] == "ThingDirectory"
            async with c.events(diff=True) as stream:
                assert await c.put(helpers.make_td("urn:example:a")) is True
                assert await c.put(helpers.make_td("urn:example:a", title="b")) is False
                anon = await c.create(helpers.make_td(None, title="anon"))
                assert anon.startswith("urn:uuid:")
                await c.patch("urn:example:a", {"title": "c"})
                assert (await c.get("urn:example:a"))["title"] == "c"
                assert await c.search("$[?@.title=='anon'].id") == [anon]
                for i in range(12):
                    await c.put(helpers.make_td(f"urn:example:p{i:02d}"))
                everything = await c.list(limit=5)
                assert len(everything) == 15 and [t["id"] for t in everything] == sorted(
                    t["id"] for t in everything)
                await c.delete("urn:example:a")
                kinds = [(await stream.next(5)).type for _ in range(17)]
                assert kinds[:4] == ["thing_created", "thing_updated", "thing_created", "thing_updated"]
                assert kinds[-1] == "thing_deleted"
                last = stream.last_event_id
            with pytest.raises(ProblemError) as err:
                await c.get("urn:example:a")
            assert err.value.status == 404
            with pytest.raises(ProblemError) as err:
                await c.put(helpers.make_td("urn:example:bad", title=3))
            assert err.value.status == 400 and err.value.problem["validationErrors"]
            with pytest.raises(ProblemError) as err:
                await c.search("$[")
            assert err.value.status == 400
            # resume: only what happened after the last event seen
            await c.put(helpers.make_td("urn:example:z"))
            async with c.events(last_event_id=last) as stream:
                ev = await stream.next(5)
                assert (ev.type, ev.data) == ("thing_created", {"id": "urn:example:z"})
        finally:
            c.close()

    run(scenario())


def test_event_stream_refused_without_token(start_directory, helpers):
    srv = start_directory(protect_reads=True)

    async def scenario():
        c = DirectoryClient(srv.url)
        with pytest.raises(ProblemError) as err:
            async with c.events():
                pass
        assert err.value.status == 401
        c.close()

    run(scenario())


def test_registrar_keeps_tds_alive_and_they_expire_when_the_hub_dies(start_directory, helpers):
    srv = start_directory(purge_interval=0.05)

    async def scenario():
        # a 2 s ttl refreshed every 0.25 s: only a refresh stalled 1.75 s lets a TD lapse (a hang,
        # not a busy machine)
        hub = Registrar(DirectoryClient(srv.url, token=helpers.token), ttl=2.0, refresh=1 / 8)
        reader = DirectoryClient(srv.url)
        assert await hub.register(helpers.make_td("urn:hub:a"))
        assert await hub.register(helpers.make_td("urn:hub:b"))
        assert (await reader.get("urn:hub:a"))["registration"]["ttl"] == 2.0
        hub.start()
        await asyncio.sleep(4.5)  # > 2 ttl: alive only because the registrar refreshes
        assert {t["id"] for t in await reader.list()} >= {"urn:hub:a", "urn:hub:b"}
        await hub.unregister("urn:hub:b")
        await hub.stop(unregister=False)  # the hub "dies": no more refreshes, nothing deleted
        with pytest.raises(ProblemError):
            await reader.get("urn:hub:b")
        deadline = asyncio.get_running_loop().time() + 60  # a hang's bound; it expires after 2 s
        while asyncio.get_running_loop().time() < deadline:
            try:
                await reader.get("urn:hub:a")
            except ProblemError as e:
                assert e.status == 404
                break
            await asyncio.sleep(0.05)
        else:
            raise AssertionError("the TD of the dead hub did not expire")
        # a directory that is down does not break the registrar
        down = Registrar(DirectoryClient("http://127.0.0.1:9/", timeout=1), ttl=5)
        assert await down.register(helpers.make_td("urn:hub:c")) is False
        assert down.failures == 1
        reader.close()

    run(scenario())


def test_standalone_command(tmp_path, helpers, capsys):
    env = {**os.environ, "WOTT_DIRECTORY_TOKEN": helpers.token}
    proc = subprocess.Popen([sys.executable, "-m", "wott_directory.cli", "--port", "0",
                             "--db", f"sqlite:///{tmp_path / 'd.db'}", "--log-level", "WARNING"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        line = proc.stdout.readline()
        url = re.search(r"at (http://\S+/) ", line).group(1)
        assert "writes need the token" in line
        with httpx.Client(base_url=url) as c:
            assert c.get("/.well-known/wot").json()["base"] == url
            r = c.put("/things/urn:example:lamp", json=helpers.make_td(), headers=helpers.td_headers())
            assert r.status_code == 401
            r = c.put("/things/urn:example:lamp", json=helpers.make_td(),
                      headers={**helpers.td_headers(), "Authorization": f"Bearer {helpers.token}"})
            assert r.status_code == 201
    finally:
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(10) == 0
    from wott_directory.cli import main

    with pytest.raises(SystemExit) as stopped:
        main(["--host", "0.0.0.0", "--open", "--port", "0", "--db", "sqlite://"])
    assert stopped.value.code == 2 and "loopback" in capsys.readouterr().err
