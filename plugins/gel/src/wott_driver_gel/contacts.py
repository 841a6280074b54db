"""Contacts of a marker-less gel: colour change against the rest reference, segmented.

Per frame: the smoothed frame's colour change from the reference (``rest.change``), less its
low-frequency part when anything changed (``drift_free``: the LEDs warming up or the exposure moving
between the rest reference and now tint the whole image smoothly, a contact changes a small patch
sharply); pixels above a threshold (``min_change`` grey levels, or ``noise_k`` times the reference's own noise
when that is larger: a noisy camera raises its own bar) form a mask, opened to drop specks;
its connected components, the fragments of one contact joined (``join``: components whose gap is
under ``join_k`` times the larger one's radius: a press whose change dips below the threshold across
its rim splits into arcs), of at least ``min_area_mm2`` are contacts. A component's

- **centre** is the centroid of the pixels inside it weighted by their change above the
  threshold: the colour change of a pressed gel is strongest on the slopes of the dent and
  symmetric about its axis, so the weighted centroid sits on the axis, and it does not jump when
  an edge pixel crosses the threshold (it enters with weight 0; the mask's own centroid jumps),
  nor is it pulled far by a wide weak rim;
- **radius** is that of the disc with the area where the change exceeds ``radius_fraction`` of
  the component's peak (its 99th percentile: one pixel's maximum is noise), the contact edge of a
  ball press, found against Taxim's hand-labelled radii (``wott-hub bench gel``, docs/gel.md).

Positions are pixel (x = column, y = row) here; the driver turns them into mm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .rest import RestReference, change, smooth

__all__ = ["ContactParams", "PixelContact", "drift_free", "find_contacts", "threshold"]


@dataclass(frozen=True, slots=True)
class ContactParams:
    min_change: float = 8.0  # grey levels
    noise_k: float = 4.0  # x the reference's noise
    min_area_px: float = 400.0
    radius_fraction: float = 0.3
    open_px: int = 5  # the opening's square size, px
    sigma_px: float = 2.0
    drift_sigma_px: float = 0.0  # the low-frequency part's Gaussian, px (0: none)
    drift_iters: int = 3
    join_k: float = 0.5
    peak_pct: float = 99.0  # the component's peak for ``radius_fraction``: this percentile of its change


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


def drift_free(d: np.ndarray, thr: float, sigma_px: float, iters: int, down: int = 4) -> np.ndarray:
    """``d`` (H, W[, C] signed change) less its low-frequency part, fitted where there is no contact.

    The low part is a normalized convolution (a Gaussian of ``sigma_px`` over the pixels counted as
    background, divided by the same over their weights), at 1/``down`` scale (it is smooth, and a
    quarter scale costs a sixteenth); after each pass the pixels still changed by ``thr`` or more, grown
    by 5 small pixels, are left out of the next, so the contact's own change is not subtracted from it
    (a plain high-pass would: the contact would shrink and its rim break)."""
    import cv2

    h, w = d.shape[:2]
    small = np.asarray(cv2.resize(d, (max(w // down, 1), max(h // down, 1)), interpolation=cv2.INTER_AREA))
    if small.ndim == 2:
        small = small[..., None]
    s = sigma_px / down
    wgt = np.ones(small.shape[:2], np.float32)
    low = np.zeros_like(small)
    grow = np.ones((5, 5), np.uint8)
    for _ in range(iters):
        num = np.asarray(cv2.GaussianBlur(small * wgt[..., None], (0, 0), s)).reshape(small.shape)
        den = np.asarray(cv2.GaussianBlur(wgt, (0, 0), s))
        low = num / np.maximum(den, 1e-3)[..., None]
        r = small - low
        still = np.sqrt((r * r).sum(axis=-1)) >= thr
        wgt = 1.0 - cv2.dilate(still.astype(np.uint8), grow).astype(np.float32)
    up = np.asarray(cv2.resize(low, (w, h), interpolation=cv2.INTER_LINEAR)).reshape(h, w, -1)
    out: np.ndarray = (d - up.reshape(d.shape)).astype(np.float32)
    return out


def join(labels: np.ndarray, n: int, stats: np.ndarray, k: float) -> np.ndarray:
    """Labels with the fragments of one contact under one label: components ``i``, ``j`` whose gap (the
    least distance between their pixels) is under ``k`` times the larger one's radius ``sqrt(area/pi)``
    (transitively). Few components, so one distance transform each."""
    import cv2

    if n <= 2 or k <= 0:
        return labels
    radius = np.sqrt(stats[:, cv2.CC_STAT_AREA] / np.pi)
    parent = list(range(n))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i in range(1, n):
        dist = cv2.distanceTransform((labels != i).astype(np.uint8), cv2.DIST_L2, 3)
        for j in range(i + 1, n):
            gap = float(dist[labels == j].min())
            if gap < k * max(radius[i], radius[j]):
                parent[root(j)] = root(i)
    lut = np.array([root(i) for i in range(n)], dtype=labels.dtype)
    joined: np.ndarray = lut[labels]
    return joined


def find_contacts(image: np.ndarray, ref: RestReference, p: ContactParams, *, smoothed: bool = False,
                  ignore: np.ndarray | None = None) -> tuple[list[PixelContact], np.ndarray]:
    """The contacts of ``image`` against ``ref`` (see module doc), and the change magnitude (H, W).
    ``smoothed``: ``image`` is already ``rest.smooth``ed by ``p.sigma_px``; ``ignore`` (H, W) bool: pixels
    whose change is not contact (a marker gel's dots, ``markers.MarkerField.dots``)."""
    import cv2

    frame = image if smoothed else smooth(image, p.sigma_px)
    mag = change(frame, ref.image)
    if ignore is not None:
        mag[ignore] = 0.0
    thr = threshold(ref, p)
    mask: np.ndarray = (mag > thr).astype(np.uint8)
    if not mask.any():  # the gel at rest, most frames: nothing to segment
        return [], mag
    if p.drift_sigma_px > 0:
        d = drift_free(frame - ref.image, thr, p.drift_sigma_px, p.drift_iters)
        mag = np.sqrt((d * d).sum(axis=-1)) if d.ndim == 3 else np.abs(d)
        if ignore is not None:
            mag[ignore] = 0.0
        mask = (mag > thr).astype(np.uint8)
        if not mask.any():
            return [], mag
    if p.open_px > 1:
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, np.ones((p.open_px, p.open_px), np.uint8))
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    labels = join(labels, n, stats, p.join_k)
    out: list[PixelContact] = []
    for i in np.unique(labels[labels > 0]):
        ys, xs = np.nonzero(labels == i)
        area = int(ys.size)
        if area < p.min_area_px:
            continue
        wts = mag[ys, xs].astype(np.float64)
        peak = float(wts.max())
        above = wts - thr  # a pixel crossing the threshold enters with weight 0: no jump
        cx = float(xs @ above) / float(above.sum())
        cy = float(ys @ above) / float(above.sum())
        top = peak if p.peak_pct >= 100 else float(np.percentile(wts, p.peak_pct))
        core = int(np.count_nonzero(wts > p.radius_fraction * top))
        rad = float(np.sqrt(core / np.pi))
        out.append(PixelContact(cx, cy, rad, peak, area))
    out.sort(key=lambda c: (c.y, c.x))
    return out, mag
