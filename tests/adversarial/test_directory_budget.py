"""Issue 33 item 10, the directory's budgets in bytes, against a real directory server on 127.0.0.1
(SQLite file): merge patches cannot grow a TD past ``max_body_bytes``; the stored TDs together stay
under ``max_store_bytes`` and the replay log (memory and database) under ``max_event_bytes``, however
large the updates; an invalid TD with 40,000 properties is validated off the IOLoop while another
client's reads keep answering."""

from __future__ import annotations

import json
import sqlite3
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from .conftest import DirectoryThread

TOKEN = "budget-token"
MIB = 1024 * 1024
AUTH = {"Authorization": f"Bearer {TOKEN}"}
TD_TYPE = {**AUTH, "Content-Type": "application/td+json"}
MERGE_PATCH = {**AUTH, "Content-Type": "application/merge-patch+json"}
READ_TIMEOUT_S = 300.0
"""No request here is timed: a loaded machine may take long; a hang would still end the test."""


@pytest.fixture
def db(tmp_path: Path) -> Path:
    return tmp_path / "tdd.db"


def started(db: Path, **settings: Any) -> DirectoryThread:
    return DirectoryThread(TOKEN, f"sqlite:///{db}", **settings).start()


@pytest.fixture
def http() -> Iterator[httpx.Client]:
    with httpx.Client(timeout=60) as c:
        yield c


def make_td(thing_id: str, **extra: Any) -> dict[str, Any]:
    return {"@context": "https://www.w3.org/2022/wot/td/v1.1", "id": thing_id, "title": f"thing {thing_id}",
            "securityDefinitions": {"nosec_sc": {"scheme": "nosec"}}, "security": "nosec_sc", **extra}


def filler(n_bytes: int, seed: str) -> str:
    return (seed * (n_bytes // len(seed) + 1))[:n_bytes]


def test_merge_patches_cannot_grow_a_td_past_max_body_bytes(db, http):
    tdd = started(db)
    try:
        url = f"{tdd.url}things/urn:grow"
        assert http.put(url, json=make_td("urn:grow"), headers=TD_TYPE).status_code == 201
        answers = []
        for i in range(5):  # each patch 1.9 MB, under max_body_bytes (2 MiB) on its own
            patch = {"description": filler(1_900_000, f"patch {i} ")} if i == 0 else \
                {f"description{i}": filler(1_900_000, f"patch {i} ")}
            answers.append(http.patch(url, content=json.dumps(patch), headers=MERGE_PATCH))
        stored = http.get(url, headers=AUTH)
    finally:
        tdd.stop()
    assert [a.status_code for a in answers] == [204, 413, 413, 413, 413], [a.text[:200] for a in answers]
    problem = answers[1].json()
    assert answers[1].headers["Content-Type"].startswith("application/problem+json")
    assert "max_body_bytes" in problem["detail"], problem
    assert len(stored.content) < 2 * MIB + 4096


def test_stored_tds_and_the_replay_log_have_byte_budgets(db, http):
    tdd = started(db, max_store_bytes=12 * MIB, max_event_bytes=6 * MIB)
    try:
        created = []
        for i in range(10):  # 10 x 1.9 MB TDs against a 12 MiB store: the seventh does not fit
            r = http.put(f"{tdd.url}things/urn:big-{i}", content=json.dumps(
                make_td(f"urn:big-{i}", description=filler(1_900_000, f"td {i} "))), headers=TD_TYPE)
            created.append(r)
        statuses = [r.status_code for r in created]
        stored = tdd.directory.stored_bytes
        for k in range(8):  # the same TD updated with 1.9 MB changes: a 1.9 MB diff each time
            r = http.put(f"{tdd.url}things/urn:big-0", content=json.dumps(
                make_td("urn:big-0", description=filler(1_900_000, f"update {k} "))), headers=TD_TYPE)
            assert r.status_code == 204, r.text[:300]
        log_bytes = tdd.directory.events.log_bytes
        first_kept = tdd.directory.events.first_kept
        # a client resuming finds only what was kept: the stream's replay holds no more than the budget
        replayed, size = 0, 0
        try:  # the replay comes at once; then the stream waits for new events: read until it is quiet
            with http.stream("GET", f"{tdd.url}events?diff=true", headers={**AUTH, "Last-Event-ID": "0"},
                             timeout=httpx.Timeout(60, read=10)) as s:
                for line in s.iter_lines():
                    if line.startswith("data: "):
                        replayed += 1
                        size += len(line)
        except httpx.ReadTimeout:
            pass
    finally:
        tdd.stop()
    assert statuses.count(201) == 6 and statuses[6:] == [413] * 4, statuses
    assert "max_store_bytes" in created[6].json()["detail"], created[6].json()
    assert stored <= 12 * MIB
    assert log_bytes <= 6 * MIB, f"{log_bytes} bytes of events kept in memory"
    with sqlite3.connect(db) as conn:
        rows, data = conn.execute("SELECT count(*), coalesce(sum(length(data)), 0) "
                                  "FROM tdd_events").fetchone()
        oldest = conn.execute("SELECT min(id) FROM tdd_events").fetchone()[0]
    assert data <= 6 * MIB + 2 * MIB, f"{rows} events, {data} bytes of them in the database"
    assert oldest >= first_kept  # the database keeps what memory keeps, no older
    assert replayed >= 1 and size <= 6 * MIB + 2 * MIB


def test_an_invalid_td_with_40000_properties_is_validated_off_the_loop(db, http):
    tdd = started(db)
    try:
        small = http.put(f"{tdd.url}things/urn:small", json=make_td("urn:small"), headers=TD_TYPE)
        assert small.status_code == 201
        props = {f"p{i}": {"type": "nope", "forms": [{"href": "x"}]} for i in range(40_000)}
        body = json.dumps(make_td("urn:wide", properties=props), separators=(",", ":")).encode()
        assert len(body) < 2 * MIB  # under max_body_bytes: it is validated, not refused for its size
        answered: list[tuple[float, float]] = []  # (sent, answered) of each GET, perf_counter s
        stop = threading.Event()

        def reader() -> None:
            with httpx.Client(timeout=READ_TIMEOUT_S) as c:
                while not stop.is_set():
                    t0 = time.perf_counter()
                    c.get(f"{tdd.url}things/urn:small").raise_for_status()
                    answered.append((t0, time.perf_counter()))
                    time.sleep(0.02)  # a client reading now and then, not a busy loop: without the
                    # pause this thread and the server's took most of the GIL from the validation
                    # it measures (a validation on the loop still holds one GET for all of it)

        thread = threading.Thread(target=reader)
        thread.start()
        try:
            while not answered and thread.is_alive():  # the reader is going before the wide TD is sent
                time.sleep(0.01)
            put_start = time.perf_counter()
            r = http.put(f"{tdd.url}things/urn:wide", content=body, headers=TD_TYPE,
                         timeout=READ_TIMEOUT_S)
            put_end = time.perf_counter()
        finally:
            stop.set()
            thread.join(READ_TIMEOUT_S)
    finally:
        tdd.stop()
    assert r.status_code == 400 and r.json()["validationErrors"], r.text[:300]
    # while the PUT was in flight, the other client kept being answered: no GET waited for the
    # validation (on the loop, one GET waits all of it: most of the PUT)
    during = [(a, b) for a, b in answered if b > put_start and a < put_end]
    longest = max((b - max(a, put_start) for a, b in during), default=0.0)
    assert len(during) >= 2 and longest < 0.5 * (put_end - put_start), \
        f"another client's TD GET waited {longest:.2f} s of the wide PUT's {put_end - put_start:.2f} s"
