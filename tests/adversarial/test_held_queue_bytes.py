"""Issue 48, item 4: the plane's held queue ("committed" durability) on a full disk under raw images.

In ``history_durability = "committed"`` a recorded Thing's records are held on the event plane until the
writer says they are committed. On a full disk nothing is committed: the writer keeps its queue within
``history_queue_mb`` and drops the rest, but the watermark stands still, so the held queue kept every
record up to ``max_held`` (1,000,000 raw images: ~250 GB). Now it is bounded in bytes too (the writer's
budget, per Thing), the oldest let go, counted in ``health.history.held.notDelivered`` and said in the log.

A real hub (``uv run wott-hub run``) records a simulated flat-vision camera's images (``record_raw_hz``,
~250 kB each) into SQLite on a tmpfs of its own (the spool on it too), ``history_queue_mb = 16``; a pad is
served live but not recorded (``history_skip``: in "committed" mode a recorded Thing says nothing while
its history fails, which is the mode's promise) and read by a bystander SSE client. At rest its resident
memory is measured, then the tmpfs is filled (every write of the database and of the spool fails:
ENOSPC) and the hub is watched until held records have been let go for ``AFTER_SHED_S``.

Measured: resident memory stays under twice its rest level; health names the held queue (its bytes
within the budget, ``notDelivered`` counted); the log says it once in a while, not per record; the
bystander keeps streaming; SIGTERM stops the hub within its bounded stop, without a traceback.
The tmpfs needs root (CI runs as root): without it the test fails naming it, it is not skipped.
"""

from __future__ import annotations

from .test_writer_queue_bytes import attack

QUEUE_MB = 16
ATTACK_S = 60.0  # at most: the held queue reaches its budget within seconds at the camera's rate
AFTER_SHED_S = 10.0  # sampled this long once held records are let go (the bound holding, not just reached)
COMMITTED = 'history_durability = "committed"\nhistory_skip = ["pad"]\n'


def test_a_full_disk_in_committed_mode_keeps_the_held_queue_in_its_byte_budget(tmp_path, running_hub,
                                                                                 eventually):
    m = attack(tmp_path, running_hub, eventually, QUEUE_MB, ATTACK_S, hub_lines=COMMITTED,
               dropping=lambda h: h["held"]["notDelivered"] > 0, after_s=AFTER_SHED_S)
    samples, healths, took, log = m["samples"], m["healths"], m["attack_s"], m["log"]
    rest_rss, rest_pad_hz, pad_hz, pad_gap = m["rest_rss_mb"], m["rest_pad_hz"], m["pad_hz"], m["pad_gap_s"]
    shed_after, rc, stop_s = m["dropped_after_s"], m["rc"], m["stop_s"]
    peak = max(rss for _, rss in samples)
    held = [h["held"] for h in healths]
    last = held[-1]
    print(f"committed, history_queue_mb {QUEUE_MB}: RSS rest {rest_rss:.0f} MB, peak {peak:.0f} MB, "
          f"last {samples[-1][1]:.0f} MB over {took:.1f} s; held records let go after "
          f"{None if shed_after is None else round(shed_after, 1)} s; held bytes max "
          f"{max(h['bytes'] for h in held) / 1e6:.1f} MB, notDelivered {last['notDelivered']}; "
          f"pad {rest_pad_hz:.1f} -> {pad_hz:.1f} events/s (longest gap {pad_gap:.2f} s); "
          f"stop {stop_s:.1f} s")

    # the disk really refused, and the held queue reached its bound: named in health and in the log
    assert healths[-1]["state"] == "degraded" and "full" in healths[-1]["lastError"], healths[-1]
    assert shed_after is not None, f"no held record let go in {ATTACK_S} s of a full disk: {last}"
    assert last["maxBytesPerThing"] == QUEUE_MB * 1_000_000, last
    assert all(h["bytes"] <= QUEUE_MB * 1_000_000 for h in held), max(h["bytes"] for h in held)
    assert "not delivered live" in log, log[-3000:]
    said = log.count("not delivered live")
    assert said <= took / 10 + 2, f"said {said} times in {took:.0f} s: once in a while, not per record"

    # memory: bounded by the budget, not by the camera's bytes
    assert peak < 2 * rest_rss, (rest_rss, samples)

    # the bystander streams on (generous bounds: the machine is shared)
    assert pad_hz > rest_pad_hz / 3, (rest_pad_hz, pad_hz)
    assert pad_gap < 5.0, pad_gap

    # a bounded stop, no traceback
    assert rc is not None, f"the hub still runs 60 s after SIGTERM: {log[-3000:]}"
    assert stop_s < 30, f"the stop took {stop_s:.1f} s"
    assert "Traceback" not in log, log[-3000:]
