"""Where the five magnetometers of each board sit, and how each chip's axes turn into the board's.

Both boards carry five MLX90393 in a plus, 7.0 mm apart, on a 20 x 29 mm board (the sensing square
and a connector tab). Positions: the ReSkin 5X board's pick-and-place file (raunaqbhirangi/reskin_sensor,
``circuits/5X_ReSkin.Zip``, ``Pick Place for PCB.txt``: U1 at the centre, U2/U4 275.6 mil = 7.0 mm
above and below, U3/U5 7.0 mm right and left); the AnySkin repository publishes no board files, and
its visualiser's photo of the board (``anyskin/visualizations/images/viz_bg.png``, 20 mm wide) shows
the same plus, 7 mm apart within the photo's precision (about ±0.5 mm). The order the firmware
sends the chips in, and each chip's in-plane rotation, are the makers' visualisers':
AnySkin ``anyskin_viz.py`` (centre, left, right, up, down; ``chip_xy_rotations`` -π/2, -π/2, π,
π/2, 0, drawn on a screen whose y points down), ReSkin ``visualizations/pygame_demo.py`` (centre,
top, right, bottom, left; its per-chip swaps and sign flips are rotations by -π/2, -π/2, 0, π, π/2
on the same screen, with z negated). The I2C addresses are the firmware's: AnySkin 0x0C-0x10,
ReSkin 0x0C, 0x13, 0x12, 0x10, 0x11.

The board frame (the TD's sensorCoordinateFrame): origin at the centre chip, x to the right chip, y
away from the connector (to the "up" chip), z out of the board into the skin. A chip's reading turns
into it by its in-plane rotation, then the screen's y flip, and z negated: each chip's own z points
into the board (the makers' handedness, a proper rotation overall). Not checked on a device.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from wott_hub.plugin_api import SkinMesh

__all__ = ["BOARDS", "Board"]

PITCH_MM = 7.0


@dataclass(frozen=True)
class Board:
    name: str
    addresses: tuple[int, ...]  # each chip's I2C address, in the order the firmware sends them
    places: tuple[str, ...]  # where each chip is: centre, left, right, up, down
    angles: tuple[float, ...]  # each chip's in-plane rotation on the makers' screen, rad

    @property
    def positions_mm(self) -> np.ndarray:
        at = {"centre": (0, 0), "left": (-1, 0), "right": (1, 0), "up": (0, 1), "down": (0, -1)}
        return np.array([(*at[p], 0) for p in self.places], dtype=np.float64) * PITCH_MM

    @property
    def rotations(self) -> np.ndarray:
        """(5, 3, 3): each chip's axes into the board frame (``board = R @ chip``)."""
        flip = np.diag([1.0, -1.0, -1.0])
        out = []
        for a in self.angles:
            c, s = math.cos(a), math.sin(a)
            out.append(flip @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]))
        return np.array(out)

    def mesh(self) -> SkinMesh:
        """The five chips as nodes, joined in four triangles around the centre (counter-clockwise)."""
        nodes = self.positions_mm
        index = {p: i for i, p in enumerate(self.places)}
        c = index["centre"]
        ring = [index[p] for p in ("right", "up", "left", "down")]
        cells = [(c, ring[k], ring[(k + 1) % 4]) for k in range(4)]
        return SkinMesh(nodes, np.array(cells), np.ones(len(nodes), dtype=bool), name=f"{self.name}-5x")


BOARDS = {
    "anyskin": Board("anyskin", (0x0C, 0x0D, 0x0E, 0x0F, 0x10), ("centre", "left", "right", "up", "down"),
                     (-math.pi / 2, -math.pi / 2, math.pi, math.pi / 2, 0.0)),
    "reskin": Board("reskin", (0x0C, 0x13, 0x12, 0x10, 0x11), ("centre", "up", "right", "down", "left"),
                    (-math.pi / 2, -math.pi / 2, 0.0, math.pi, math.pi / 2)),
}
