"""The project's own optical model of a gel sensor: a ball pressed into a lit gel, as a camera sees it.

Used where no real contact frames may be shipped (the DIGIT: only its rest frame is public with a
licence that allows reuse, ``../shared/data/digit``): tests and benchmarks add modelled presses to the
real background. The gel's surface under a ball of radius ``R`` pressed ``d`` deep is the ball's cap
inside the contact circle (radius ``sqrt(2 R d - d²)``), smoothed by a Gaussian of ``skin_mm`` (the gel's
membrane does not follow a sharp edge). Three coloured lights graze the gel from three sides 120° apart,
as a DIGIT's and a Mini's LEDs do; a surface element of normal ``n`` reflects light ``c`` in proportion to
``n · l_c`` (Lambert), so a press changes each colour channel by ``gain (n · l_c - n0 · l_c)``: bright on
the slopes facing a light, dark on those facing away, zero on the flat. A model, not a measurement: its
colours are plausible, not the sensor's.
"""

from __future__ import annotations

import numpy as np

__all__ = ["LIGHTS", "press_depth", "press_image"]

_ELEVATION = np.radians(30.0)
LIGHTS = np.array([[np.cos(a) * np.cos(_ELEVATION), np.sin(a) * np.cos(_ELEVATION), np.sin(_ELEVATION)]
                   for a in np.radians([90.0, 210.0, 330.0])])
"""Unit vectors towards the blue, green and red lights (BGR order, OpenCV's channels)."""


def press_depth(shape: tuple[int, int], x: float, y: float, *, r_mm: float, depth_mm: float,
                mm_per_px: float, skin_mm: float = 0.15) -> np.ndarray:
    """The indentation (mm, >= 0) of a ball of radius ``r_mm`` pressed ``depth_mm`` deep at pixel (x, y)."""
    import cv2

    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w]
    d2 = ((xx - x) ** 2 + (yy - y) ** 2) * mm_per_px**2
    cap = np.sqrt(np.maximum(r_mm**2 - d2, 0.0)) - (r_mm - depth_mm)
    dent = np.maximum(cap, 0.0).astype(np.float32)
    out: np.ndarray = cv2.GaussianBlur(dent, (0, 0), skin_mm / mm_per_px)
    return out


def press_image(background: np.ndarray, x: float, y: float, *, r_mm: float, depth_mm: float,
                mm_per_px: float, gain: float = 140.0, noise: float = 1.0, seed: int = 0) -> np.ndarray:
    """``background`` (H, W, 3 uint8 BGR) with a modelled ball press at pixel (x, y) (see module doc)."""
    dent = press_depth(background.shape[:2], x, y, r_mm=r_mm, depth_mm=depth_mm, mm_per_px=mm_per_px)
    gy, gx = np.gradient(-dent, mm_per_px)  # the surface height falls into the dent
    norm = np.sqrt(1.0 + gx * gx + gy * gy)
    n = np.stack([-gx / norm, -gy / norm, 1.0 / norm], axis=-1)
    shade = n @ LIGHTS.T - LIGHTS[:, 2]  # n . l - n0 . l, per light
    rng = np.random.default_rng(seed)
    img = background.astype(np.float32) + gain * shade + rng.normal(0.0, noise, background.shape)
    out: np.ndarray = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    return out
