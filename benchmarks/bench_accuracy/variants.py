"""The processing settings compared, and one recording processed under one of them, timed.

A variant is a name and a function from the device's own processing settings (what
the hub would use, ``processing_params``) to the settings tried. The processor is
built as the hub builds it (tuned to what the driver declares, ``tune_processor``:
the camera skins' noise floor) and fed the recorded frames in order; each ``process`` call
is timed alone (``perf_counter``), so the time is the per-frame cost a hub pays.
A frame the processor refuses (``FrameError``) is left out of the score and counted.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace

from wott_hub.runtime.pipeline import tune_processor
from wott_hub.tactile import FrameError, FrameProcessor, FrameResult, ProcessingParams
from wott_hub.tactile.processing import processing_params

from .families import Recording
from .score import spacing_mm

__all__ = ["DEFAULT", "VARIANTS", "Variant", "processor", "run"]


@dataclass(frozen=True)
class Variant:
    name: str
    tweak: Callable[[ProcessingParams], ProcessingParams]


DEFAULT = Variant("default", lambda p: p)


def _set(name: str, **changes: object) -> Variant:
    return Variant(name, lambda p: replace(p, **changes))


def _act(name: str, **changes: object) -> Variant:
    return Variant(name, lambda p: replace(p, actions=replace(p.actions, **changes)))


VARIANTS: list[Variant] = [
    DEFAULT,
    _set("connected sets (segmentation before issue 31)", segmentation="components"),
    _set("no birth test", birth_noise=0.0),
    _set("birth 0.5 noise floor", birth_noise=0.5),
    _set("birth 2 noise floors", birth_noise=2.0),
    _set("birth 4 noise floors", birth_noise=4.0),
    _set("merge 1 noise floor, no ratio", merge_noise=1.0, merge_ratio=0.0),
    _set("merge 4 noise floors", merge_noise=4.0),
    _set("merge ratio 0.25", merge_ratio=0.25),
    Variant("no side-lobe test", lambda p: replace(p, side_lobe_ratio=0.0)),
    _set("track gate 1 mesh spacing", track_gate_mm=-1.0),
    _set("track gate 6 mesh spacings", track_gate_mm=-6.0),
    _act("speed window 0.1 s", speed_window_s=0.1),
    _act("speed window 0.4 s", speed_window_s=0.4),
    _act("no hold test (motion judged to the last frame)", hold_ratio=0.0),
]
"""The settings compared (``--variants``); a negative gate is in mesh spacings (resolved in ``run``)."""


def processor(rec: Recording, variant: Variant) -> FrameProcessor:
    """The processor the hub would make for ``rec``'s device, with ``variant``'s settings."""
    params = variant.tweak(processing_params(rec.description))
    gate = getattr(params, "track_gate_mm", None)  # absent before issue 31: the bench scores that code too
    if gate is not None and gate < 0:
        params = replace(params, track_gate_mm=-gate * spacing_mm(rec.description.mesh))
    proc = FrameProcessor(rec.description.mesh, params)
    tune_processor(proc, rec.driver)
    return proc


def run(rec: Recording, variant: Variant) -> tuple[list[int], list[FrameResult], list[float], int]:
    """(indices of the frames processed, their results, seconds per frame, frames refused)."""
    proc = processor(rec, variant)
    kept: list[int] = []
    results: list[FrameResult] = []
    times: list[float] = []
    refused = 0
    for k, frame in enumerate(rec.frames):
        t0 = time.perf_counter()
        try:
            res = proc.process(frame)
        except FrameError:
            refused += 1
            continue
        times.append(time.perf_counter() - t0)
        kept.append(k)
        results.append(res)
    return kept, results, times, refused
