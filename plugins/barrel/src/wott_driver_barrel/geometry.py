"""Where the markers are on the TacLink barrel and how the two cameras see them.

Markers (docs/barrel-vision.md): 16 rings x 16 rays of printed dots, ring k
at height ``z_k = linspace(25, 235, 16)`` mm (inside the free band, z in
[21, 240]), ray j at azimuth ``j * 22.5`` degrees from the device x axis.
They sit on the skin, not on mesh nodes: each is the point where the
horizontal ray from the axis at (0, 0, z_k) towards azimuth j pierces the rest
mesh, held by that triangle's barycentric weights, so a marker moves with its
three nodes (``marker_displacement``) and the layout does not depend on how
the FE mesh happens to be meshed. Marker ``m = ring * 16 + ray``.

Cameras: equidistant fisheye (image radius ``r = f * theta``, theta the angle
from the optical axis), one on the axis below the bottom rim looking up (+z),
one above the top rim looking down (-z). With the defaults (f = 234 px,
6 mm beyond the rims, principal point at the image centre) both see all 256
markers in a 640x480 frame, the near ring at r = 220 px, the far ring at
41 px, like the real sensor's frames in ../shared/data/taclink/.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from wott_hub.plugin_api import SkinMesh

__all__ = ["BarrelLayout", "FisheyeCamera", "MarkerLayout", "default_cameras"]

RINGS = 16
RAYS = 16


@dataclass(frozen=True, eq=False)
class MarkerLayout:
    """Marker positions on a barrel mesh at rest, as barycentric points of its triangles."""

    mesh: SkinMesh
    rings: int = RINGS
    rays: int = RAYS
    z_range_mm: tuple[float, float] = (25.0, 235.0)
    radius_mm: float = 2.5  # printed dot radius

    def __post_init__(self) -> None:
        if self.mesh.cells.shape[1] != 3:
            raise ValueError("the barrel layout needs a triangle mesh")
        if self.rings < 1 or self.rays < 3:
            raise ValueError(f"need >= 1 ring and >= 3 rays, got {self.rings} x {self.rays}")

    @property
    def n_markers(self) -> int:
        return self.rings * self.rays

    @cached_property
    def ring_z(self) -> np.ndarray:
        return np.linspace(*self.z_range_mm, self.rings)

    @cached_property
    def ray_azimuth(self) -> np.ndarray:
        return np.arange(self.rays) * (2 * np.pi / self.rays)

    @cached_property
    def _hits(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(triangle nodes (M, 3), barycentric weights (M, 3), rest positions (M, 3))."""
        zz, aa = np.meshgrid(self.ring_z, self.ray_azimuth, indexing="ij")
        origin = np.column_stack([np.zeros(zz.size), np.zeros(zz.size), zz.ravel()])
        direction = np.column_stack([np.cos(aa.ravel()), np.sin(aa.ravel()), np.zeros(zz.size)])
        tri, bary, t = _ray_mesh(origin, direction, self.mesh.nodes, self.mesh.cells)
        missed = ~np.isfinite(t)
        if missed.any():
            m = int(np.argmax(missed))
            raise ValueError(f"marker {m} (z={zz.ravel()[m]:.1f} mm) does not lie on the mesh")
        return tri, bary, origin + t[:, None] * direction

    @property
    def triangles(self) -> np.ndarray:
        return self._hits[0]

    @property
    def weights(self) -> np.ndarray:
        return self._hits[1]

    @property
    def rest(self) -> np.ndarray:
        """Marker positions (M, 3) mm at rest."""
        rest: np.ndarray = self._hits[2]
        return rest

    @cached_property
    def normals(self) -> np.ndarray:
        n = np.einsum("mk,mkj->mj", self.weights, self.mesh.normals[self.triangles])
        unit: np.ndarray = n / np.linalg.norm(n, axis=1, keepdims=True)
        return unit

    @cached_property
    def tangents(self) -> tuple[np.ndarray, np.ndarray]:
        """Two unit tangents per marker: around the barrel and along it (in the surface)."""
        n = self.normals
        around = np.column_stack([-np.sin(self.ray_azimuth), np.cos(self.ray_azimuth),
                                  np.zeros(self.rays)])
        around = np.tile(around, (self.rings, 1))
        around -= np.einsum("ij,ij->i", around, n)[:, None] * n
        around /= np.linalg.norm(around, axis=1, keepdims=True)
        along = np.cross(n, around)
        return around, along

    def marker_displacement(self, displacement: np.ndarray) -> np.ndarray:
        """Marker displacement (M, 3) from node displacement (N, 3)."""
        moved: np.ndarray = np.einsum("mk,mkj->mj", self.weights, displacement[self.triangles])
        return moved

    def positions(self, displacement: np.ndarray | None = None) -> np.ndarray:
        if displacement is None:
            return self.rest
        moved: np.ndarray = self.rest + self.marker_displacement(displacement)
        return moved


