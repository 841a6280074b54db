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

The noise of a frame is a window, at an offset drawn from the caller's
generator, of one bank of standard normal values made once per frame size
(twice the frame, fixed seed): within a frame every pixel's noise is an
independent Gaussian draw, and two frames share a noise field only when their
offsets coincide (1 in H x W). Drawing a frame of Gaussian values was the most
expensive step of a simulated camera at rest (~1.2 ms of 1.3 for 640 x 480);
a window and one fused OpenCV pass cost ~0.1 ms.
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
    """``picture`` (float32, left unchanged) with sensor noise of ``noise_std`` grey levels, as uint8.

    Rounded half to even and saturated to 0..255, as ``np.clip(np.rint(...))`` would.
    """
    picture = np.ascontiguousarray(picture, dtype=np.float32)  # OpenCV's layout
    if not (noise_std and noise_std > 0):
        image: np.ndarray = np.clip(np.rint(picture), 0, 255).astype(np.uint8)
        return image
    import cv2

    rng = rng if rng is not None else np.random.default_rng()
    n = picture.size
    offset = int(rng.integers(n + 1))
    noise = _noise_bank(n)[offset:offset + n].reshape(picture.shape)
    exposed: np.ndarray = cv2.addWeighted(picture, 1.0, noise, float(noise_std), 0.0, dtype=cv2.CV_8U)
    return exposed


_NOISE_BANK_SEED = 0x5E_4509
_noise_banks: dict[int, np.ndarray] = {}


def _noise_bank(n: int) -> np.ndarray:
    """2n standard normal float32 values for frames of n pixels, made on first use (a race makes
    the same values twice: harmless)."""
    bank = _noise_banks.get(n)
    if bank is None:
        rng = np.random.default_rng(_NOISE_BANK_SEED)
        bank = _noise_banks[n] = rng.standard_normal(2 * n, dtype=np.float32)
    return bank
