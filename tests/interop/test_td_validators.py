"""Every TD the demo hub serves, through the standard's own validators: the Thingweb playground
(``@thing-description-playground/core`` and ``/assertions``, npm, pinned by package-lock.json) and
pyld's JSON-LD expansion.

The TDs: each Thing of the catalogue (the demo devices, one per installed family, and the hub
Thing), a replay Thing started through the hub Thing's ``replay`` action, the embedded directory's
own TD (``/.well-known/wot``) and every TD the directory lists. No network: both JSON-LD processors
get their contexts from local files only (``CONTEXTS``), any other URL fails the test. The TD 1.0
context (``https://www.w3.org/2019/wot/td/v1``) is not among the reference data in ../shared, and it
is not copied from the web into the repository: that URI is answered with the TD 1.1 context. Every
TD lists it first and the 1.1 URI second, and a later context in the array overrides an earlier
one, so the terms the TDs use get their TD 1.1 definitions either way (docs/interop.md).

Before issue 34 JSON-LD failed on every device TD: the Tactile context's unit term ``mm/s`` is a
term in the form of an IRI ("term in form of IRI must expand to definition", in both processors).
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path
from typing import Any

import httpx
import pytest
from pyld import jsonld

from wott_hub.td.builder import tactile_context

HERE = Path(__file__).resolve().parent
TD_V1 = "https://www.w3.org/2019/wot/td/v1"
TD_V11 = "https://www.w3.org/2022/wot/td/v1.1"
DISCOVERY = "https://www.w3.org/2022/wot/discovery"
QUDT_MM_PER_S = "http://qudt.org/vocab/unit/MilliM-PER-SEC"


@pytest.fixture(scope="module")
def contexts(fleet, shared_data, tmp_path_factory) -> dict[str, Path]:
    """Context URL -> local file. The Tactile context is the one the hub serves (and the package's)."""
    served = httpx.get(f"{fleet.url}/contexts/tactile-v1.jsonld")
    assert served.status_code == 200 and served.json() == tactile_context()
    tactile = tmp_path_factory.mktemp("contexts") / "tactile-v1.jsonld"
    tactile.write_bytes(served.content)
    td11 = shared_data / "w3c" / "td-context-1.1.jsonld"
    return {
        TD_V1: td11,  # the 1.0 context is not in ../shared: answered with 1.1 (module docstring)
        TD_V11: td11,
        DISCOVERY: shared_data / "w3c" / "discovery-core.jsonld",
        f"{fleet.url}/contexts/tactile-v1.jsonld": tactile,
    }


@pytest.fixture(scope="module")
def served_tds(fleet, eventually) -> dict[str, dict[str, Any]]:
    """Every TD the demo hub serves, by where it was read, with a replay Thing running meanwhile."""
    with httpx.Client(base_url=fleet.url, timeout=10) as c:
        hub = c.get("/wot/hub").json()
        device = next(d["id"] for d in c.get("/wot/hub/properties/devices").json() if d["recorded"])
        r = c.post(hub["actions"]["replay"]["forms"][0]["href"], json={"device": device, "from": "-10s"})
        assert r.status_code == 200, r.text
        try:
            tds = {f"/wot/{i}": c.get(path).json() for i, path in c.get("/wot").json().items()}
            tds["/.well-known/wot"] = c.get("/.well-known/wot").json()
            replay_id = tds[f"/wot/{r.json()['thing']}"]["id"]

            def listed() -> list[dict[str, Any]] | None:  # the directory registers a new Thing a moment later
                things = c.get("/things").json()
                return things if replay_id in {td["id"] for td in things} else None

            tds.update({f"/things/{td['id']}": td
                        for td in eventually(listed, what="the replay Thing in the directory")})
        finally:
            c.post(hub["actions"]["stopReplay"]["forms"][0]["href"], json={"device": device})
    replay = r.json()["thing"]
    assert f"/wot/{replay}" in tds
    families = {td.get("tac:family") for td in tds.values()} - {None}
    assert len(families) >= 3, families  # a device of every installed family
    assert any(td.get("@type") == "ThingDirectory" for td in tds.values())
    assert len(tds) >= 12
    return tds


IRI_TERM_URL = "http://127.0.0.1:1/bad.jsonld"
IRI_TERM = "iri-term"  # the name of test_an_iri_shaped_term_fails_both_processors's TD in the node run


@pytest.fixture(scope="module")
def iri_term(contexts, tmp_path_factory) -> tuple[dict[str, Any], Path]:
    """What issue 34 found: a TD whose context has a unit term with a '/' (``mm/s`` as it was), and
    that context's file (served at ``IRI_TERM_URL``)."""
    bad = json.loads(Path(contexts[TD_V11]).read_text())  # any context will do: one more term
    bad["@context"]["mm/s"] = "http://qudt.org/vocab/unit/MilliM-PER-SEC"
    path = tmp_path_factory.mktemp("iri-term") / "bad.jsonld"
    path.write_text(json.dumps(bad))
    td = {"@context": [TD_V1, TD_V11, IRI_TERM_URL], "title": "t",
          "securityDefinitions": {"n": {"scheme": "nosec"}}, "security": ["n"]}
    return td, path


@pytest.fixture(scope="module")
def validated(node_wot, served_tds, contexts, iri_term, tmp_path_factory) -> dict[str, dict[str, Any]]:
    """The playground's report of each TD (validate_tds.mjs) by its name: each served TD, and the TD of
    ``iri_term`` last, under ``IRI_TERM``. One node process for all: its start and its validators'
    loading are paid once (the reports of a TD do not depend on the others': the bad context is
    requested by that TD alone, and it comes after the served ones). A TD served the same (equal as
    JSON) at two places (a Thing's own URL and the directory, say) is validated once and its report
    given to both: the validators are deterministic."""
    work = tmp_path_factory.mktemp("playground")
    first: dict[str, str] = {}  # the TD's text -> the first place it was read
    for where, td in served_tds.items():
        first.setdefault(json.dumps(td, sort_keys=True), where)
    unique = {where: served_tds[where] for where in first.values()}
    bad_td, bad_context = iri_term
    (work / "input.json").write_text(json.dumps(
        {"contexts": {**{url: str(path) for url, path in contexts.items()}, IRI_TERM_URL: str(bad_context)},
         "tds": {**unique, IRI_TERM: bad_td}}))
    done = subprocess.run([*node_wot, str(HERE / "validate_tds.mjs"), str(work / "input.json")], cwd=HERE,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    lines = [json.loads(line) for line in done.stdout.splitlines() if line.strip()]
    assert lines and lines[-1] == {"done": len(unique) + 1}, done.stderr[-3000:]
    reports = {line["name"]: line for line in lines[:-1]}
    served = {where: {**reports[first[json.dumps(td, sort_keys=True)]], "name": where}
              for where, td in served_tds.items()}
    return {**served, IRI_TERM: reports[IRI_TERM]}


@pytest.fixture(scope="module")
def playground(validated) -> dict[str, dict[str, Any]]:
    """The playground's report of each served TD, by where the TD was read."""
    return {where: got for where, got in validated.items() if where != IRI_TERM}


def test_the_playground_validates_every_served_td(served_tds, playground):
    assert set(playground) == set(served_tds)
    for where, got in playground.items():
        report = got["report"]
        assert report["json"] == report["schema"] == report["jsonld"] == "passed", (where, report, got["log"])
        assert report["additional"] in ("passed", "warning"), (where, got["details"], got["log"])
        assert "error" not in got["assertions"], (where, got["assertions"])
        assert got["assertions"]["fail"] == [], (where, got["assertions"]["fail"])
        assert got["assertions"]["counts"].get("pass", 0) > 100, (where, got["assertions"]["counts"])


def test_the_only_defaults_not_stated_are_read_write_only_inside_values(served_tds, playground):
    """The full schema (every TD 1.1 default stated) passes once readOnly/writeOnly are added to the
    data schemas of values (members, items, input, output, data): every other default is stated
    (wott_hub.td.defaults, the directory's selftd). Those two are left out on purpose."""
    for where, got in playground.items():
        assert got["report"]["defaults"] in ("passed", "warning"), where  # a warning: those two
        left = got["defaults"]["besidesValueReadWriteOnly"]
        assert left == [], (where, left)
        td = served_tds[where]
        for name, prop in td.get("properties", {}).items():
            assert {k: type(prop.get(k)) for k in ("readOnly", "writeOnly", "observable")} == dict.fromkeys(
                ("readOnly", "writeOnly", "observable"), bool), (where, name)
        for name, action in td.get("actions", {}).items():
            stated = (action.get("safe"), action.get("idempotent"))
            assert all(isinstance(v, bool) for v in stated), (where, name)


def _loader(contexts: dict[str, Path]):
    documents = {url: json.loads(path.read_text()) for url, path in contexts.items()}

    def load(url: str, options: Any = None) -> dict[str, Any]:
        if url not in documents:
            raise AssertionError(f"JSON-LD context {url} requested: only local contexts (no network)")
        return {"contentType": "application/ld+json", "contextUrl": None, "documentUrl": url,
                "document": documents[url]}

    return load


def test_pyld_expands_every_served_td(served_tds, contexts):
    options = {"documentLoader": _loader(contexts)}
    units = set()
    for where, td in served_tds.items():
        expanded = jsonld.expand(td, options)  # raises on an invalid context or term
        assert len(expanded) == 1 and expanded[0]["@id"] == td["id"], where
        text = json.dumps(expanded)
        if "tac:family" in td:
            assert "https://w3id.org/wott/tactile#" in text, where  # the Tactile terms are IRIs
            units |= {u for u in ("MilliM", "N", "NanoSEC", "MilliM-PER-SEC")
                      if f'"http://qudt.org/vocab/unit/{u}"' in text}
    assert units == {"MilliM", "N", "NanoSEC", "MilliM-PER-SEC"}  # every unit an IRI, mm.s-1 too


def test_the_loader_refuses_what_it_does_not_hold(contexts):
    td = {"@context": [TD_V11, "https://example.org/elsewhere.jsonld"], "title": "t"}
    refused = r"loading remote context failed[\s\S]*example\.org/elsewhere"
    with pytest.raises(jsonld.JsonLdError, match=refused):
        jsonld.expand(td, {"documentLoader": _loader(contexts)})


def test_an_iri_shaped_term_fails_both_processors(contexts, iri_term, validated):
    """What issue 34 found: a unit term with a '/' (``mm/s`` as it was) is refused, so a vocabulary
    change that breaks JSON-LD fails here (pyld) and in the playground's JSON-LD check (its report
    comes from the module's one node run, ``validated``)."""
    td, bad_context = iri_term
    with pytest.raises(jsonld.JsonLdError):
        jsonld.expand(td, {"documentLoader": _loader({**contexts, IRI_TERM_URL: bad_context})})
    got = validated[IRI_TERM]
    assert got["report"]["jsonld"] == "failed" and any("term in form of IRI" in x for x in got["log"]), got
