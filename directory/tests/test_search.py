"""JSONPath search (RFC 9535) over HTTP, and the pre-filter's equivalence with the plain library."""

from __future__ import annotations

import json

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from jsonpath import JSONPathEnvironment
from wott_directory.mergepatch import apply_merge_patch, merge_diff
from wott_directory.search import SearchEngine


def _fleet(http, helpers):
    for i, (title, kind) in enumerate([("barrel-1", "barrel"), ("barrel-2", "barrel"), ("pad-1", "flat")]):
        td = helpers.make_td(f"urn:example:{i}", title=title, **{"@type": ["tac:TactileSensor"],
                                                                "tac:family": kind})
        td["properties"]["skinNodes"] = {"type": "object", "observable": True,
                                         "forms": [{"href": f"https://h/{i}/nodes"}]}
        assert http.put(f"/things/urn:example:{i}", json=td, headers=helpers.td_headers()).status_code == 201


def test_jsonpath_search(http, helpers):
    # tdd-search-large-tdds; the JSONPath affordance of directory.tm.json
    _fleet(http, helpers)
    q = lambda query: http.get("/search/jsonpath", params={"query": query})  # noqa: E731
    r = q('$[?@.title=="barrel-1"]')
    assert r.status_code == 200 and r.headers["content-type"] == "application/json"
    assert [td["id"] for td in r.json()] == ["urn:example:0"]
    assert q('$[?@["tac:family"]=="barrel"].title').json() == ["barrel-1", "barrel-2"]
    assert q("$[?search(@.title, 'pad')].id").json() == ["urn:example:2"]
    assert q("$[?@.properties.skinNodes.observable==true].id").json() == [
        "urn:example:0", "urn:example:1", "urn:example:2"]
    assert q("$[?length(@.properties) > 1 && @.title != 'pad-1'].id").json() == [
        "urn:example:0", "urn:example:1"]
    assert q("$[*].registration.created").status_code == 200
    assert q("$..forms[?@.href=='https://h/2/nodes'].href").json() == ["https://h/2/nodes"]
    assert q('$[?@.title=="nope"]').json() == []
    assert q("$[?@.title==$[0].title].id").json() == [q("$[0].id").json()[0]]


def test_search_sees_writes_at_once(http, helpers):
    _fleet(http, helpers)
    http.delete("/things/urn:example:1")
    assert http.get("/search/jsonpath", params={"query": "$[?@['tac:family']=='barrel'].id"}).json() == [
        "urn:example:0"]


# -- the pre-filter gives the library's own answers ----------------------------

keys = st.sampled_from(["title", "kind", "n", "flag", "nested"])
scalars = st.one_of(st.sampled_from(["a", "b", "barrel", ""]), st.integers(-2, 2),
                    st.sampled_from([1.0, 0.0]), st.booleans(), st.none())
values = st.recursive(scalars, lambda inner: st.one_of(st.lists(inner, max_size=3),
                                                        st.dictionaries(keys, inner, max_size=3)),
                      max_leaves=6)
tds = st.lists(st.dictionaries(keys, values, max_size=4), max_size=8)


PLAIN = JSONPathEnvironment(strict=True)
ENGINE = SearchEngine(cache_size=16)


def _literal(v) -> str:
    return json.dumps(v)


@st.composite
def queries(draw):
    def cond():
        path = "@" + "".join(draw(st.lists(st.one_of(keys.map(lambda k: f".{k}"),
                                                      st.integers(-2, 2).map(lambda i: f"[{i}]")),
                                            min_size=1, max_size=3)))
        lit = _literal(draw(scalars))
        op = draw(st.sampled_from(["==", "==", "!=", "<"]))
        return f"{path} {op} {lit}" if draw(st.booleans()) else f"{lit} {op} {path}"

    expr = cond()
    for _ in range(draw(st.integers(0, 2))):
        expr = f"({expr}) {draw(st.sampled_from(['&&', '||']))} ({cond()})"
    if draw(st.booleans()):
        expr = f"!({expr})" if draw(st.booleans()) else expr
    tail = draw(st.sampled_from(["", ".title", "..n", "[*]"]))
    return f"$[?{expr}]{tail}"


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(tds, queries())
def test_prefilter_matches_the_library(docs, query):
    plain = PLAIN.compile(query).findall(docs)
    assert ENGINE.search(query, docs) == plain


def test_prefilter_is_used_for_equality_filters():
    engine = SearchEngine()
    assert engine.compile('$[?@.title=="x"]').guard is not None
    assert engine.compile('$[?@.a.b[0]==1 && @.c > 2].id').guard is not None
    assert engine.compile('$[?@.a==1 || @.b==2]').guard is not None
    assert engine.compile('$[?@.a==1 || @.b>2]').guard is None
    assert engine.compile('$[?@.a==$[0].a]').guard is None
    assert engine.compile('$..[?@.a==1]').guard is None


# -- JSON merge patch (RFC 7396 appendix A) ------------------------------------

RFC7396 = [
    ({"a": "b"}, {"a": "c"}, {"a": "c"}),
    ({"a": "b"}, {"b": "c"}, {"a": "b", "b": "c"}),
    ({"a": "b"}, {"a": None}, {}),
    ({"a": "b", "b": "c"}, {"a": None}, {"b": "c"}),
    ({"a": ["b"]}, {"a": "c"}, {"a": "c"}),
    ({"a": "c"}, {"a": ["b"]}, {"a": ["b"]}),
    ({"a": {"b": "c"}}, {"a": {"b": "d", "c": None}}, {"a": {"b": "d"}}),
    ({"a": [{"b": "c"}]}, {"a": [1]}, {"a": [1]}),
    (["a", "b"], ["c", "d"], ["c", "d"]),
    ({"a": "b"}, ["c"], ["c"]),
    ({"a": "foo"}, None, None),
    ({"a": "foo"}, "bar", "bar"),
    ({"e": None}, {"a": 1}, {"e": None, "a": 1}),
    ([1, 2], {"a": "b", "c": None}, {"a": "b"}),
    ({}, {"a": {"bb": {"ccc": None}}}, {"a": {"bb": {}}}),
]


def test_merge_patch_rfc7396_examples():
    for target, patch, result in RFC7396:
        assert apply_merge_patch(target, patch) == result


leaves = st.one_of(st.integers(), st.text(max_size=3), st.booleans())
json_docs = st.dictionaries(keys, st.recursive(leaves, lambda inner: st.one_of(
    st.lists(inner, max_size=2), st.dictionaries(keys, inner, max_size=2)), max_leaves=5), max_size=4)


@settings(max_examples=100, deadline=None)
@given(json_docs, json_docs)
def test_merge_diff_is_the_inverse_of_apply(old, new):
    assert apply_merge_patch(old, merge_diff(old, new)) == new
