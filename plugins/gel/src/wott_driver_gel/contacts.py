"""Contacts of a marker-less gel: colour change against the rest reference, segmented.

Per frame: the smoothed frame's colour change from the reference (``rest.change``), less its
low-frequency part when anything changed (``drift.py``: the LEDs warming up or the exposure moving
between the rest reference and now tint the whole image smoothly, a contact changes a small patch
sharply); pixels above a threshold (``min_change`` grey levels, or ``noise_k`` times the reference's own noise
when that is larger: a noisy camera raises its own bar) form a mask, opened to drop specks;
its connected components, the fragments of one contact joined (``join``: components whose gap is
under ``join_k`` times the larger one's radius: a press whose change dips below the threshold across
its rim splits into arcs), of at least ``min_area_mm2``, that stand out from the gel around them are
contacts: a component's peak change is at least ``contrast_k`` times the change in a ring about it
(1.5 to 2.5 of its radii out, its 90th percentile). A ball or
a finger dents the gel locally: the ring around a real press barely changes (its peak is 13-90 times
the ring's in Taxim's sets and the modelled DIGIT presses down to 0.05 mm deep; 4 for the faintest
press the threshold still finds), while a change spread over the whole gel (the older GelSight set's
frames carry streaks all over the pad, light changes the drift model leaves) passes the threshold in
patches that are no stronger than their surroundings (1.3-2.2). A component's

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

from .drift import drift, drift_free, upsample
from .rest import RestReference, magnitude, smooth

__all__ = ["ContactParams", "PixelContact", "components", "drift", "drift_free", "find_contacts",
           "load_labelling", "threshold", "upsample"]


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
    contrast_k: float = 3.0  # its peak over the change around it (0: no such test)


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


def percentile(a: np.ndarray, q: float) -> float:
    """``np.percentile(a, q)`` (its default, linear interpolation, to the last bit) of a 1-D float64 array,
    from one partition around the two ranks it needs: a tenth of numpy's time on a contact's pixels."""
    at = q / 100.0 * (a.size - 1)
    lo = int(np.floor(at))
    hi = min(lo + 1, a.size - 1)
    part = np.partition(a, [lo, hi])
    x, y, t = float(part[lo]), float(part[hi]), at - lo
    return y - (y - x) * (1.0 - t) if t >= 0.5 else x + (y - x) * t


_EIGHT = np.ones((3, 3), dtype=bool)
"""8-connectivity, as ``cv2.connectedComponents``' default."""


def load_labelling() -> None:
    """Import what ``components`` needs (``scipy.ndimage``: 0.2-0.5 s the first time), so that a driver
    does it before its first frame (``GelDriver``'s ``prepare``) and not at the first touch, which it
    would hold up that long."""
    from scipy import ndimage  # noqa: F401


def components(mask: np.ndarray) -> tuple[int, np.ndarray, np.ndarray]:
    """``cv2.connectedComponentsWithStats(mask, connectivity=8)`` without its centroids: (n labels, the
    (H, W) int32 labels, (n, 5) int32 ``CC_STAT_LEFT``, ``TOP``, ``WIDTH``, ``HEIGHT``, ``AREA``), by
    ``scipy.ndimage`` (label 0: the background, its area and the whole mask's box; not used here).

    Why not OpenCV's: with more than one thread (its default) OpenCV labels in parallel, and its pool's
    thread then spins for about 0.7 ms after each call waiting for more work: 0.7 ms of a core for a
    labelling of 0.1 ms, on every touched frame (3-4 % of a core for a Mini and a DIGIT together, the
    OpenCV thread a hub showed; docs/gel.md, "What a frame costs"). ``scipy.ndimage.label`` runs in the
    calling thread, in 0.1 ms too. The components are the same pixels; their numbering may differ where
    several components share a mask (OpenCV numbers them by 2 x 2 blocks), which nothing here depends on:
    a contact's pixels, centre and radius do not (``join`` groups by a symmetric gap, the contacts are
    sorted by position)."""
    from scipy import ndimage

    labels, count = ndimage.label(mask, structure=_EIGHT, output=np.int32)
    n = int(count) + 1
    stats = np.empty((n, 5), dtype=np.int32)
    stats[:, 4] = np.bincount(labels.ravel(), minlength=n)
    stats[0, :4] = 0, 0, mask.shape[1], mask.shape[0]
    for i, (rows, cols) in enumerate(ndimage.find_objects(labels), 1):
        stats[i, :4] = cols.start, rows.start, cols.stop - cols.start, rows.stop - rows.start
    return n, labels, stats


def join(labels: np.ndarray, n: int, stats: np.ndarray, k: float) -> np.ndarray:
    """The label (n,) each of the ``n`` labels goes under, the fragments of one contact under one:
    components ``i``, ``j`` whose gap (the least distance between their pixels) is under ``k`` times the
    larger one's radius ``sqrt(area/pi)`` (transitively). Few components, so one distance transform each."""
    import cv2

    if n <= 2 or k <= 0:
        return np.arange(n)
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
    lut: np.ndarray = np.array([root(i) for i in range(n)])
    return lut


