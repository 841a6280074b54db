"""Contacts of a marker-less gel: colour change against the rest reference, segmented.

Per frame: the smoothed frame's colour change from the reference (``rest.change``); pixels
above a threshold (``min_change`` grey levels, or ``noise_k`` times the reference's own noise
when that is larger: a noisy camera raises its own bar) form a mask, opened to drop specks;
its connected components of at least ``min_area_mm2`` are contacts. A component's

- **centre** is the change-weighted centroid of the pixels inside it: the colour change of a
  pressed gel is strongest on the slopes of the dent and symmetric about its axis, so the
  weighted centroid sits on the axis, and it does not jump when an edge pixel crosses the
  threshold (the mask's own centroid does);
- **radius** is that of the disc with the area where the change exceeds ``radius_fraction`` of
  the component's peak (the contact edge of a ball press, found against Taxim's hand-labelled
  radii: ``wott-hub bench gel``, docs/gel.md).

Positions are pixel (x = column, y = row) here; the driver turns them into mm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .rest import RestReference, change, smooth

__all__ = ["ContactParams", "PixelContact", "find_contacts", "threshold"]


@dataclass(frozen=True, slots=True)
class ContactParams:
    min_change: float = 8.0  # grey levels
    noise_k: float = 4.0  # x the reference's noise
    min_area_px: float = 400.0
    radius_fraction: float = 0.3
    open_px: int = 5  # the opening's square size, px
    sigma_px: float = 2.0


@dataclass(frozen=True, slots=True)
class PixelContact:
    x: float  # px (column)
    y: float  # px (row)
    radius: float  # px
    peak: float  # grey levels, the largest change inside
    area: int  # px, the component's


def threshold(ref: RestReference, p: ContactParams) -> float:
    """The colour change that counts as contact against ``ref`` (grey levels)."""
    return max(p.min_change, p.noise_k * ref.noise)


def find_contacts(image: np.ndarray, ref: RestReference, p: ContactParams, *, smoothed: bool = False,
                  ignore: np.ndarray | None = None) -> tuple[list[PixelContact], np.ndarray]:
    """The contacts of ``image`` against ``ref`` (see module doc), and the change magnitude (H, W).
    ``smoothed``: ``image`` is already ``rest.smooth``ed by ``p.sigma_px``; ``ignore`` (H, W) bool: pixels
    whose change is not contact (a marker gel's dots, ``markers.MarkerField.dots``)."""
    import cv2

    mag = change(image if smoothed else smooth(image, p.sigma_px), ref.image)
    if ignore is not None:
        mag[ignore] = 0.0
    mask: np.ndarray = (mag > threshold(ref, p)).astype(np.uint8)
    if not mask.any():  # the gel at rest, most frames: nothing to segment
        return [], mag
    if p.open_px > 1:
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, np.ones((p.open_px, p.open_px), np.uint8))
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    out: list[PixelContact] = []
    for i in range(1, n):
        area = int(stats[i, cv2.CC_STAT_AREA])
        if area < p.min_area_px:
            continue
        x0, y0 = int(stats[i, cv2.CC_STAT_LEFT]), int(stats[i, cv2.CC_STAT_TOP])
        w, h = int(stats[i, cv2.CC_STAT_WIDTH]), int(stats[i, cv2.CC_STAT_HEIGHT])
        inside = labels[y0:y0 + h, x0:x0 + w] == i
        ys, xs = np.nonzero(inside)
        wts = mag[y0:y0 + h, x0:x0 + w][ys, xs].astype(np.float64)
        total = float(wts.sum())
        peak = float(wts.max())
        cx = x0 + float(xs @ wts) / total
        cy = y0 + float(ys @ wts) / total
        core = int(np.count_nonzero(wts > p.radius_fraction * peak))
        out.append(PixelContact(cx, cy, float(np.sqrt(core / np.pi)), peak, area))
    out.sort(key=lambda c: (c.y, c.x))
    return out, mag
