from __future__ import annotations

import json

import pytest

from wott_hub.events.record import KIND_EVENT, KIND_PROPERTY, Record
from wott_hub.history import HistoryReader, HistoryWriter, create_engine, database_url, upgrade


@pytest.fixture(params=["sqlite", "postgresql"])
def database(request, tmp_path):
    """The history database of a test: an SQLite file, then a fresh PostgreSQL database (the
    session's throw-away cluster, tests/postgres.py): the same models and migrations on both."""
    if request.param == "postgresql":
        return request.getfixturevalue("pg_url")
    return database_url(tmp_path / "history.db")


@pytest.fixture
def engine(database):
    eng = create_engine(database)
    upgrade(eng)
    yield eng
    eng.dispose()


@pytest.fixture
def writer(engine):
    w = HistoryWriter(engine, interval_s=0.01)
    yield w
    w.stop()


@pytest.fixture
def reader(engine):
    return HistoryReader(engine)


def _make_records(thing: str, start_after: int, n: int, t0_ns: int = 10**18, period_ns: int = 8_333_333):
    """n records alternating a skinDeformedDetection event and a contactInformation change."""
    out = []
    for i in range(n):
        seq = start_after + i + 1
        t = t0_ns + (i // 2) * period_ns
        if i % 2 == 0:
            data = json.dumps({"timeStamp": t, "numOfDeformedNodes": 1,
                               "arrayOfDeformedNodes": [{"deformedNodeID": i, "deformedNodeIntensity": 0.5}]})
            out.append(Record(thing, seq, KIND_EVENT, "skinDeformedDetection", t, data))
        else:
            data = json.dumps({"numOfContacts": 1, "contactLocations": [{"x": i, "y": 0, "z": 0}],
                               "contactForces": [{"x": 0, "y": 0, "z": -0.1}]})
            out.append(Record(thing, seq, KIND_PROPERTY, "contactInformation", t, data))
    return out


@pytest.fixture
def make_records():
    return _make_records