def surround(mag: np.ndarray, x: float, y: float, r: float) -> float:
    """The change around a component centred at (``x``, ``y``) of radius ``r`` px: the 90th percentile over
    the ring from 1.5 r to 2.5 r, sampled on a grid of about r/8 px (~1,500 pixels whatever the size); 0
    where the ring is off the view. Another contact inside the ring counts as surroundings: two presses
    closer than their radii (and not joined as one) can hide the weaker one (docs/gel.md)."""
    h, w = mag.shape
    step = max(1, int(r / 8))
    y0, y1 = max(int(y - 2.5 * r), 0), min(int(y + 2.5 * r) + 1, h)
    x0, x1 = max(int(x - 2.5 * r), 0), min(int(x + 2.5 * r) + 1, w)
    yy, xx = np.mgrid[y0:y1:step, x0:x1:step]
    d2 = (yy - y) ** 2 + (xx - x) ** 2
    ring = mag[y0:y1:step, x0:x1:step][(d2 >= (1.5 * r) ** 2) & (d2 <= (2.5 * r) ** 2)]
    return float(np.percentile(ring, 90)) if ring.size else 0.0


def find_contacts(image: np.ndarray, ref: RestReference, p: ContactParams, *, smoothed: bool = False,
                  ignore: np.ndarray | None = None) -> tuple[list[PixelContact], np.ndarray]:
    """The contacts of ``image`` against ``ref`` (see module doc), and the change magnitude (H, W).
    ``smoothed``: ``image`` is already ``rest.smooth``ed by ``p.sigma_px``; ``ignore`` (H, W) bool: pixels
    whose change is not contact (a marker gel's dots, ``markers.MarkerField.dots``).

    The frame-wide work is one subtraction and one norm per step; the segmentation (opening aside) and
    each component's centre and radius are computed inside bounding boxes: the changed pixels' box for
    the connected components, each component's own box for its reductions (a contact covers a small
    part of the view)."""
    import cv2

    frame = image if smoothed else smooth(image, p.sigma_px)
    d = cv2.subtract(frame, ref.image) if frame.dtype == ref.image.dtype else frame - ref.image
    mag = magnitude(d)
    if ignore is not None:
        mag[ignore] = 0.0
    thr = threshold(ref, p)
    if not float(mag.max()) > thr:  # the gel at rest, most frames: nothing to segment
        return [], mag
    h, w = mag.shape
    y0, y1, x0, x1 = 0, h, 0, w  # the box outside which nothing passes the threshold
    if p.drift_sigma_px > 0:
        low = drift(d, thr, p.drift_sigma_px, p.drift_iters)
        # |d - low| <= |d| + max |low| (the resized low part is a convex mix of its samples): only pixels
        # changed by more than thr - max |low| can be contact, so the drift is taken out in their box
        x0, y0, bw, bh = cv2.boundingRect((mag > thr - float(magnitude(low).max())).view(np.uint8))
        if bw == 0:
            return [], mag
        y1, x1 = y0 + bh, x0 + bw
        up = upsample(low, (h, w), (y0, y1, x0, x1)).reshape(d[y0:y1, x0:x1].shape)
        mag[y0:y1, x0:x1] = magnitude(np.subtract(d[y0:y1, x0:x1], up))
        if ignore is not None:
            mag[ignore] = 0.0
    # the mask in that box and a margin of the opening's size (zeros: the full frame's opening near the box)
    m = p.open_px if p.open_px > 1 else 0
    y0, y1, x0, x1 = max(y0 - m, 0), min(y1 + m, h), max(x0 - m, 0), min(x1 + m, w)
    mask: np.ndarray = (mag[y0:y1, x0:x1] > thr).view(np.uint8)  # 1 where changed
    if p.open_px > 1:
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, np.ones((p.open_px, p.open_px), np.uint8))
    bx, by, bw, bh = cv2.boundingRect(mask)
    if bw == 0:
        return [], mag
    mask = mask[by:by + bh, bx:bx + bw]
    y0, x0 = y0 + by, x0 + bx
    n, labels, stats = components(mask)
    lut = join(labels, n, stats, p.join_k)
    if not np.array_equal(lut, np.arange(n)):
        labels = lut.astype(labels.dtype)[labels]
    box = mag[y0:y0 + bh, x0:x0 + bw]
    out: list[PixelContact] = []
    for i in np.unique(lut[1:]):
        parts = np.flatnonzero(lut == i)
        cx0 = int(stats[parts, cv2.CC_STAT_LEFT].min())
        cy0 = int(stats[parts, cv2.CC_STAT_TOP].min())
        cx1 = int((stats[parts, cv2.CC_STAT_LEFT] + stats[parts, cv2.CC_STAT_WIDTH]).max())
        cy1 = int((stats[parts, cv2.CC_STAT_TOP] + stats[parts, cv2.CC_STAT_HEIGHT]).max())
        ys, xs = np.nonzero(labels[cy0:cy1, cx0:cx1] == i)
        area = int(ys.size)
        if area < p.min_area_px:
            continue
        wts = box[cy0:cy1, cx0:cx1][ys, xs].astype(np.float64)
        xs, ys = xs + (x0 + cx0), ys + (y0 + cy0)
        peak = float(wts.max())
        if p.contrast_k > 0 and peak < p.contrast_k * surround(mag, float(xs.mean()), float(ys.mean()),
                                                               float(np.sqrt(area / np.pi))):
            continue
        above = wts - thr  # a pixel crossing the threshold enters with weight 0: no jump
        cx = float(xs @ above) / float(above.sum())
        cy = float(ys @ above) / float(above.sum())
        top = peak if p.peak_pct >= 100 else percentile(wts, p.peak_pct)
        core = int(np.count_nonzero(wts > p.radius_fraction * top))
        rad = float(np.sqrt(core / np.pi))
        out.append(PixelContact(cx, cy, rad, peak, area))
    out.sort(key=lambda c: (c.y, c.x))
    return out, mag
