"""Marker vision shared by the camera-based skins (barrel, flat pad).

Submodules import OpenCV inside the functions that need it, so importing
``wott_vision`` (or any of its modules) never loads cv2: a hub whose scene has
no camera pays nothing for this package.

- ``wott_vision.markers``: ``detect_markers`` (threshold, connected components, sub-pixel centroids)
- ``wott_vision.tracking``: ``MarkerTracker`` (nearest-neighbour association to a reference grid)
- ``wott_vision.render``: ``render_markers`` (anti-aliased synthetic marker images for simulators)
- ``wott_vision.camera``: ``open_source`` (OpenCV ``VideoCapture`` over a device, file or URL)
- ``wott_vision.simulated``: ``SimulatedSource`` (a simulator read like a camera)
"""

__all__: list[str] = []
