"""Marker blobs, bright on a dark skin or dark on a lit gel: where are they, to a fraction of a pixel?

``polarity`` says which: ``"bright"`` (the barrel's white dots on black, the default) or
``"dark"`` (a GelSight Mini marker gel's black dots on its lit surface, issue 44). A dark
marker is found as a bright one in the inverted image, so everything below holds for both.

One global threshold, connected components, then an intensity-weighted
centroid per component. Two details make this work on real skins:

- The threshold is Otsu's, floored a little above the median (the skin), so a
  frame with no markers does not turn noise into blobs, and it adapts to
  exposure changes from frame to frame.
- Far markers seen at a grazing angle are packed a pixel or two apart, and at
  Otsu's level neighbours merge into one blob. A second, higher level
  (half-way between the threshold and the markers' brightness) splits a blob
  into its bright cores when it holds two or more of them; a blob with one
  core (nearly all of them) keeps its own, larger, support. That is a
  two-level component tree, the cheap end of MSER.

The weight of a pixel is its brightness above the level that segmented it, so
it falls to zero at the blob's edge: the centroid does not jump when one edge
pixel crosses the threshold, which is what makes it sub-pixel.

cv2 is imported inside the functions (see ``wott_vision``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["MarkerDetector", "as_gray", "auto_threshold", "detect_markers"]

MIN_CONTRAST = 20  # grey levels above the median skin a marker must reach
CENTROIDS = ("weighted", "binary")
POLARITIES = ("bright", "dark")
SPLIT_CORE_FRACTION = 0.15  # of the blob's area, for a core to count as a marker of its own


def _histogram(gray: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
    import cv2

    return cv2.calcHist([gray], [0], mask, [256], [0, 256]).ravel()


def _otsu(hist: np.ndarray) -> float:
    """Otsu's level from a 256-bin histogram (the level maximising between-class variance)."""
    p = hist / max(hist.sum(), 1.0)
    levels = np.arange(256, dtype=np.float64)
    w0 = np.cumsum(p)
    m0 = np.cumsum(p * levels)
    mt = m0[-1]
    w1 = 1.0 - w0
    with np.errstate(divide="ignore", invalid="ignore"):
        between = (mt * w0 - m0) ** 2 / (w0 * w1)
    between[~np.isfinite(between)] = 0.0
    return float(np.argmax(between))


def _percentile(hist: np.ndarray, q: float, start: int = 0) -> float:
    h = hist[start:]
    total = h.sum()
    if total <= 0:
        return float(start)
    return float(start + np.searchsorted(np.cumsum(h), q * total))


def _level(hist: np.ndarray) -> int:
    return int(max(_otsu(hist), _percentile(hist, 0.5) + MIN_CONTRAST))


def auto_threshold(gray: np.ndarray, mask: np.ndarray | None = None) -> int:
    """Otsu's level, but at least ``MIN_CONTRAST`` above the median grey (the skin)."""
    return _level(_histogram(gray, mask))


def as_gray(gray: np.ndarray) -> np.ndarray:
    """A frame as the contiguous (H, W) uint8 image the detector takes.

    BGR / BGRA (OpenCV's camera frames) become grey; other dtypes are clipped to 0..255
    (floats all within 0..1 are scaled by 255 first); anything else is a ValueError.
    """
    g = np.asarray(gray)
    if g.ndim == 3 and g.shape[2] in (3, 4):
        import cv2

        g = cv2.cvtColor(g, cv2.COLOR_BGR2GRAY if g.shape[2] == 3 else cv2.COLOR_BGRA2GRAY)
    if g.ndim != 2:
        raise ValueError(f"expected a grey image (H, W), got shape {g.shape}")
    if g.dtype != np.uint8:
        if np.issubdtype(g.dtype, np.floating) and np.nanmax(g, initial=0.0) <= 1.0:
            g = g * 255.0
        g = np.clip(np.nan_to_num(g), 0, 255).astype(np.uint8)
    return np.ascontiguousarray(g)


