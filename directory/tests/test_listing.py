"""Listing with pagination (WoT Discovery 7.3.2.1.5): order, next/canonical Link headers, collection."""

from __future__ import annotations

import random
from urllib.parse import parse_qs, urlsplit

import pytest


@pytest.fixture
def populated(http, helpers, tdd):
    ids = [f"urn:example:t{i:02d}" for i in range(25)] + ["urn:example:Zed", "urn:example:äpfel"]
    random.Random(1).shuffle(ids)
    for thing_id in ids:
        r = http.put(f"/things/{thing_id}", json=helpers.make_td(thing_id, title=thing_id),
                     headers=helpers.td_headers())
        assert r.status_code == 201
    return sorted([*ids, tdd.directory.own_id])


def test_listing_is_an_array_sorted_by_id(http, populated):
    # tdd-things-list-only, tdd-things-list-method, tdd-things-list-resp, -resp-content-type,
    # tdd-things-list-pagination-order-default, tdd-things-default-representation
    r = http.get("/things")
    assert r.status_code == 200
    assert r.headers["content-type"] == "application/ld+json"
    ids = [td["id"] for td in r.json()]
    assert ids == populated  # Python sorts str by code point: "Zed" < "t00" < "äpfel"
    assert all("registration" in td for td in r.json())


def test_pages_follow_next_links(http, populated):
    # tdd-things-list-pagination, -limit, -header-nextlink, -nextlink-attr, -nextlink-base,
    # -header-canonicallink
    seen: list[str] = []
    url = "/things?limit=10"
    pages = 0
    while url:
        r = http.get(url)
        assert r.status_code == 200
        page = r.json()
        assert len(page) <= 10
        seen += [td["id"] for td in page]
        canonical = r.links["canonical"]
        assert canonical["url"] == f"{http.base_url}things"
        assert canonical["etag"]
        nxt = r.links.get("next")
        if nxt:
            assert nxt["url"].startswith(str(http.base_url))  # absolute
            q = parse_qs(urlsplit(nxt["url"]).query)
            assert q["limit"] == ["10"] and q["offset"] == [str(len(seen))]
            url = nxt["url"]
        else:
            url = None
        pages += 1
    assert pages == 3
    assert seen == populated


def test_limit_above_the_page_size_is_capped_with_a_next_link(start_directory, helpers):
    import httpx

    srv = start_directory(page_size=5)
    with httpx.Client(base_url=srv.url, headers={"Authorization": f"Bearer {helpers.token}"}) as c:
        for i in range(7):
            c.put(f"/things/urn:example:{i}", json=helpers.make_td(f"urn:example:{i}"),
                  headers=helpers.td_headers())
        r = c.get("/things?limit=100")
        assert len(r.json()) == 5
        q = parse_qs(urlsplit(r.links["next"]["url"]).query)
        assert q == {"offset": ["5"], "limit": ["100"]}
        assert len(c.get(r.links["next"]["url"]).json()) == 3  # 7 TDs + the directory's own
        r = c.get("/things")  # no limit: the server's page size, next link without limit
        assert parse_qs(urlsplit(r.links["next"]["url"]).query) == {"offset": ["5"]}


def test_etag_changes_with_the_collection(http, helpers, populated):
    first = http.get("/things?limit=5").links["canonical"]["etag"]
    assert http.get("/things?limit=5").links["canonical"]["etag"] == first
    http.delete(f"/things/{populated[0]}")
    assert http.get("/things?limit=5").links["canonical"]["etag"] != first


def test_collection_format(http, populated):
    # tdd-things-list-pagination-collection
    r = http.get("/things", params={"limit": 10, "format": "collection"})
    assert r.status_code == 200 and r.headers["content-type"] == "application/ld+json"
    body = r.json()
    assert body["@context"] == "https://www.w3.org/2022/wot/discovery"
    assert body["@type"] == "ThingCollection"
    assert body["total"] == len(populated)
    assert [td["id"] for td in body["members"]] == populated[:10]
    assert body["next"] == r.links["next"]["url"]
    assert "format=collection" in body["next"]
    assert body["@id"].startswith(f"{http.base_url}things?")


def test_offset_past_the_end_is_an_empty_page(http, populated):
    r = http.get("/things", params={"offset": 1000})
    assert r.status_code == 200 and r.json() == []
    assert "next" not in r.links


@pytest.mark.parametrize("query", ["limit=0", "limit=-3", "limit=ten", "offset=-1", "offset=1.5",
                                   "format=xml"])
def test_bad_query_arguments_are_400_problems(http, query):
    r = http.get(f"/things?{query}")
    assert r.status_code == 400
    assert r.headers["content-type"] == "application/problem+json"
    assert r.json()["status"] == 400 and r.json()["detail"]
