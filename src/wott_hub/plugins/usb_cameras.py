"""The USB cameras of the gel sensors, as the built-in plugin declares them (``wott_hub_usb_devices``).

The families ``digit`` and ``gelsight-mini`` are a plugin's (issue 44); what identifies their
sensors on USB is knowledge that does not depend on that plugin being installed, so the hub
declares it here: ``wott-hub discover --usb`` names a DIGIT or a Mini even where no plugin can
open it yet (listed, not adopted). Both are UVC cameras: the match is on the ``video4linux``
node, which gets the family's ``device`` setting (``/dev/videoN``).

- DIGIT: udev ``ID_MODEL=DIGIT`` (what Meta's ``digit-interface`` lists DIGITs by, through
  pyudev), USB ``2833:0209``, its serial (``D20001``) in ``ID_SERIAL_SHORT``.
- GelSight Mini: its V4L2 name contains ``GelSight Mini`` (what GelSight's SDK looks the camera
  up by), USB ``0c45:636d`` (the camera chip's vendor, Microdia/Sonix).

A camera exposes a second, metadata-only node with the same serial; ``discovery.usb`` keeps the
capture node. Not tried on a device.
"""

from __future__ import annotations

from .model import UsbMatch

__all__ = ["CAMERAS", "DIGIT", "GELSIGHT_MINI"]

DIGIT = (
    UsbMatch("digit", "video4linux", "DIGIT (Meta), UVC camera", model="DIGIT", setting="device"),
    UsbMatch("digit", "video4linux", "DIGIT (Meta), UVC camera", vendor_id="2833", product_ids=("0209",),
             setting="device"),
)
GELSIGHT_MINI = (
    UsbMatch("gelsight-mini", "video4linux", "GelSight Mini, UVC camera", v4l_product="GelSight Mini",
             setting="device"),
    UsbMatch("gelsight-mini", "video4linux", "GelSight Mini, UVC camera", vendor_id="0c45",
             product_ids=("636d",), setting="device"),
)
CAMERAS = DIGIT + GELSIGHT_MINI
