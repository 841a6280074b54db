"""Reconnect pacing: grows, is capped, is jittered within bounds, starts over after a success."""

from __future__ import annotations

import asyncio
import random
import threading

import pytest

from wott_hub.drivers.backoff import Backoff


def test_delays_grow_exponentially_up_to_the_cap_without_jitter():
    b = Backoff(initial_s=0.1, cap_s=1.0, factor=2.0, jitter=0.0)
    assert [round(b.next_delay(), 9) for _ in range(7)] == [0.1, 0.2, 0.4, 0.8, 1.0, 1.0, 1.0]
    assert b.attempts == 7


def test_jitter_stays_within_its_band_and_spreads_retries():
    b = Backoff(initial_s=0.1, cap_s=2.0, jitter=0.5, rng=random.Random(1))
    for attempt in range(40):
        base = b.base_delay(attempt)
        d = b.next_delay()
        assert base * 0.5 <= d <= base <= 2.0
    fleet = [Backoff(initial_s=1.0, cap_s=1.0, rng=random.Random(seed)).next_delay() for seed in range(20)]
    assert len({round(d, 6) for d in fleet}) == 20  # devices that failed together do not retry together


def test_reset_after_success_starts_over():
    b = Backoff(initial_s=0.05, cap_s=5.0, jitter=0.0)
    for _ in range(10):
        b.next_delay()
    b.reset()
    assert b.next_delay() == 0.05


def test_a_device_gone_for_days_does_not_overflow():
    b = Backoff(initial_s=0.05, cap_s=5.0, jitter=0.0)
    b.attempts = 10**6
    assert b.next_delay() == 5.0


def test_wait_returns_early_when_stopped_and_sleep_works_in_asyncio():
    stop = threading.Event()
    stop.set()
    assert Backoff(initial_s=60.0, cap_s=60.0).wait(stop) is True
    b = Backoff(initial_s=0.001, cap_s=0.001)
    assert b.wait(threading.Event()) is False
    asyncio.run(b.sleep())
    assert b.attempts == 2


@pytest.mark.parametrize("kwargs", [{"initial_s": 0}, {"initial_s": 2.0, "cap_s": 1.0}, {"factor": 0.5},
                                    {"jitter": 1.5}])
def test_nonsense_settings_are_refused(kwargs):
    with pytest.raises(ValueError):
        Backoff(**kwargs)
