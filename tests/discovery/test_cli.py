"""``wott-hub directory query|list`` against a real directory mounted under a prefix: a bare host
URL is enough, the host's ``/.well-known/wot`` names the API."""

from __future__ import annotations

import asyncio
import json
import re
import sys
from pathlib import Path

from wott_directory import Directory, DirectoryClient, DirectoryServer, DirectorySettings

WOTT_HUB = Path(sys.executable).with_name("wott-hub")


async def _cli(*args: str) -> tuple[int, str, str]:
    pipe = asyncio.subprocess.PIPE
    proc = await asyncio.create_subprocess_exec(str(WOTT_HUB), "directory", *args, stdout=pipe, stderr=pipe)
    out, err = await asyncio.wait_for(proc.communicate(), 60)
    return proc.returncode, out.decode(), err.decode()


def test_directory_query_and_list(run):
    async def scenario():
        server = await DirectoryServer(Directory(DirectorySettings(token="t")), prefix="/tdd").start()
        client = DirectoryClient(server.url, token="t")
        try:
            assert server.url.endswith("/tdd/")
            for name in ("barrel-1", "pad-1"):
                await client.put({"@context": "https://www.w3.org/2022/wot/td/v1.1", "id": f"urn:ex:{name}",
                                  "title": name, "securityDefinitions": {"n": {"scheme": "nosec"}},
                                  "security": "n"})
            root = server.url.removesuffix("tdd/")
            code, out, err = await _cli("query", '$[?@.title=="barrel-1"].id', "--url", root)
            assert code == 0, err
            assert json.loads(out) == ["urn:ex:barrel-1"]
            code, out, _ = await _cli("list", "--url", server.url)
            assert code == 0 and re.search(r"^urn:ex:pad-1 +pad-1$", out, re.M), out  # a table: id, title
            code, _, err = await _cli("query", "$[?@.title==", "--url", root)
            assert code == 1 and "400" in err and "JSONPath" in err
        finally:
            client.close()
            await server.stop()

    run(scenario(), 120)
