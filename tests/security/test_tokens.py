"""Tokens: the format, the stored hash, revocation without a restart, the CLI, the policy's rules."""

from __future__ import annotations

import json
import os
import time

import pytest
from typer.testing import CliRunner

from wott_hub.cli import app
from wott_hub.config import HubConfig
from wott_hub.errors import ConfigError, Conflict, InvalidInput
from wott_hub.security import AccessPolicy, Scope, SecurityConfig, TokenFile, TokenStore, build_policy
from wott_hub.security.tokens import split_token


def test_a_token_is_stored_only_as_a_salted_scrypt_hash(tmp_path):
    f = TokenFile(tmp_path / "t.json")
    token, stored = f.create("dash", Scope.READ)
    tid, secret = split_token(token)
    assert token.startswith("wott_") and tid == stored.id
    text = (tmp_path / "t.json").read_text()
    assert secret not in text and stored.hash.startswith("scrypt$")
    assert oct(os.stat(tmp_path / "t.json").st_mode & 0o777) == "0o600"
    again, other = f.create("dash2", Scope.READ)
    assert other.hash.split("$")[4] != stored.hash.split("$")[4]  # its own salt
    with pytest.raises(Conflict):
        f.create("dash", Scope.ADMIN)


def test_verify_accepts_the_token_and_nothing_near_it(tmp_path):
    f = TokenFile(tmp_path / "t.json")
    token, _ = f.create("a", Scope.CONTROL)
    store = TokenStore(file=f.path)
    assert store.verify(token).name == "a"
    assert store.verify(token).scope_level is Scope.CONTROL  # the remembered answer
    tid, secret = split_token(token)
    for wrong in (token[:-1], f"wott_{tid}_{secret}x", f"wott_00000000_{secret}", "", "Bearer", secret):
        assert store.verify(wrong) is None, wrong


def test_a_revoked_token_stops_working_without_a_restart(tmp_path, monkeypatch):
    import wott_hub.security.tokens as tokens

    monkeypatch.setattr(tokens, "_RELOAD_EVERY_S", 0.0)
    f = TokenFile(tmp_path / "t.json")
    token, _ = f.create("a", Scope.READ)
    store = TokenStore(file=f.path)
    assert store.verify(token) is not None
    time.sleep(0.01)
    f.revoke("a")
    assert store.verify(token) is None


def test_scopes_imply_the_ones_below():
    assert Scope.ADMIN.grants(Scope.CONTROL) and Scope.CONTROL.grants(Scope.READ)
    assert not Scope.READ.grants(Scope.CONTROL) and not Scope.CONTROL.grants(Scope.ADMIN)
    with pytest.raises(InvalidInput, match="read, control or admin"):
        Scope.parse("root")


@pytest.mark.parametrize(("method", "path", "scope"), [
    ("GET", "/wot/hub", Scope.READ), ("GET", "/things", Scope.READ), ("GET", "/.well-known/wot", Scope.READ),
    ("POST", "/wot/hub/actions/replay", Scope.CONTROL), ("PUT", "/hub/property/x", Scope.CONTROL),
    ("PUT", "/things/urn:x", Scope.ADMIN), ("DELETE", "/things/urn:x", Scope.ADMIN),
    ("PATCH", "/things/urn:x", Scope.ADMIN), ("POST", "/things", Scope.ADMIN),
    ("OPTIONS", "/wot/hub", None), ("GET", "/healthz", None), ("GET", "/", None),
    ("GET", "/twin/device.html", None), ("GET", "/contexts/tactile-v1.jsonld", None),
])
def test_the_scope_each_route_needs(method, path, scope):
    assert AccessPolicy().required(method, path) == scope


def test_a_safe_action_needs_read_a_fleet_action_admin_others_control():
    policy = AccessPolicy(enforced=True)
    form = {"htv:methodName": "POST", "op": ["invokeaction"]}
    policy.secure_td({"actions": {
        "historyRecords": {"safe": True, "forms": [{**form, "href": "http://h:1/wot/hub/actions/historyRecords"}]},
        "addDevice": {"forms": [{**form, "href": "http://h:1/wot/hub/actions/addDevice"}]},
        "replay": {"safe": False, "forms": [{**form, "href": "http://h:1/wot/hub/actions/replay"}]}}})
    assert policy.required("POST", "/wot/hub/actions/historyRecords") is Scope.READ
    assert policy.required("POST", "/wot/hub/actions/addDevice") is Scope.ADMIN
    assert policy.required("POST", "/wot/hub/actions/replay") is Scope.CONTROL
    assert policy.required("POST", "/wot/pad/actions/calibrate") is Scope.CONTROL


