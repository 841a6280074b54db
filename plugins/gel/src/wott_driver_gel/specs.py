"""The two sensors' numbers, each with where it comes from (docs/gel.md, "Defaults and their sources").

GelSight Mini (gelsightinc/gsrobotics): a UVC camera streaming MJPEG at its native 3280 x 2464. The
maker's software crops ``MINI_BORDER_FRACTION`` of the frame from each side (``crop_and_resize`` in
``utilities/image_processing.py``, ``border_fraction=0.15``) and resizes what is left to its working
size (320 x 240 by default there). Scale: Taxim's calibration of a Mini (``taxim/calib/gelsight_mini/
params.json``) gives 0.0295 mm/px on its 640 x 480 frames, so the shaped view is 640 x 0.0295 =
18.88 mm wide whatever size it is resized to: ``mm_per_px`` defaults to that width over the frame's.

DIGIT (facebookresearch/digit-interface, tacto): a UVC camera whose QVGA frames (320 x 240) are
turned 90° (digit-interface's ``get_frame``: transpose, then flip about the x axis) to 240 wide x
320 tall. Scale: tacto's DIGIT camera (``config_digit.yml``: vertical field of view 60°, 21.67 mm from
the camera to the gel) sees 2 x 21.67 x tan(30°) = 25.02 mm over the rotated frame's 320 rows, 0.0782
mm/px; its 240 columns span 18.77 mm. Streams and LED levels are digit-interface's.
"""

from __future__ import annotations

import math

__all__ = ["DIGIT_LED_MAX", "DIGIT_STREAMS", "DIGIT_VIEW_MM", "MINI_BORDER_FRACTION", "MINI_DECODE_SCALE",
           "MINI_NATIVE", "MINI_SIZE", "MINI_VIEW_MM", "default_mm_per_px"]

MINI_NATIVE = (3280, 2464)
"""The Mini's native MJPEG frame (width, height), px."""
MINI_BORDER_FRACTION = 0.15
"""Cropped from each side of the native frame before resizing (gsrobotics ``crop_and_resize``)."""
MINI_SIZE = (320, 240)
"""The shaped frame (width, height) gsrobotics works at by default, px."""
MINI_DECODE_SCALE = 8
"""The native JPEG decoded at 1/8 (410 x 308; cropped 287 x 216, then resized to ``MINI_SIZE``): libjpeg's
DCT scaling costs 0.6x the 1/4 decode's CPU, and Taxim's Mini presses at 287 x 216 resized to 320 x 240
score as at 320 x 240 (``bench gel``'s decode table: error against run time)."""
MINI_VIEW_MM = 640 * 0.0295
"""Width of the shaped view, mm (Taxim's 0.0295 mm/px at 640 px)."""

DIGIT_STREAMS: dict[str, tuple[int, int, int]] = {
    "QVGA60": (320, 240, 60), "QVGA30": (320, 240, 30), "VGA30": (640, 480, 30), "VGA15": (640, 480, 15),
}
"""digit-interface's streams: (width, height, fps) as the camera sends them, before the rotation."""
DIGIT_VIEW_MM = 240 * (2 * 21.66890464317989 * math.tan(math.radians(30.0)) / 320)
"""Width of the rotated DIGIT view, mm (tacto's camera: 0.0782 mm/px at 240 px)."""
DIGIT_LED_MAX = 15
"""The firmware's per-channel LED level (digit-interface: 0..15 for each of R, G, B)."""


def default_mm_per_px(family: str, width_px: int) -> float:
    """The sensor's scale for frames ``width_px`` wide (its view's width spread over them)."""
    view = MINI_VIEW_MM if family == "gelsight-mini" else DIGIT_VIEW_MM
    return view / float(width_px)
