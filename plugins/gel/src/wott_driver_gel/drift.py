"""The illumination drift of a gel's colour change: its low-frequency part, fitted where there is no contact.

LEDs warming up or the exposure moving between the rest reference and now tint the whole image smoothly
(per region and per channel); a contact changes a small patch sharply. The drift is a normalized
convolution (a Gaussian of ``sigma_px`` over the pixels counted as background, divided by the same over
their weights) at 1/``down`` scale: it is smooth, and a quarter scale costs a sixteenth. After each pass
the pixels still changed by ``thr`` or more, grown by 5 small pixels, are left out of the next, so the
contact's own change is not subtracted from it (a plain high-pass would: the contact would shrink and its
rim break). A pass that leaves out the same pixels as the one before would give the same low part again:
the passes stop there.

The small image is held as planes (channel, row, column) and each pass's Gaussian is two matrix products
(``Gaussian_rows @ plane @ Gaussian_cols.T``, the reflected border folded into the matrices): on a few
thousand samples and a kernel half as wide as the image, that is half ``cv2.sepFilter2D``'s time, and the
division by the weights, the norm and the weighting run on whole planes. Its result equals
``rest.blur``'s (the same kernel, the same border) to float rounding (1e-6 of the change).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

__all__ = ["drift", "drift_free", "gaussian_matrix", "upsample"]


@lru_cache(maxsize=16)
def gaussian_matrix(n: int, sigma_px: float) -> np.ndarray:
    """(n, n) float32: row i holds the weights ``rest.blur``'s Gaussian (``GaussianBlur``'s float kernel,
    4 sigma either side) gives the n samples of a line at sample i, the border reflected (OpenCV's
    ``BORDER_REFLECT_101``, folded as often as the kernel outreaches the line). Read-only."""
    from .rest import gaussian_kernel

    k = gaussian_kernel(sigma_px).ravel().astype(np.float64)
    r = len(k) // 2
    m = np.zeros((n, n))
    for t in range(-r, r + 1):
        j = np.arange(n) + t
        if n == 1:
            j[:] = 0
        while ((j < 0) | (j >= n)).any():
            j = np.where(j < 0, -j, np.where(j >= n, 2 * (n - 1) - j, j))
        np.add.at(m, (np.arange(n), j), k[t + r])
    out: np.ndarray = m.astype(np.float32)
    out.setflags(write=False)
    return out


def drift(d: np.ndarray, thr: float, sigma_px: float, iters: int, down: int = 4) -> np.ndarray:
    """The low-frequency part of ``d`` (H, W[, C] signed change), (H/down, W/down, C) (module doc)."""
    import cv2

    h, w = d.shape[:2]
    small = np.asarray(cv2.resize(d, (max(w // down, 1), max(h // down, 1)), interpolation=cv2.INTER_AREA),
                       dtype=np.float32)
    if small.ndim == 2:
        small = small[..., None]
    hs, ws, c = small.shape
    planes = np.ascontiguousarray(small.transpose(2, 0, 1))  # (C, hs, ws)
    s = sigma_px / down
    gr, gc = gaussian_matrix(hs, s), gaussian_matrix(ws, s).T

    def blurred(x: np.ndarray) -> np.ndarray:
        out: np.ndarray = np.matmul(np.matmul(gr, x), gc)
        return out

    # the first pass weighs every pixel 1: its weights' blur is the matrices' row sums' product
    den = np.maximum(np.outer(gr.sum(axis=1), gc.sum(axis=0)), 1e-3).astype(np.float32)
    num = blurred(planes)
    grow = np.ones((5, 5), np.uint8)
    low: np.ndarray = np.zeros_like(planes)
    left_out: np.ndarray | None = None
    for k in range(iters):
        low = num / den
        if k == iters - 1:  # no pass follows to leave pixels out of
            break
        r = planes - low
        still = (np.sqrt((r * r).sum(axis=0)) >= thr).view(np.uint8)
        out_now = np.asarray(cv2.dilate(still, grow))
        if left_out is not None and np.array_equal(out_now, left_out):
            break
        left_out = out_now
        keep = (out_now == 0).astype(np.float32)
        num = blurred(planes * keep)
        den = np.maximum(blurred(keep), 1e-3)
    out: np.ndarray = np.ascontiguousarray(low.transpose(1, 2, 0))
    return out


def drift_free(d: np.ndarray, thr: float, sigma_px: float, iters: int, down: int = 4) -> np.ndarray:
    """``d`` (H, W[, C] signed change) less its low-frequency part (``drift``)."""
    low = drift(d, thr, sigma_px, iters, down)
    h, w = d.shape[:2]
    out: np.ndarray = np.subtract(d, upsample(low, (h, w), (0, h, 0, w)).reshape(d.shape), dtype=np.float32)
    return out


def upsample(low: np.ndarray, shape: tuple[int, int], box: tuple[int, int, int, int]) -> np.ndarray:
    """Rows ``y0:y1``, columns ``x0:x1`` (``box``) of ``low`` (h, w, C) resized to ``shape`` (bilinear),
    (y1 - y0, x1 - x0, C). When ``shape`` is a whole multiple of ``low``'s, only the part of ``low`` under
    the box (and one small pixel around it) is resized: the same values, for the box's cost."""
    import cv2

    h, w = shape
    hs, ws, c = low.shape
    y0, y1, x0, x1 = box
    if h % hs or w % ws or h // hs != w // ws:
        part, a0, b0 = low, 0, 0
        size = (w, h)
    else:
        k = h // hs
        a0, a1 = max(y0 // k - 1, 0), min(-(-y1 // k) + 1, hs)
        b0, b1 = max(x0 // k - 1, 0), min(-(-x1 // k) + 1, ws)
        part, size = low[a0:a1, b0:b1], ((b1 - b0) * k, (a1 - a0) * k)
        a0, b0 = a0 * k, b0 * k
    up = np.asarray(cv2.resize(np.ascontiguousarray(part if c > 1 else part[..., 0]), size,
                               interpolation=cv2.INTER_LINEAR)).reshape(size[1], size[0], c)
    out: np.ndarray = up[y0 - a0:y1 - a0, x0 - b0:x1 - b0]
    return out