def test_open_on_loopback_refused_elsewhere_unless_insecure():
    assert not build_policy(SecurityConfig(), "127.0.0.1").enforced
    assert not build_policy(SecurityConfig(), "::1").enforced
    with pytest.raises(ConfigError, match="wott-hub tokens create"):
        build_policy(SecurityConfig(), "0.0.0.0")
    assert not build_policy(SecurityConfig(insecure=True), "0.0.0.0").enforced
    assert build_policy(SecurityConfig(tokens_file="/nonexistent.json"), "127.0.0.1").enforced


def test_open_mode_tds_declare_nosec_and_enforced_ones_bearer():
    forms = [{"href": "ws://h:1/x"}, {"href": "http://h:2/wot/x/properties/p"},
             {"href": "http://h:2/wot/x/properties/p/observe", "subprotocol": "sse"}]
    td = {"properties": {"p": {"forms": forms}}}
    assert AccessPolicy().secure_td(dict(td))["security"] == ["nosec_sc"]
    secured = AccessPolicy(enforced=True).secure_td(td)
    assert secured["security"] == ["bearer_sc"]
    either = ["bearer_either_sc"]
    got = secured["properties"]["p"]["forms"]
    assert [f.get("security") for f in got] == [either, None, None, either]
    # before the SSE form, the same stream as a long poll under the Thing's header scheme: node-wot
    # 0.9.2 subscribes with it (tests/interop/test_nodewot_credentials.py)
    assert got[2] == {"href": forms[2]["href"], "op": [], "subprotocol": "longpoll",
                      "contentType": "application/json"}
    assert AccessPolicy(enforced=True).secure_td(secured) == secured  # once only


def test_cli_create_list_revoke(tmp_path):
    runner = CliRunner()
    f = str(tmp_path / "t.json")
    out = runner.invoke(app, ["tokens", "create", "kiosk", "--scope", "control", "--file", f])
    assert out.exit_code == 0, out.output
    token = out.stdout.strip().splitlines()[-1]
    assert split_token(token) is not None
    listed = runner.invoke(app, ["tokens", "list", "--file", f])
    assert "kiosk" in listed.stdout and "control" in listed.stdout
    assert split_token(token)[1] not in listed.stdout
    bad = runner.invoke(app, ["tokens", "create", "x", "--scope", "root", "--file", f])
    assert bad.exit_code == 2 and "read, control or admin" in bad.output
    assert runner.invoke(app, ["tokens", "revoke", "kiosk", "--file", f]).exit_code == 0
    assert json.loads((tmp_path / "t.json").read_text()) == {"tokens": []}
    assert runner.invoke(app, ["tokens", "revoke", "kiosk", "--file", f]).exit_code == 3


def test_cli_create_without_a_file_prints_a_config_entry_the_config_accepts(tmp_path):
    out = CliRunner().invoke(app, ["tokens", "create", "wall", "--scope", "admin"])
    assert out.exit_code == 0
    entry = out.output[out.output.index("[[security.client]]"):]
    (tmp_path / "hub.toml").write_text(entry)
    cfg = HubConfig.load(tmp_path / "hub.toml")
    token = [line for line in out.output.splitlines() if line.startswith("wott_")][0]
    assert TokenStore(cfg.security.client).verify(token).scope == "admin"


def test_security_table_errors_name_the_key(tmp_path):
    with pytest.raises(ConfigError, match=r"\[security\]: cert and key go together"):
        HubConfig.from_dict({"security": {"cert": "c.pem"}})
    with pytest.raises(ConfigError, match=r"\[security\].cors_origins"):
        HubConfig.from_dict({"security": {"cors_origins": ["lab.example"]}})


def test_tls_selfsigned_writes_a_pair_ssl_loads(tmp_path):
    from wott_hub.security.tls import server_context

    out = CliRunner().invoke(app, ["tls", "selfsigned", "--out", str(tmp_path), "--host", "hub.lab"])
    assert out.exit_code == 0, out.output
    assert server_context(tmp_path / "cert.pem", tmp_path / "key.pem") is not None
    with pytest.raises(ConfigError, match="not a matching PEM"):
        server_context(tmp_path / "key.pem", tmp_path / "key.pem")
