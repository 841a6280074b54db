"""The rest reference of a marker-less gel: the median of its first frames at rest.

A gel at rest looks the same from frame to frame up to the camera's noise; a frame that
differs from the one before by more than ``max_change`` (grey levels, the 99.9th percentile
of the per-pixel colour change after a light blur) means something touches or moves, and the
frames collected so far are thrown away: a reference taken under a finger would report it as
rest forever. Once ``frames`` consecutive frames agree, their per-pixel median is the
reference (a median, not a mean: one frame's flicker does not move it) and their scatter about
it is the noise the contact threshold scales with (``RestReference.noise``).

cv2 is imported in the functions (``wott_vision``'s rule: importing the plugin loads no cv2).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from wott_hub.plugin_api import InvalidInput

__all__ = ["NoRestFrame", "RestCollector", "RestReference", "blur", "change", "gaussian_kernel", "magnitude",
           "smooth"]


class NoRestFrame(InvalidInput):
    """No rest reference (yet): the message says why (health shows it as it is)."""


def smooth(image: np.ndarray, sigma_px: float) -> np.ndarray:
    """``image`` as float32, Gaussian-blurred by ``sigma_px`` (the camera's noise and JPEG blocks out).
    A camera's uint8 frame goes straight into the filter (no float copy of it is made first)."""
    f = np.asarray(image)
    if f.dtype != np.uint8:
        f = f.astype(np.float32)
    if sigma_px <= 0:
        return f.astype(np.float32)
    return blur(f, sigma_px)


def blur(image: np.ndarray, sigma_px: float) -> np.ndarray:
    """``image`` (uint8 or float32, any channels) Gaussian-blurred by ``sigma_px``, as float32.

    ``cv2.GaussianBlur``'s kernel for float images (4 sigma either side, the border reflected) applied
    as one separable filter: the same result (to 1e-5 grey levels) in half ``GaussianBlur``'s time on
    float images, a quarter on a uint8 frame (``GaussianBlur`` would need it converted first)."""
    import cv2

    k = gaussian_kernel(float(sigma_px))
    out: np.ndarray = cv2.sepFilter2D(image, cv2.CV_32F, k, k, borderType=cv2.BORDER_REFLECT_101)
    return out


@lru_cache(maxsize=8)
def gaussian_kernel(sigma_px: float) -> np.ndarray:
    """(size, 1) float32: ``GaussianBlur``'s kernel for float images (4 sigma either side)."""
    import cv2

    size = int(round(sigma_px * 8 + 1)) | 1
    k: np.ndarray = cv2.getGaussianKernel(size, sigma_px, cv2.CV_32F)
    return k


def change(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per-pixel colour change ``|a - b|`` (the norm over the channels) of two smoothed frames."""
    import cv2

    return magnitude(cv2.subtract(a, b) if a.dtype == b.dtype else a - b)


def magnitude(d: np.ndarray) -> np.ndarray:
    """The norm over the channels (H, W) of a signed change ``d`` (H, W[, C] float32)."""
    import cv2

    if d.ndim == 2:
        absolute: np.ndarray = np.abs(d)
        return absolute
    # the channels' squares summed by one matrix product per pixel: a fifth of numpy's einsum's time
    out: np.ndarray = cv2.sqrt(cv2.transform(cv2.multiply(d, d), _ONES[: d.shape[2]].reshape(1, -1)))
    return out


_ONES = np.ones(4, dtype=np.float32)


@dataclass(frozen=True, slots=True, eq=False)
class RestReference:
    image: np.ndarray  # (H, W[, 3]) float32, smoothed
    noise: float  # grey levels: the rest frames' typical colour change about the median (0: one frame)
    raw: np.ndarray  # (H, W[, 3]) uint8, the median as the camera gave it (calibration, markers)


class RestCollector:
    """Frames in, a ``RestReference`` out once ``frames`` consecutive ones agree (see module doc)."""

    def __init__(self, frames: int = 5, max_change: float = 10.0, sigma_px: float = 2.0) -> None:
        if frames < 1:
            raise ValueError(f"rest frames must be >= 1, got {frames}")
        self.frames, self.max_change, self.sigma_px = frames, max_change, sigma_px
        self._raw: list[np.ndarray] = []
        self._last: np.ndarray | None = None

    def reset(self) -> None:
        self._raw, self._last = [], None

    def add(self, image: np.ndarray) -> RestReference:
        """Take one frame; the reference once enough agree, else ``NoRestFrame`` with the reason."""
        img = np.asarray(image)
        s = smooth(img, self.sigma_px)
        if self._last is not None:
            if self._last.shape != s.shape:
                self.reset()
            else:
                moved = float(np.percentile(change(s, self._last), 99.9))
                if moved > self.max_change:
                    self._raw, self._last = [img], s
                    raise NoRestFrame(f"no rest frame yet: the image changed by {moved:.1f} grey levels "
                                      f"between frames (at rest: at most {self.max_change:g}); is the gel "
                                      "touched?")
        self._raw.append(img)
        self._last = s
        if len(self._raw) < self.frames:
            raise NoRestFrame(f"no rest frame yet: {len(self._raw)} of {self.frames} frames at rest")
        stack = np.stack(self._raw)
        median = np.median(stack, axis=0)
        raw = np.clip(np.rint(median), 0, 255).astype(np.uint8)
        ref = smooth(median, self.sigma_px)
        noise = 0.0
        if len(self._raw) > 1:
            noise = float(np.median([np.percentile(change(smooth(f, self.sigma_px), ref), 99.0)
                                     for f in self._raw]))
        self.reset()
        return RestReference(ref, noise, raw)
