"""node-wot 0.9.2, from the network namespace, consuming a protected TD with a bearer token.

The TD declares ``bearer`` (header); node-wot is given the token for the Thing's id
(``servient.addCredentials``), as its documentation says, and must read a property
and receive events, with the TD as it is served: over the long-poll forms a secured TD lists
before its SSE forms (node-wot's SSE client sends no credential; tests/interop/
test_nodewot_credentials.py has the measurements). Without the token it gets nothing. The
node packages are the ones tests/interop pins (``npm ci`` there; ``.ci/run`` does it).
"""

from __future__ import annotations

import json
import shutil
import subprocess

from wott_hub.security import Scope, TokenFile

from .conftest import HERE, HubProcess
from .test_network import write_config

NODE_MODULES = HERE.parent / "interop" / "node_modules"


def _node(ns: str, workdir, url: str, token: str) -> dict:
    out = subprocess.run(["ip", "netns", "exec", ns, shutil.which("node") or "node",
                          str(workdir / "nodewot_bearer.mjs"), url, token, "8"],
                         capture_output=True, text=True, timeout=120, cwd=workdir)
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_nodewot_with_a_bearer_token_reads_and_receives_events(netns, tmp_path):
    assert (NODE_MODULES / "@node-wot" / "core").is_dir(), "run `npm ci` in tests/interop (.ci/run does)"
    token = TokenFile(tmp_path / "tokens.json").create("node-wot", Scope.READ)[0]
    cfg = write_config(tmp_path, netns[1], '[security]\ntokens_file = "tokens.json"')
    work = tmp_path / "node"
    work.mkdir()
    shutil.copy(HERE / "nodewot_bearer.mjs", work)
    (work / "node_modules").symlink_to(NODE_MODULES)
    hub = HubProcess(["-c", cfg], tmp_path)
    try:
        url = hub.info["devices"]["pad"]
        got = _node(netns[0], work, url, token)
        assert got["security"] == ["bearer_sc"]
        assert got["read"]["shapeType"] == "rectangularPrism", got
        assert got["events"]["skinDeformedDetection"] > 0, got
        assert got["errors"] == [], got
        refused = _node(netns[0], work, url, "wott_00000000_not-a-token")
        assert refused["errors"] == ["TD: HTTP 401"]
    finally:
        hub.stop()
    assert token.split("_", 2)[2] not in hub.log_path.read_text()
