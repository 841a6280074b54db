"""Python's cyclic garbage collector, set for a process that is a hub (``wott-hub run``).

Why (issue 35; docs/hub.md, "Garbage collection"): at 32 devices x 120 Hz a hub makes ~15,000
objects a second that live a second or more (records kept for resume, a frame's arrays), none in
a reference cycle. With CPython's defaults they reached the oldest generation, whose full
collections then ran every few seconds and scanned every object of the process (~300,000): 170 ms
with the event loop stopped, frames dropped by the devices meanwhile (3 % at 32 devices).

- Middle generation collected 10x less often (``THRESHOLDS``: every ~70,000 allocations, ~3 s at
  32 devices instead of ~0.3 s): a recorded Thing's records (``events.plane.RING_RECORDED``) are
  gone before it runs, so they never reach the oldest generation.
- What start-up made (imports, wotpy, Thing Descriptions: ~130,000 objects that live as long as the
  hub) is moved out of the collector's sight (``gc.freeze``): a full collection, when one comes,
  scans only what was made since. Frozen objects are still freed when their last reference goes;
  only a cycle made before start-up ended and dropped later is never collected.

Not done by ``Hub`` itself: the thresholds and the frozen set are the process's, and a program
that embeds a hub (tests run hundreds in one process) decides for its own.
"""

from __future__ import annotations

import gc

__all__ = ["THRESHOLDS", "tune_for_hub"]

THRESHOLDS = (700, 100, 10)
"""``gc.set_threshold``: CPython's default but the middle generation's (10)."""


def tune_for_hub() -> None:
    """After start-up: these thresholds, and what start-up made frozen."""
    gc.set_threshold(*THRESHOLDS)
    gc.collect()
    gc.freeze()
