"""``wott-hub calibrate gelsight-mini|digit DATA -o OUT``: the depth calibration from ball presses.

DATA is a ``.npz`` laid out as Taxim's calibration packs (``dataPack.npz``): ``f0`` the background
(H, W, 3 uint8 BGR, the gel at rest), ``imgs`` the presses (K, H, W, 3), ``touch_center`` (K, 2: x =
column, y = row, px) and ``touch_radius`` (K, px) the contact circles as labelled. Options:
``ball_diameter_mm`` (required: the pressing ball's diameter; Taxim's README: "a small sphere (~4mm)"),
``mm_per_px`` (default the family's scale for frames of that width, docs/gel.md). Frames must be of
the size the device will process (a calibration refuses a device at another scale).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wott_hub.plugin_api import SettingsError

from .depth import calibrate
from .specs import default_mm_per_px

__all__ = ["OPTIONS", "calibrate_file"]

OPTIONS = ("ball_diameter_mm", "mm_per_px")


def _number(options: dict[str, str], key: str, default: float | None) -> float:
    if key not in options:
        if default is None:
            raise SettingsError(f"--option {key}=...: required (e.g. {key}=4)")
        return default
    try:
        value = float(options[key])
    except ValueError:
        raise SettingsError(f"--option {key}: a number, got {options[key]!r}") from None
    if not (np.isfinite(value) and 0 < value <= 100):
        raise SettingsError(f"--option {key}: must be in (0, 100], got {options[key]!r}")
    return value


def calibrate_file(family: str, data: str, out: str, options: dict[str, str]) -> str:
    unknown = sorted(set(options) - set(OPTIONS))
    if unknown:
        raise SettingsError(f"--option {unknown[0]}: unknown; the options are {', '.join(OPTIONS)}")
    ball = _number(options, "ball_diameter_mm", None)
    try:
        with np.load(data, allow_pickle=False) as f:
            bg, imgs = np.asarray(f["f0"]), np.asarray(f["imgs"])
            centres, radii = np.asarray(f["touch_center"], float), np.asarray(f["touch_radius"], float)
    except (OSError, ValueError, KeyError, EOFError) as e:
        raise SettingsError(f"data {data!r}: not a ball-press pack (f0, imgs, touch_center, touch_radius): "
                            f"{e}") from None
    if bg.ndim != 3 or imgs.shape[1:] != bg.shape or centres.shape != (len(imgs), 2) or radii.shape != (
            len(imgs),):
        raise SettingsError(f"data {data!r}: f0 {bg.shape}, imgs {imgs.shape}, touch_center {centres.shape} "
                            f"and touch_radius {radii.shape} do not agree")
    mm_per_px = _number(options, "mm_per_px", default_mm_per_px(family, bg.shape[1]))
    try:
        cal = calibrate(bg, imgs, centres, radii, ball_radius_mm=ball / 2, mm_per_px=mm_per_px)
    except ValueError as e:
        raise SettingsError(f"data {data!r}: {e}") from None
    try:
        cal.save(out)
    except OSError as e:
        raise SettingsError(f"--out {out!r}: {e.strerror or e}") from None
    size = Path(out).stat().st_size if Path(out).exists() else 0
    return (f"wrote {out} ({size // 1024} KiB): {family} depth from {len(imgs)} presses of a {ball:g} mm "
            f"ball at {mm_per_px:g} mm/px on {bg.shape[1]}x{bg.shape[0]} frames; use it as "
            f"calibration = {out!r}")
