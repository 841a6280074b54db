from __future__ import annotations

import datetime as dt

import pytest

from wott_hub.history import parse_time

NOW = 1_795_000_000_123_456_789


def test_numbers_relative_times_and_iso_dates():
    assert parse_time(str(NOW)) == NOW  # nanoseconds, exactly
    assert parse_time("1795000000") == 1_795_000_000 * 10**9
    assert parse_time("1795000000.5") == 1_795_000_000_500_000_000
    assert parse_time("-10m", now_ns=NOW) == NOW - 600 * 10**9
    assert parse_time("-250ms", now_ns=NOW) == NOW - 250_000_000
    assert parse_time("now", now_ns=NOW) == NOW
    assert parse_time("2026-11-22T10:00:00Z") == int(
        dt.datetime(2026, 11, 22, 10, tzinfo=dt.UTC).timestamp()) * 10**9
    with pytest.raises(ValueError, match="not a time"):
        parse_time("yesterday")
