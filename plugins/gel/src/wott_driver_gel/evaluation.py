"""Real GelSight presses as recordings, and how far the driver's contacts are from their labels.

The ``taxim`` wheel (MIT; a test and benchmark dependency only, imported here when asked) ships
Taxim's calibration sets: ``gelsight_mini`` (one background and 24 hand-labelled ball presses of a
GelSight Mini, 480 x 640, 0.0295 mm/px) and ``gelsight`` (an older GelSight, 48 presses). A set is
written as a folder of PNG frames (lossless: the frames the driver reads are the wheel's bytes): the
background ``rest`` times, then each press followed by the background, so every press is a contact
of its own. ``wott-hub bench gel`` and the tests read the driver's contacts against the labels here.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["PressSet", "dent_depth", "load_taxim", "write_recording"]


@dataclass(frozen=True, slots=True, eq=False)
class PressSet:
    background: np.ndarray  # (H, W, 3) uint8 BGR
    presses: np.ndarray  # (K, H, W, 3) uint8 BGR
    centres_px: np.ndarray  # (K, 2) x = column, y = row
    radii_px: np.ndarray  # (K,)
    mm_per_px: float


def load_taxim(which: str = "gelsight_mini") -> PressSet:
    """One of Taxim's sets (``gelsight_mini`` or ``gelsight``)."""
    import json
    from importlib import resources

    root = resources.files("taxim") / "calib" / which
    with resources.as_file(root / "dataPack.npz") as path:
        data = np.load(path, allow_pickle=False)
        bg, imgs = np.asarray(data["f0"]), np.asarray(data["imgs"])
        centres, radii = data["touch_center"].astype(float), data["touch_radius"].astype(float)
    scale = 0.0295
    params = root / "params.json"
    if params.is_file():
        scale = float(json.loads(params.read_text())["sensor"]["pixmm"])
    return PressSet(bg, imgs, centres, radii, scale)


def write_recording(folder: Path, background: np.ndarray, presses: np.ndarray, *, rest: int = 5,
                    between: int = 1, suffix: str = ".png") -> list[int]:
    """The frames as numbered images in ``folder`` (PNG, or ``suffix``'s format: ``.jpg`` at quality 95):
    ``rest`` backgrounds, then each press and ``between`` backgrounds. Returns each press's frame index."""
    import cv2

    folder.mkdir(parents=True, exist_ok=True)
    frames: list[np.ndarray] = [background] * rest
    at = []
    for p in presses:
        at.append(len(frames))
        frames.append(p)
        frames.extend([background] * between)
    params = [cv2.IMWRITE_JPEG_QUALITY, 95] if suffix == ".jpg" else []
    for k, f in enumerate(frames):
        cv2.imwrite(str(folder / f"{k:05d}{suffix}"), f, params)
    return at


def dent_depth(depth_mm: np.ndarray, centre_px: np.ndarray, radius_px: float, scale: int
               ) -> tuple[float, float]:
    """(depth at the centre, depth of the dent below its contact edge), mm, of a depth map at 1/``scale``.

    A ball's geometry fixes the second (``R - sqrt(R² - r²)`` for a contact of radius r): the gel around
    the contact sinks too (an elastic solid is no bed of springs), which the first includes."""
    h, w = depth_mm.shape
    cx, cy = centre_px / scale
    i, j = min(max(int(round(cy)), 0), h - 1), min(max(int(round(cx)), 0), w - 1)
    centre = float(depth_mm[max(i - 1, 0):i + 2, max(j - 1, 0):j + 2].max())
    t = np.linspace(0.0, 2 * np.pi, 64, endpoint=False)
    r = radius_px / scale
    ys = np.clip(np.rint(cy + r * np.sin(t)).astype(int), 0, h - 1)
    xs = np.clip(np.rint(cx + r * np.cos(t)).astype(int), 0, w - 1)
    return centre, centre - float(depth_mm[ys, xs].mean())