@dataclass
class MarkerDetector:
    """A configured detector; call it on grey frames. Reuse it: the ROI is computed once.

    After a call, ``areas`` holds each returned blob's size in pixels (a blob
    much larger than its marker usually is two markers pressed together).

    ``mask`` (H, W), non-zero where markers may be, also crops the search to its
    bounding box, which is where the ROI variant gets its speed. ``downscale=2``
    detects on a half-size image (faster, coarser, merges the smallest markers). ``polarity``
    ``"dark"`` finds dark dots (see the module doc).
    """

    min_area: float = 4
    max_area: float = 2000
    threshold: int | None = None
    mask: np.ndarray | None = None
    centroid: str = "weighted"
    split: bool = True
    downscale: int = 1
    polarity: str = "bright"
    areas: np.ndarray = field(default_factory=lambda: np.empty(0), init=False, repr=False)
    _roi: tuple[int, int, int, int] | None = field(default=None, init=False, repr=False)
    _mask_roi: np.ndarray | None = field(default=None, init=False, repr=False)
    _mask_shape: tuple[int, ...] = field(default=(), init=False, repr=False)

    def __post_init__(self) -> None:
        if self.centroid not in CENTROIDS:
            raise ValueError(f"centroid must be one of {CENTROIDS}, got {self.centroid!r}")
        if self.polarity not in POLARITIES:
            raise ValueError(f"polarity must be one of {POLARITIES}, got {self.polarity!r}")
        if self.downscale not in (1, 2, 4):
            raise ValueError(f"downscale must be 1, 2 or 4, got {self.downscale!r}")
        if not 0 < self.min_area <= self.max_area:
            raise ValueError(f"need 0 < min_area <= max_area, got {self.min_area}, {self.max_area}")
        if self.threshold is not None and not 0 <= int(self.threshold) < 255:
            raise ValueError(f"threshold must be in [0, 254], got {self.threshold}")
        if self.mask is not None:
            m = np.asarray(self.mask)
            if m.ndim != 2:
                raise ValueError(f"mask must be (H, W), got shape {m.shape}")
            ys, xs = np.nonzero(m)
            if len(xs) == 0:
                raise ValueError("mask selects no pixel")
            x0, x1, y0, y1 = int(xs.min()), int(xs.max()) + 1, int(ys.min()), int(ys.max()) + 1
            self._roi = (x0, y0, x1, y1)
            self._mask_shape = m.shape
            self._mask_roi = np.ascontiguousarray((m[y0:y1, x0:x1] != 0).astype(np.uint8) * 255)

    def __call__(self, gray: np.ndarray) -> np.ndarray:
        g = as_gray(gray)
        if self.polarity == "dark":
            g = 255 - g  # a dark dot is a bright one in the negative
        x0 = y0 = 0
        mask = None
        if self._roi is not None:
            if self._mask_shape != g.shape:
                raise ValueError(f"mask shape {self._mask_shape} differs from image shape {g.shape}")
            x0, y0, x1, y1 = self._roi
            g = g[y0:y1, x0:x1]
            mask = self._mask_roi
        s = self.downscale
        if s > 1:
            import cv2

            h, w = g.shape
            g = cv2.resize(g, (w // s, h // s), interpolation=cv2.INTER_AREA)
            if mask is not None:
                mask = cv2.resize(mask, (w // s, h // s), interpolation=cv2.INTER_NEAREST)
        pts, area = _detect(g, mask, self.threshold, self.min_area / s**2, self.max_area / s**2,
                            self.centroid == "weighted", self.split)
        self.areas = area * s**2
        if s > 1:
            pts = (pts + 0.5) * s - 0.5  # pixel centres of the small image in full-size coordinates
        pts[:, 0] += x0
        pts[:, 1] += y0
        return pts


def detect_markers(
    gray: np.ndarray,
    *,
    min_area: float = 4,
    max_area: float = 2000,
    threshold: int | None = None,
    mask: np.ndarray | None = None,
    centroid: str = "weighted",
    split: bool = True,
    downscale: int = 1,
    polarity: str = "bright",
) -> np.ndarray:
    """Sub-pixel (x, y) centroids (K, 2) of the bright (``polarity="dark"``: dark) blobs of
    ``gray`` (H, W) uint8.

    Pixel (row i, column j) is centred on (x=j, y=i), as in OpenCV. ``threshold``
    None picks Otsu's level per frame; ``mask`` restricts the search. Blobs of
    fewer than ``min_area`` or more than ``max_area`` pixels are dropped.
    """
    return MarkerDetector(min_area, max_area, threshold, mask, centroid, split, downscale, polarity)(gray)


def _detect(g: np.ndarray, mask: np.ndarray | None, threshold: int | None, min_area: float,
            max_area: float, weighted: bool, split: bool) -> tuple[np.ndarray, np.ndarray]:
    """Work on the list of foreground pixels only (about a tenth of the frame).

    OpenCV's component statistics cost more than the labelling itself, so areas
    and centroids are sums over the foreground pixels (``np.bincount``), and the
    second level's nesting comes for free: a core's pixels all carry its blob's label.
    """
    import cv2

    hist = None
    if threshold is None:
        hist = _histogram(g, mask)
        t = _level(hist)
    else:
        t = int(threshold)
    _, fg = cv2.threshold(g, t, 1, cv2.THRESH_BINARY)
    if mask is not None:
        fg = cv2.bitwise_and(fg, fg, mask=mask)
    n, lab = cv2.connectedComponents(fg, connectivity=8, ltype=cv2.CV_32S)
    idx = np.flatnonzero(fg.view(bool))
    if n <= 1 or idx.size == 0:
        return np.empty((0, 2)), np.empty(0)
    label = lab.ravel()[idx]
    value = g.ravel()[idx]
    area = np.bincount(label, minlength=n)
    keep = (area >= min_area) & (area <= max_area)
    keep[0] = False
    weight = value.astype(np.float64) - t if weighted else np.ones(idx.size)

    total = n
    if split:
        if hist is None:
            hist = np.bincount(value, minlength=256).astype(np.float64)
        hi = _percentile(hist, 0.9, start=t + 1)  # the markers' typical brightness
        t2 = int(round(t + 0.5 * (hi - t)))
        core_px = value > t2
        if t < t2 < 255 and core_px.any():
            _, fg2 = cv2.threshold(g, t2, 1, cv2.THRESH_BINARY)
            fg2 = cv2.bitwise_and(fg2, fg)
            n2, lab2 = cv2.connectedComponents(fg2, connectivity=8, ltype=cv2.CV_32S)
            sub = lab2.ravel()[idx]  # 0 outside the cores
            parent = np.zeros(n2, dtype=np.int64)
            parent[sub[core_px]] = label[core_px]  # nested: all of a core's pixels agree
            area2 = np.bincount(sub, minlength=n2)
            # a core counts when it could be a marker on its own; speckle on a real
            # marker makes tiny cores, two merged markers make two big ones
            core = (area2 >= min_area) & (area2 <= max_area) & (area2 >= SPLIT_CORE_FRACTION * area[parent])
            core[0] = False
            split_parent = np.bincount(parent[core], minlength=n) >= 2
            split_parent[0] = False
            children = core & split_parent[parent]
            if children.any():
                keep &= ~split_parent
                in_split = split_parent[label]
                label = label.copy()
                label[in_split] = np.where(sub[in_split] > 0, n + sub[in_split], 0)
                if weighted:
                    weight[in_split] -= t2 - t
                keep = np.concatenate([keep, children])
                area = np.concatenate([area, area2])
                total = n + n2
    w_img = g.shape[1]
    ys, xs = np.divmod(idx, w_img)
    sw = np.bincount(label, weights=weight, minlength=total)
    sx = np.bincount(label, weights=weight * xs, minlength=total)
    sy = np.bincount(label, weights=weight * ys, minlength=total)
    sel = keep & (sw > 0)
    return np.column_stack([sx[sel] / sw[sel], sy[sel] / sw[sel]]), area[sel].astype(np.float64)
