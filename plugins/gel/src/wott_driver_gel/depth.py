"""Depth of a marker-less gel by photometric stereo: colour change -> surface gradient -> depth map.

**Calibration** (``calibrate``; ``wott-hub calibrate`` writes its result): the standard GelSight
ball-press method. A ball of known radius ``R`` pressed into the gel leaves a spherical dent whose
slope is known at every pixel of the contact circle (centre ``c``, radius ``r``, both in the frame):
the indentation ``D = sqrt(R² - |p - c|²) - sqrt(R² - r²)`` has gradient ``-(p - c) / sqrt(R² - |p - c|²)``.
Each press pixel's colour change from the background (B, G, R, blurred) is binned in a 3-D table;
a bin keeps the mean gradient (gx, gy) of its pixels. Pixels far from the contact teach the table that
no change is no slope. Bins no pixel fell in take a least-squares quadratic fit of the gradient on the
colour change (so the table answers everywhere, smoothly). Saved as ``.npz``.

**Depth** (``DepthCalibration.depth``): each pixel's colour change looked up in the table (below the
contact threshold: no slope, so the flat gel integrates to zero), the gradients integrated by solving
Poisson's equation ``∇²D = ∂gx/∂x + ∂gy/∂y`` with ``D = 0`` on the view's border, by the type-I
discrete sine transform (``scipy.fft.dstn``: exact for that boundary, O(n log n)), on a frame reduced
``scale`` times (the depth is smooth; a 640 x 480 frame is solved at 160 x 120).

**Force** (``normal_force``): an estimate, not a measurement. The gel as an elastic (Winkler) foundation:
each area element pushed ``D`` deep pushes back ``E D / h`` (Young's modulus E of the gel's material,
thickness h), so the normal force is ``E / h ∫ D dA`` over the contact (docs/gel.md, "Force").
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["BINS", "RANGE", "DepthCalibration", "calibrate", "normal_force", "poisson"]

BINS = 64
RANGE = 128.0  # grey levels: colour changes beyond +-RANGE fall in the outer bins
_FORMAT = 1


def _bin(diff: np.ndarray) -> np.ndarray:
    """Bin indices (..., 3) of colour changes (..., 3)."""
    idx = np.floor((diff + RANGE) * (BINS / (2 * RANGE))).astype(np.int64)
    out: np.ndarray = np.clip(idx, 0, BINS - 1)
    return out


def _features(diff: np.ndarray) -> np.ndarray:
    """Quadratic features (N, 10) of colour changes (N, 3), scaled to about 1."""
    b, g, r = (diff / RANGE).T
    return np.column_stack([np.ones_like(b), b, g, r, b * b, g * g, r * r, b * g, b * r, g * r])


def poisson(gx: np.ndarray, gy: np.ndarray) -> np.ndarray:
    """The surface D (H, W) whose gradient is closest to (gx, gy), D = 0 on the border (DST-I)."""
    from scipy.fft import dstn, idstn

    div = np.zeros_like(gx, dtype=np.float64)
    div[:, 1:] += gx[:, 1:] - gx[:, :-1]
    div[1:, :] += gy[1:, :] - gy[:-1, :]
    inner = div[1:-1, 1:-1]
    h, w = inner.shape
    kx = 2.0 * np.cos(np.pi * np.arange(1, w + 1) / (w + 1)) - 2.0
    ky = 2.0 * np.cos(np.pi * np.arange(1, h + 1) / (h + 1)) - 2.0
    solved = idstn(dstn(inner, type=1) / (kx[None, :] + ky[:, None]), type=1)
    out = np.zeros_like(div)
    out[1:-1, 1:-1] = solved
    return out


@dataclass(frozen=True, slots=True, eq=False)
class DepthCalibration:
    """A colour-change -> gradient table (``lut`` BINS³ x 2) for frames at ``mm_per_px``."""

    lut: np.ndarray
    mm_per_px: float
    ball_radius_mm: float
    presses: int
    scale: int = 4
    sigma_px: float = 2.0

    def save(self, path: str | Path) -> None:
        np.savez_compressed(path, format=_FORMAT, lut=self.lut.astype(np.float32), mm_per_px=self.mm_per_px,
                            ball_radius_mm=self.ball_radius_mm, presses=self.presses, scale=self.scale,
                            sigma_px=self.sigma_px)

    @classmethod
    def load(cls, path: str | Path) -> DepthCalibration:
        """A saved calibration; ``ValueError`` naming what is wrong with the file."""
        try:
            with np.load(path, allow_pickle=False) as f:
                fmt = int(f["format"])
                lut = np.asarray(f["lut"], dtype=np.float32)
                out = cls(lut, float(f["mm_per_px"]), float(f["ball_radius_mm"]), int(f["presses"]),
                          int(f["scale"]), float(f["sigma_px"]))
        except (KeyError, OSError, EOFError, ValueError, TypeError) as e:
            raise ValueError(f"{path}: not a depth calibration written by `wott-hub calibrate` ({e})"
                             ) from None
        if fmt != _FORMAT:
            raise ValueError(f"{path}: calibration format {fmt}, expected {_FORMAT}")
        if out.lut.shape != (BINS, BINS, BINS, 2) or not np.isfinite(out.lut).all():
            raise ValueError(f"{path}: its table has shape {out.lut.shape}, expected {(BINS,) * 3 + (2,)}")
        return out

    def gradients(self, diff: np.ndarray, moving: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(gx, gy) of colour changes ``diff`` (H, W, 3); 0 where ``moving`` is false."""
        i = _bin(diff)
        g = self.lut[i[..., 0], i[..., 1], i[..., 2]]
        g[~moving] = 0.0
        return g[..., 0], g[..., 1]

    def depth(self, frame_s: np.ndarray, ref_s: np.ndarray, threshold: float) -> np.ndarray:
        """The indentation (mm, H/scale x W/scale) of a smoothed frame against the smoothed reference."""
        s = self.scale
        h, w = frame_s.shape[:2]
        diff = (frame_s - ref_s)[: h - h % s, : w - w % s]
        small = diff.reshape(h // s, s, w // s, s, 3).mean(axis=(1, 3))
        moving = np.sqrt(np.einsum("ijk,ijk->ij", small, small)) > threshold
        gx, gy = self.gradients(small, moving)
        d: np.ndarray = np.maximum(poisson(gx, gy), 0.0) * (s * self.mm_per_px)  # slopes x pixel pitch
        return d


def calibrate(background: np.ndarray, presses: np.ndarray, centres_px: np.ndarray, radii_px: np.ndarray, *,
              ball_radius_mm: float, mm_per_px: float, sigma_px: float = 2.0, scale: int = 4,
              inner: float = 0.95) -> DepthCalibration:
    """The table from a background and ball presses of radius ``ball_radius_mm`` (see module doc).

    ``centres_px`` (K, 2) are (x = column, y = row), ``radii_px`` (K,) the contact circles' radii.
    ``inner``: only pixels within that fraction of the circle are taken (its edge is the least sure).
    """
    from .rest import smooth

    if len(presses) == 0 or len(presses) != len(centres_px) or len(presses) != len(radii_px):
        raise ValueError("calibrate needs presses, each with a centre and a radius")
    R = ball_radius_mm / mm_per_px  # noqa: N806 - the ball's radius, px
    if not (radii_px < R).all():
        raise ValueError(f"a contact radius is not smaller than the ball's ({ball_radius_mm} mm = "
                         f"{R:.0f} px)")
    ref = smooth(background, sigma_px)
    h, w = background.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    diffs, grads = [], []
    rng = np.random.default_rng(0)
    for img, (cx, cy), r in zip(presses, centres_px, radii_px, strict=True):
        diff = smooth(img, sigma_px) - ref
        dx, dy = xx - cx, yy - cy
        d2 = dx * dx + dy * dy
        inside = d2 < (inner * r) ** 2
        root = np.sqrt(R * R - d2[inside])
        diffs.append(diff[inside])
        grads.append(np.column_stack([-dx[inside] / root, -dy[inside] / root]))
        far = np.flatnonzero((d2 > (3.0 * r) ** 2).ravel())
        take = rng.choice(far, min(len(far), int(inside.sum())), replace=False)
        diffs.append(diff.reshape(-1, 3)[take])
        grads.append(np.zeros((len(take), 2)))
    diff_all, grad_all = np.concatenate(diffs), np.concatenate(grads)
    fit, *_ = np.linalg.lstsq(_features(diff_all), grad_all, rcond=None)
    b = np.arange(BINS)
    centres = (b + 0.5) * (2 * RANGE / BINS) - RANGE
    grid = np.stack(np.meshgrid(centres, centres, centres, indexing="ij"), axis=-1).reshape(-1, 3)
    lut = (_features(grid) @ fit).reshape(BINS, BINS, BINS, 2)
    idx = _bin(diff_all)
    flat = np.ravel_multi_index((idx[:, 0], idx[:, 1], idx[:, 2]), (BINS,) * 3)
    count = np.bincount(flat, minlength=BINS**3)
    seen = count >= 3
    for k in range(2):
        mean = np.bincount(flat, weights=grad_all[:, k], minlength=BINS**3) / np.maximum(count, 1)
        lut_k = lut[..., k].reshape(-1)
        lut_k[seen] = mean[seen]
        lut[..., k] = lut_k.reshape((BINS,) * 3)
    return DepthCalibration(lut.astype(np.float32), mm_per_px, ball_radius_mm, len(presses), scale, sigma_px)


def normal_force(depth_mm: np.ndarray, pixel_mm: float, modulus_mpa: float, thickness_mm: float) -> float:
    """The Winkler estimate of the normal force (N) of a depth map (mm) whose pixels are ``pixel_mm``
    wide: ``E / h`` x the indented volume (see module doc)."""
    return float(modulus_mpa / thickness_mm * depth_mm.sum() * pixel_mm * pixel_mm)