def _ray_mesh(origin: np.ndarray, direction: np.ndarray, nodes: np.ndarray,
              cells: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """First hit of each ray on a triangle mesh (Moller-Trumbore, all rays x all triangles)."""
    a, b, c = nodes[cells[:, 0]], nodes[cells[:, 1]], nodes[cells[:, 2]]
    e1, e2 = b - a, c - a
    p = np.cross(direction[:, None, :], e2[None, :, :])  # (R, T, 3)
    det = np.einsum("tj,rtj->rt", e1, p)
    ok = np.abs(det) > 1e-12
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = origin[:, None, :] - a[None, :, :]
    u = np.einsum("rtj,rtj->rt", s, p) * inv
    q = np.cross(s, e1[None, :, :])
    v = np.einsum("rj,rtj->rt", direction, q) * inv
    t = np.einsum("tj,rtj->rt", e2, q) * inv
    eps = 1e-9
    hit = ok & (u >= -eps) & (v >= -eps) & (u + v <= 1 + eps) & (t > 0)
    t = np.where(hit, t, np.inf)
    best = np.argmin(t, axis=1)
    rows = np.arange(len(origin))
    tbest = t[rows, best]
    ub, vb = u[rows, best], v[rows, best]
    bary = np.column_stack([1 - ub - vb, ub, vb])
    return cells[best], np.clip(bary, 0.0, 1.0), tbest


@dataclass(frozen=True)
class FisheyeCamera:
    """Equidistant fisheye on the barrel's axis: r = f * theta around the principal point.

    ``looking_up`` True: at ``z_mm`` below the skin, optical axis +z, image x
    along device x and image y along device y. False: above, axis -z, image x
    along device x and image y along -y (both frames right-handed).
    """

    name: str
    z_mm: float
    looking_up: bool
    f_px: float = 234.0
    cx: float = 319.5
    cy: float = 239.5
    width: int = 640
    height: int = 480

    def __post_init__(self) -> None:
        if not (self.f_px > 0 and self.width > 0 and self.height > 0):
            raise ValueError(f"camera {self.name}: f_px, width and height must be positive")

    def _local(self, points: np.ndarray) -> np.ndarray:
        p = np.asarray(points, dtype=np.float64)
        x, y, z = p[..., 0], p[..., 1], p[..., 2] - self.z_mm
        if self.looking_up:
            return np.stack([x, y, z], axis=-1)
        return np.stack([x, -y, -z], axis=-1)

    def project(self, points: np.ndarray) -> np.ndarray:
        """Image (x, y) px of 3D points (..., 3) mm."""
        c = self._local(points)
        rho = np.hypot(c[..., 0], c[..., 1])
        theta = np.arctan2(rho, c[..., 2])
        scale = np.divide(self.f_px * theta, rho, out=np.zeros_like(rho), where=rho > 1e-12)
        return np.stack([self.cx + scale * c[..., 0], self.cy + scale * c[..., 1]], axis=-1)

    def visible(self, px: np.ndarray, margin: float = 0.0) -> np.ndarray:
        return ((px[..., 0] >= -margin) & (px[..., 0] <= self.width - 1 + margin)
                & (px[..., 1] >= -margin) & (px[..., 1] <= self.height - 1 + margin))


def default_cameras(height_mm: float = 260.0, *, offset_mm: float = 6.0, f_px: float = 234.0,
                    width: int = 640, height: int = 480) -> tuple[FisheyeCamera, FisheyeCamera]:
    cx, cy = (width - 1) / 2, (height - 1) / 2
    return (FisheyeCamera("bottom", -offset_mm, True, f_px, cx, cy, width, height),
            FisheyeCamera("top", height_mm + offset_mm, False, f_px, cx, cy, width, height))


@dataclass(frozen=True, eq=False)
class BarrelLayout:
    """The markers and the two cameras: what each camera sees for a given skin displacement."""

    markers: MarkerLayout
    cameras: tuple[FisheyeCamera, ...] = field(default_factory=default_cameras)
    min_radius_px: float = 1.4  # a dot never draws smaller than this (detectable, min_area 4)

    @property
    def mesh(self) -> SkinMesh:
        return self.markers.mesh

    @property
    def n_features(self) -> int:
        """Model input size: (x, y) displacement of every marker in every camera."""
        return len(self.cameras) * self.markers.n_markers * 2

    @cached_property
    def reference_px(self) -> tuple[np.ndarray, ...]:
        """Marker image positions (M, 2) at rest, one array per camera."""
        return tuple(cam.project(self.markers.rest) for cam in self.cameras)

    def image_points(self, displacement: np.ndarray | None = None) -> tuple[np.ndarray, ...]:
        pos = self.markers.positions(displacement)
        return tuple(cam.project(pos) for cam in self.cameras)

    def points_and_radii(
        self, displacement: np.ndarray | None = None
    ) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
        """(``image_points(displacement)``, apparent dot radii): what a simulator draws, per camera.

        A dot's radius (M,) px is r_mm * sqrt(|det J|) of the surface projection.
        """
        pos = self.markers.positions(displacement)
        around, along = self.markers.tangents
        h = 0.05
        points, radii = [], []
        for cam in self.cameras:
            p0 = cam.project(pos)
            j1 = (cam.project(pos + h * around) - p0) / h
            j2 = (cam.project(pos + h * along) - p0) / h
            det = np.abs(j1[:, 0] * j2[:, 1] - j1[:, 1] * j2[:, 0])
            points.append(p0)
            radii.append(np.maximum(self.markers.radius_mm * np.sqrt(det), self.min_radius_px))
        return tuple(points), tuple(radii)

    def jacobians(self, h: float = 0.05) -> tuple[np.ndarray, ...]:
        """d(image px)/d(marker position mm) at rest, (M, 2, 3) per camera."""
        rest = self.markers.rest
        out = []
        for cam in self.cameras:
            p0 = cam.project(rest)
            jac = np.zeros((len(rest), 2, 3))
            for k in range(3):
                step = np.zeros(3)
                step[k] = h
                jac[:, :, k] = (cam.project(rest + step) - p0) / h
            out.append(jac)
        return tuple(out)

    def stereo_maps(self, tangential_ratio: float = 0.2, noise_px: float = 0.05) -> np.ndarray:
        """(2, M, 2, 2): ``maps[a] @ motion in camera 1-a`` = the same marker's motion in camera a.

        The best linear guess of a marker's image motion in one camera from the
        other camera's view, when the marker is lost in one (merged with a
        neighbour) but seen in the other: a Gaussian prior on its 3D motion,
        mostly along the skin normal (tangential spread ``tangential_ratio`` of
        the normal one), observed through the other camera's Jacobian.
        """
        if len(self.cameras) != 2:
            raise ValueError("stereo maps need exactly two cameras")
        n = self.markers.normals
        prior = (1 - tangential_ratio**2) * n[:, :, None] * n[:, None, :] + tangential_ratio**2 * np.eye(3)
        jac = self.jacobians()
        maps = np.zeros((2, self.markers.n_markers, 2, 2))
        for a in (0, 1):
            ja, jb = jac[a], jac[1 - a]
            cov_b = jb @ prior @ jb.transpose(0, 2, 1) + noise_px**2 * np.eye(2)
            maps[a] = ja @ prior @ jb.transpose(0, 2, 1) @ np.linalg.inv(cov_b)
        return maps

    def features(self, displacement: np.ndarray) -> np.ndarray:
        """The exact model input for a node displacement (no detector in the loop): (n_features,)."""
        now = self.image_points(displacement)
        return np.concatenate([(p - r).ravel() for p, r in zip(now, self.reference_px, strict=True)])
