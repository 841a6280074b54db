"""Synthetic marker images, so simulators feed the real detector and tracker.

Each marker is a disc whose edge is anti-aliased analytically: a pixel's
coverage is ``clip(r + 0.5 - d, 0, 1)`` with ``d`` the distance from its centre
to the disc's centre, a one-pixel linear ramp that integrates to the disc's
area and keeps the drawn centroid on the true centre at any sub-pixel offset
(integer-snapped drawing, as ``cv2.circle`` without ``shift`` does, would
quantise the very motion the tracker measures). A Gaussian blur stands for the
lens, additive Gaussian noise for the sensor. Discs are accumulated as one
sparse sum (``np.bincount``), so 256 markers cost about a millisecond.

``marker_picture`` is the noiseless, blurred picture and ``expose`` adds the
sensor noise: a simulator whose skin is at rest draws its picture once and
exposes it on every frame, the same bytes ``render_markers`` would give.
"""

from __future__ import annotations

import numpy as np

__all__ = ["expose", "marker_picture", "render_markers"]


def render_markers(
    points: np.ndarray,
    radius_px: float | np.ndarray,
    size: tuple[int, int] = (480, 640),
    blur_sigma: float = 1.0,
    noise_std: float = 0.0,
    rng: np.random.Generator | None = None,
    *,
    intensity: float = 255.0,
    background: float = 0.0,
) -> np.ndarray:
    """A uint8 (H, W) image of white anti-aliased discs on black.

    ``points`` (M, 2) are (x, y) centres in pixels, pixel (row i, column j)
    centred on (x=j, y=i). Markers with a non-finite centre or a radius <= 0 are
    not drawn; overlapping discs saturate. ``noise_std`` is in grey levels.
    """
    picture = marker_picture(points, radius_px, size, blur_sigma, intensity=intensity, background=background)
    return expose(picture, noise_std, rng)


def marker_picture(
    points: np.ndarray,
    radius_px: float | np.ndarray,
    size: tuple[int, int] = (480, 640),
    blur_sigma: float = 1.0,
    *,
    intensity: float = 255.0,
    background: float = 0.0,
) -> np.ndarray:
    """The float32 (H, W) picture ``render_markers`` draws, before sensor noise and rounding."""
    h, w = (int(size[0]), int(size[1]))
    if h <= 0 or w <= 0:
        raise ValueError(f"size must be (H, W) > 0, got {size}")
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    radius = np.broadcast_to(np.asarray(radius_px, dtype=np.float64), (len(pts),))
    ok = np.isfinite(pts).all(axis=1) & np.isfinite(radius) & (radius > 0)
    # skip discs entirely outside the frame
    ok &= (pts[:, 0] + radius > -1) & (pts[:, 0] - radius < w) & (pts[:, 1] + radius > -1)
    ok &= pts[:, 1] - radius < h
    pts, radius = pts[ok], radius[ok]

    coverage: np.ndarray = np.zeros(h * w)
    if len(pts):
        half = np.ceil(radius + 1.0).astype(np.int64)
        flat_idx, flat_cov = [], []
        for hs in np.unique(half):  # one vectorised patch size per group
            sel = half == hs
            p, r = pts[sel], radius[sel]
            base = np.floor(p).astype(np.int64)
            off = np.arange(-hs, hs + 2)
            xs = base[:, 0, None] + off  # (n, L)
            ys = base[:, 1, None] + off
            dx2 = (xs - p[:, 0, None]) ** 2
            dy2 = (ys - p[:, 1, None]) ** 2
            d = np.sqrt(dy2[:, :, None] + dx2[:, None, :])  # (n, L, L)
            cov = np.clip(r[:, None, None] + 0.5 - d, 0.0, 1.0)
            inside = ((ys >= 0) & (ys < h))[:, :, None] & ((xs >= 0) & (xs < w))[:, None, :]
            keep = inside & (cov > 0)
            idx = ys[:, :, None] * w + xs[:, None, :]
            flat_idx.append(idx[keep])
            flat_cov.append(cov[keep])
        coverage = np.bincount(np.concatenate(flat_idx), weights=np.concatenate(flat_cov),
                               minlength=h * w)
        np.minimum(coverage, 1.0, out=coverage)
    img: np.ndarray = (background + (intensity - background) * coverage).reshape(h, w).astype(np.float32)
    if blur_sigma and blur_sigma > 0:
        import cv2

        img = cv2.GaussianBlur(img, (0, 0), sigmaX=float(blur_sigma), borderType=cv2.BORDER_REPLICATE)
    return img


def expose(picture: np.ndarray, noise_std: float = 0.0, rng: np.random.Generator | None = None) -> np.ndarray:
    """``picture`` (float32, left unchanged) with sensor noise of ``noise_std`` grey levels, as uint8."""
    img = picture
    if noise_std and noise_std > 0:
        import cv2

        # OpenCV's generator is 5x faster than NumPy's for a frame of noise; seeding it from
        # ``rng`` keeps a render reproducible (OpenCV's generator is per thread)
        rng = rng if rng is not None else np.random.default_rng()
        cv2.setRNGSeed(int(rng.integers(2**31 - 1)))
        noise = np.empty_like(picture)
        # OpenCV's stubs take only arrays for mean and stddev; it takes scalars as well
        cv2.randn(noise, 0.0, float(noise_std))  # type: ignore[call-overload]
        img = picture + noise
    image: np.ndarray = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    return image
