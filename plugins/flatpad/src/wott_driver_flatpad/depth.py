"""Normal depth from apparent marker area (docs/flat-pad.md, "depth model").

A marker is a small patch of the gel surface, so its image area is the local
area scale of the camera mapping from the rest surface to the image. For a
pinhole (camera.py) with p = c + f·X / Z, that is, exactly,

    A / A_rest = det(∂p/∂X0) / det(∂p/∂X0)_rest = (Z0 / Z)² · (1 - X·∇ζ) · det F

with ζ = log(Z / Z0) (Z the effective distance, Z = Z0 + dz / n_gel), X the
marker's in-plane offset from the optical axis, and det F the in-plane area
stretch of the gel. The total brightness a marker adds over the background is
proportional to its image area whatever the blur, so a window sum around each
tracked marker measures A / A_rest.

Two of the three factors are depth. The third, det F, cannot be told apart
from depth by any image measurement at one marker: the marker field's own
image dilation contains the same product. We take the prior det F = 1 (no
in-plane stretch: exact for a press, a tap and a pinch of the indentation
model; wrong, and reported separately, under a shearing slide). Taking logs
and log(1 - a) ≈ -a gives one sparse linear system for ζ over the grid,

    2ζ + X·∇ζ = -log(A / A_rest),   ζ = 0 on the clamped border,

with ∇ as finite differences on the marker grid. It is solved directly (its
LU factors are computed once per layout); iterating it as a fixed point would
diverge off-axis, where the parallax term X·∇ζ outweighs 2ζ. The neglected
second-order term is put back by ``nonlinear_passes`` extra solves.

The depth model then maps x = Z / Z0 - 1 = e^ζ - 1 to dz. Ideally dz = n_gel·Z0·x;
``calibrate`` replaces that by a least-squares polynomial dz = Σ a_k x^k fitted
on simulated presses of known depth (absorbing what the image chain does to
areas: saturation, anti-aliasing, neighbours' light, grid-scale gradients),
and ``fit_depth_model`` does the same fit on any (x, dz) samples, e.g. presses
of a real pad on a calibrated stage.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .camera import PadOptics
from .geometry import PadLayout

__all__ = [
    "DepthModel",
    "MarkerPhotometry",
    "ParallaxSolver",
    "fill_lost",
    "fit_depth_model",
]


@dataclass(frozen=True, slots=True)
class DepthModel:
    """dz (mm, device z; negative into the gel) as a polynomial of x = Z / Z0 - 1."""

    coefficients: tuple[float, ...]  # a_1, a_2, ... (no constant: x = 0 at rest by construction)
    source: str = "physical"
    rmse_mm: float | None = None  # of the fit on its calibration samples
    samples: int = 0

    @classmethod
    def physical(cls, optics: PadOptics) -> DepthModel:
        return cls((optics.gel_n * optics.z_eff_mm,), "physical")

    def dz(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        out = np.zeros_like(x)
        for a in reversed(self.coefficients):
            out = (out + a) * x
        return out

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["coefficients"] = list(self.coefficients)
        return d

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> DepthModel:
        coeffs = tuple(float(a) for a in data["coefficients"])
        if not coeffs or not all(np.isfinite(coeffs)):
            raise ValueError(f"depth model coefficients must be finite numbers, got {data['coefficients']!r}")
        return cls(coeffs, str(data.get("source", "file")), data.get("rmse_mm"), int(data.get("samples", 0)))

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=2) + "\n")

    @classmethod
    def load(cls, path: str | Path) -> DepthModel:
        try:
            return cls.from_dict(json.loads(Path(path).read_text()))
        except (OSError, ValueError, KeyError, TypeError) as e:
            raise ValueError(f"cannot read depth model {path}: {e}") from e


def fit_depth_model(x: np.ndarray, dz: np.ndarray, degree: int = 3, source: str = "fit") -> DepthModel:
    """Least-squares dz ≈ Σ_{k=1..degree} a_k x^k over finite samples."""
    x = np.asarray(x, dtype=float).ravel()
    dz = np.asarray(dz, dtype=float).ravel()
    ok = np.isfinite(x) & np.isfinite(dz)
    x, dz = x[ok], dz[ok]
    if len(x) < 4 * degree or np.ptp(x) == 0:
        raise ValueError(f"need varied samples to fit a degree-{degree} depth model, got {len(x)}")
    basis = np.column_stack([x**k for k in range(1, degree + 1)])
    coeffs, *_ = np.linalg.lstsq(basis, dz, rcond=None)
    rmse = float(np.sqrt(np.mean((basis @ coeffs - dz) ** 2)))
    return DepthModel(tuple(float(a) for a in coeffs), source, rmse, int(len(x)))


class ParallaxSolver:
    """Solves 2ζ + X·∇ζ = -log(A / A_rest) on the marker grid, ζ = 0 at clamped markers.

    The matrix depends only on the layout, so it is factorised once; a frame
    costs one sparse triangular solve per pass.
    """

    def __init__(self, layout: PadLayout, parallax: bool = True) -> None:
        import scipy.sparse as sp
        from scipy.sparse.linalg import splu

        self.layout = layout
        self.parallax = parallax
        n = layout.n_markers
        gx, gy = _grid_gradient(layout)
        x = layout.mesh.nodes[:, :2] - layout.axis_mm
        self._gx, self._gy, self._x = gx, gy, x
        a = 2.0 * sp.identity(n, format="csr")
        if parallax:
            a = a + sp.diags(x[:, 0]) @ gx + sp.diags(x[:, 1]) @ gy
        self._fixed = ~layout.mesh.free
        a = a.tolil()
        for i in np.flatnonzero(self._fixed):
            a.rows[i], a.data[i] = [int(i)], [1.0]
        self._lu = splu(a.tocsc())

    def solve(self, log_ratio: np.ndarray, nonlinear_passes: int = 1) -> np.ndarray:
        """ζ = log(Z / Z0) per marker."""
        rhs = -np.asarray(log_ratio, dtype=float)
        rhs[self._fixed] = 0.0
        zeta: np.ndarray = self._lu.solve(rhs)
        if not self.parallax:
            return zeta
        for _ in range(nonlinear_passes):
            a = self._x[:, 0] * (self._gx @ zeta) + self._x[:, 1] * (self._gy @ zeta)
            a = np.clip(a, -0.5, 0.5)
            corr = a + np.log1p(-a)  # what log(1 - a) ≈ -a left out
            corr[self._fixed] = 0.0
            zeta = self._lu.solve(rhs + corr)
        return zeta


def _grid_gradient(layout: PadLayout) -> tuple[Any, Any]:  # scipy.sparse CSR matrices (SciPy ships no types)
    """Sparse d/dx and d/dy (1/mm) on the marker grid: central inside, one-sided on the border."""
    import scipy.sparse as sp

    r, c = np.divmod(np.arange(layout.n_markers), layout.cols)

    def along(pos: np.ndarray, size: int, stride: int) -> Any:
        lo = np.where(pos > 0, -stride, 0)
        hi = np.where(pos < size - 1, stride, 0)
        idx = np.arange(layout.n_markers)
        span = (hi - lo) / stride * layout.pitch_mm
        rows = np.concatenate([idx, idx])
        cols = np.concatenate([idx + hi, idx + lo])
        vals = np.concatenate([1.0 / span, -1.0 / span])
        return sp.csr_matrix((vals, (rows, cols)), shape=(layout.n_markers,) * 2)

    return along(c, layout.cols, 1), along(r, layout.rows, layout.cols)


def fill_lost(layout: PadLayout, values: np.ndarray, valid: np.ndarray, sweeps: int = 64) -> np.ndarray:
    """Replace invalid markers' values by the mean of their valid grid neighbours.

    Repeated until every hole is filled (a hole far from any valid marker takes
    as many sweeps as its distance); the valid values never change.
    """
    if valid.all():
        return values
    out = layout.grid(np.where(valid[:, None], values.reshape(len(values), -1), 0.0).copy())
    known = layout.grid(valid.copy())
    for _ in range(sweeps):
        if known.all():
            break
        acc = np.zeros_like(out)
        cnt = np.zeros(known.shape)
        for axis, shift in ((0, 1), (0, -1), (1, 1), (1, -1)):
            nb = np.roll(out, shift, axis=axis)
            nk = np.roll(known, shift, axis=axis).astype(float)
            edge: list[slice | int] = [slice(None)] * 2
            edge[axis] = 0 if shift == 1 else -1
            nk[tuple(edge)] = 0.0  # np.roll wraps around: the opposite border is no neighbour
            acc += nb * nk[..., None]
            cnt += nk
        grow = ~known & (cnt > 0)
        out[grow] = acc[grow] / cnt[grow][:, None]
        known = known | grow
    out[~known] = 0.0
    return out.reshape(values.shape)


class MarkerPhotometry:
    """Per-marker brightness above the background, summed over a square window.

    The background is the reference image with the markers removed by a
    median filter wider than a marker; its integral image is kept, so each
    frame costs one integral image and four look-ups per marker. Works for
    bright markers on a dark gel and for dark markers on a bright one (the
    polarity is read from the reference).
    """

    def __init__(self, reference: np.ndarray, reference_points: np.ndarray, half_px: int,
                 marker_diameter_px: float) -> None:
        import cv2  # camera path only

        self.half = int(half_px)
        k = int(2 * np.ceil(1.5 * marker_diameter_px) + 1)
        background = cv2.medianBlur(reference, min(k, 255) | 1)
        self._bg_integral = cv2.integral(background, sdepth=cv2.CV_64F)
        self.shape = reference.shape
        raw = self._window_sums(reference, reference_points, self._integral(reference))
        self.polarity = 1.0 if np.nansum(raw) >= 0 else -1.0
        self.reference = raw * self.polarity

    @staticmethod
    def _integral(gray: np.ndarray) -> np.ndarray:
        import cv2

        integral: np.ndarray = cv2.integral(gray, sdepth=cv2.CV_64F)
        return integral

    def _window_sums(self, gray: np.ndarray, points: np.ndarray, integral: np.ndarray) -> np.ndarray:
        h, w = self.shape
        ok = np.isfinite(points).all(axis=1)
        c = np.zeros((len(points), 2), dtype=np.int64)
        c[ok] = np.rint(points[ok]).astype(np.int64)
        x0 = np.clip(c[:, 0] - self.half, 0, w)
        x1 = np.clip(c[:, 0] + self.half + 1, 0, w)
        y0 = np.clip(c[:, 1] - self.half, 0, h)
        y1 = np.clip(c[:, 1] + self.half + 1, 0, h)

        def box(s: np.ndarray) -> np.ndarray:
            total: np.ndarray = s[y1, x1] - s[y0, x1] - s[y1, x0] + s[y0, x0]
            return total

        out: np.ndarray = box(integral) - box(self._bg_integral)
        out[~ok] = np.nan
        return out

    def area_ratio(self, gray: np.ndarray, points: np.ndarray) -> np.ndarray:
        """A / A_rest per marker (NaN for lost markers or a window with no marker light)."""
        s = self._window_sums(gray, points, self._integral(gray)) * self.polarity
        with np.errstate(divide="ignore", invalid="ignore"):
            r: np.ndarray = s / self.reference
        r[~(r > 0)] = np.nan
        return r
