"""The scene set: the same gestures on every family, sized to its skin.

Each case is one short scene (rest, the gesture, rest) and the actions a user expects
from it. Sizes follow each skin: the 16 x 16 pads (1.5 mm markers, 22.5 mm wide) are
pressed by 3 mm tips, the taxel board (16 x 16 taxels at 4 mm) by 10 mm tips, the
TacLink barrel (markers 14-21 mm apart) by 12 mm tips. "Close" presses are 2.5 tip
radii apart, the issue's resolvable distance; "far" ones at least 4.5 radii. On the
barrel, "near" is a press near the bottom camera's end (z = 55 mm, where the markers
are seen at a grazing angle) and "far" one at mid-height on the other side (z = 130 mm,
farthest from both cameras).

Every gesture is played twice: placement A (where the settings were looked at while
they were chosen) and placement B, held out: other places, depths and tip sizes
(pads: 2.5 mm tips, half as deep; taxels: 8 mm tips; barrel: 14 mm tips 5 mm deep on
the other side, as in the issue's report).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

__all__ = ["CASES", "Case", "STATIC_KINDS"]

START_S = 0.3  # rest before every gesture: the skin's rest frames are scored too (no phantom contact)
STATIC_KINDS = ("press", "two-far", "two-close", "release", "near", "far")  # no slip allowed on these


@dataclass(frozen=True)
class Case:
    """One scene: its kind, the steps and the actions it must produce, in order of first appearance."""

    kind: str
    steps: tuple[dict[str, Any], ...]
    expected: tuple[str, ...]
    radius_mm: float
    placement: str = "A"

    @property
    def static(self) -> bool:
        return self.kind in STATIC_KINDS

    @property
    def name(self) -> str:
        return f"{self.kind} {self.placement}"

    def scene(self, name: str) -> dict[str, Any]:
        return {"scene": {"name": name, "loop": False}, "step": [dict(s) for s in self.steps]}


def _press(at: list[float], r: float, depth: float, **kw: Any) -> dict[str, Any]:
    return {"kind": "press", "at": at, "start_s": START_S, "duration_s": 1.0, "depth_mm": depth,
            "radius_mm": r, "ramp_s": 0.1} | kw


PRESSED = ("touch", "press", "release")


def _set(r: float, depth: float, centre: list[float], far: tuple[list[float], list[float]],
         close: tuple[list[float], list[float]], slide: tuple[list[float], list[float]],
         pinch: tuple[list[float], list[float], float]) -> list[Case]:
    return [
        Case("press", (_press(centre, r, depth),), PRESSED, r),
        Case("two-far", (_press(far[0], r, depth), _press(far[1], r, depth)), PRESSED, r),
        Case("two-close", (_press(close[0], r, depth), _press(close[1], r, depth)), PRESSED, r),
        Case("slide", ({"kind": "slide", "at": slide[0], "to": slide[1], "start_s": START_S,
                        "duration_s": 1.0, "depth_mm": depth, "radius_mm": r, "ramp_s": 0.1},),
             ("touch", "slip", "release"), r),
        Case("pinch", ({"kind": "pinch", "at": pinch[0], "to": pinch[1], "approach_mm": pinch[2],
                        "start_s": START_S, "duration_s": 1.0, "depth_mm": depth, "radius_mm": r,
                        "ramp_s": 0.1},), ("touch", "pinch", "release"), r),
        Case("tap", ({"kind": "tap", "at": centre, "start_s": START_S, "depth_mm": depth, "radius_mm": r},),
             ("touch", "pat", "release"), r),
        Case("release", (_press(centre, r, depth, ramp_s=0.35, duration_s=1.2),), PRESSED, r),
    ]


def _held_out(cases: list[Case]) -> list[Case]:
    return [replace(c, placement="B") for c in cases]


def _pad() -> list[Case]:
    y = 11.25
    a = _set(3.0, 0.8, [11.25, y, 0.0], far=([4.5, 4.5, 0.0], [18.0, 18.0, 0.0]),
             close=([7.5, y, 0.0], [15.0, y, 0.0]), slide=([5.0, 8.0, 0.0], [17.0, 14.0, 0.0]),
             pinch=([2.5, y, 0.0], [20.0, y, 0.0], 8.0))
    b = _set(2.5, 0.4, [9.0, 13.0, 0.0], far=([5.0, 17.0, 0.0], [17.0, 5.0, 0.0]),
             close=([11.0, 6.0, 0.0], [11.0, 12.25, 0.0]), slide=([16.0, 17.0, 0.0], [6.0, 6.0, 0.0]),
             pinch=([11.0, 3.0, 0.0], [11.0, 19.5, 0.0], 9.0))
    return [*a, *_held_out(b)]


def _taxel() -> list[Case]:
    y = 30.0
    a = _set(10.0, 1.5, [30.0, y, 0.0], far=([12.0, 12.0, 0.0], [48.0, 48.0, 0.0]),
             close=([17.5, y, 0.0], [42.5, y, 0.0]), slide=([10.0, 20.0, 0.0], [50.0, 40.0, 0.0]),
             pinch=([8.0, y, 0.0], [52.0, y, 0.0], 16.0))
    b = _set(8.0, 1.0, [22.0, 37.0, 0.0], far=([10.0, 48.0, 0.0], [48.0, 12.0, 0.0]),
             close=([36.0, 16.0, 0.0], [36.0, 36.0, 0.0]), slide=([50.0, 50.0, 0.0], [14.0, 30.0, 0.0]),
             pinch=([30.0, 6.0, 0.0], [30.0, 54.0, 0.0], 26.0))
    return [*a, *_held_out(b)]


def _barrel() -> list[Case]:
    # A: the +x, -y side (the twin's default view), azimuth -25 degrees at radius ~53 mm mid-height;
    # B: the +y side (azimuth 90 degrees) and -x
    side = [48.0, -22.4]
    a = _set(12.0, 4.0, [*side, 130.0], far=([*side, 90.0], [-48.0, 22.4, 150.0]),
             close=([*side, 115.0], [*side, 145.0]), slide=([17.9, -49.1, 80.0], [17.9, -49.1, 180.0]),
             pinch=([0.0, -50.0, 75.0], [0.0, -50.0, 185.0], 40.0))
    a += [Case("near", (_press([40.0, -18.6, 55.0], 12.0, 4.0),), PRESSED, 12.0),
          Case("far", (_press([-48.0, 22.4, 130.0], 12.0, 4.0),), PRESSED, 12.0)]
    b = _set(14.0, 5.0, [0.0, 53.0, 130.0], far=([0.0, 53.0, 85.0], [-53.0, 0.0, 175.0]),
             close=([0.0, 53.0, 113.0], [0.0, 53.0, 148.0]),
             slide=([-37.5, 37.5, 170.0], [-37.5, 37.5, 80.0]),
             pinch=([-50.0, 0.0, 70.0], [-50.0, 0.0, 190.0], 50.0))
    b += [Case("near", (_press([0.0, 45.0, 210.0], 14.0, 5.0),), PRESSED, 14.0),
          Case("far", (_press([-40.0, -35.0, 130.0], 14.0, 5.0),), PRESSED, 14.0)]
    return [*a, *_held_out(b)]


CASES: dict[str, list[Case]] = {"pad": _pad(), "taxel": _taxel(), "barrel": _barrel()}
"""Cases by skin; each family plays the cases of its skin (families.py)."""
