"""The scores summed per family and written as the report's tables.

A release speed is right within 20 % of the scene's, or within the detector's rest speed
(5 mm/s) where the scene's is below 25 mm/s (a static press lifts at 0 mm/s: no relative
error exists). Percentiles are nearest-rank (``report.pct``).
"""

from __future__ import annotations

import statistics
from collections.abc import Iterable

from report import markdown_table, pct

from .score import CaseScore

__all__ = ["ACTION_COLUMNS", "SUMMARY_HEADER", "actions_table", "cases_table", "noise_table", "speed_ok",
           "summary", "summary_row", "targets_table"]

ACTION_COLUMNS = ("touch", "press", "slip", "pinch", "pat", "collision", "release")
GESTURE = {"slide": "slide", "pinch": "pinch", "tap": "tap"}  # every other case is a static press
REST_SPEED = 5.0


def speed_ok(reported: float | None, truth: float) -> bool:
    if reported is None:
        return False
    return abs(reported - truth) <= max(0.2 * truth, REST_SPEED)


def _pct(part: int, whole: int) -> str:
    return f"{100 * part / whole:.1f}" if whole else "-"


def _mp(values: list[float], scale: float = 1.0, fmt: str = "{:.2f}") -> str:
    if not values:
        return "-"
    return f"{fmt.format(statistics.median(values) * scale)} / {fmt.format(pct(values, 95) * scale)}"


def summary(scores: Iterable[CaseScore]) -> dict[str, float | int]:
    """The numbers the targets are stated in, over ``scores``."""
    s = list(scores)
    loc = [v for c in s for v in c.location_mm]
    force = [v for c in s for v in c.force_rel]
    us = [v for c in s for v in c.process_us]
    expected = sum(len(c.expected) for c in s)
    return {
        "steady": sum(c.steady for c in s), "right": sum(c.right for c in s),
        "frames": sum(c.frames for c in s), "spurious": sum(c.spurious for c in s),
        "rest": sum(c.rest for c in s), "phantom": sum(c.phantom for c in s),
        "loc_median": statistics.median(loc) if loc else float("nan"), "loc_p95": pct(loc, 95),
        "force_median": statistics.median(force) if force else float("nan"), "force_p95": pct(force, 95),
        "expected": expected, "reported": expected - sum(len(c.missed) for c in s),
        "false": sum(len(c.false_actions) for c in s),
        "static": sum(c.static for c in s), "static_slip": sum(c.static and "slip" in c.reported for c in s),
        "release_ok": sum(speed_ok(c.release_speed, c.release_truth) for c in s), "cases": len(s),
        "actions_ok": sum(not c.missed and not c.false_actions for c in s),
        "us_median": statistics.median(us) if us else float("nan"), "us_p95": pct(us, 95),
    }


def summary_row(name: str, m: dict[str, float | int]) -> list[object]:
    return [name, _pct(int(m["right"]), int(m["steady"])), f"{m['loc_median']:.2f} / {m['loc_p95']:.2f}",
            _pct(int(m["spurious"]), int(m["frames"])), f"{m['phantom']} / {m['rest']}",
            f"{100 * m['force_median']:.0f} / {100 * m['force_p95']:.0f}",
            f"{m['reported']} / {m['expected']}", m["false"], f"{m['actions_ok']} / {m['cases']}",
            f"{m['static_slip']} / {m['static']}",
            f"{m['release_ok']} / {m['cases']}", f"{m['us_median']:.0f} / {m['us_p95']:.0f}"]


SUMMARY_HEADER = ["family", "right count % (steady frames)", "location median / p95 mm",
                  "spurious % of frames", "phantom (rest frames)", "force error median / p95 %",
                  "scripted actions reported", "other actions", "cases with exactly their actions",
                  "slip on a static press",
                  "release speed right", "µs/frame median / p95"]


def targets_table(rows: list[list[object]]) -> str:
    return markdown_table(SUMMARY_HEADER, rows)


def cases_table(scores: list[CaseScore]) -> str:
    rows = []
    for c in scores:
        speed = "-" if c.release_speed is None else f"{c.release_speed:.1f} ({c.release_truth:.1f})"
        slip = "-" if c.slip_speed is None else f"{c.slip_speed:.1f} ({c.slip_truth:.1f})"
        rows.append([c.family, c.case, f"{c.right} / {c.steady}", _mp(c.location_mm),
                     f"{c.spurious} / {c.frames}", _mp(c.force_rel, 100, "{:.0f}"), " ".join(c.reported),
                     " ".join(c.missed) or "-", speed, slip])
    return markdown_table(["family", "case", "right count (steady frames)", "location median / p95 mm",
                           "frames with a spurious contact", "force error median / p95 %", "actions reported",
                           "missed", "release speed mm/s (scene's)", "slip speed mm/s (scene's)"], rows)


def actions_table(scores: list[CaseScore]) -> str:
    """Per family and scripted gesture: in how many of its cases each action was reported."""
    rows = []
    for family in dict.fromkeys(c.family for c in scores):
        for gesture in ("press", "slide", "pinch", "tap"):
            cases = [c for c in scores
                     if c.family == family and GESTURE.get(c.case.split()[0], "press") == gesture]
            if cases:
                rows.append([family, f"{gesture} ({len(cases)})",
                             *(sum(a in c.reported for c in cases) for a in ACTION_COLUMNS)])
    return markdown_table(["family", "scripted (cases)", *ACTION_COLUMNS], rows)


def noise_table(rows: list[list[object]]) -> str:
    """Per family: ε, what its frames at rest show, the contact thresholds derived from its noise floor."""
    return markdown_table(["family", "ε mm", "rest frames", "largest node norm at rest, median / max mm",
                           "declared noise floor mm", "merge: valley below the lower peak, mm",
                           "birth: peak above its base, mm", "side-lobe ratio"], rows)
