"""A simulated taxel board: plays a scene and sends its pressure frames over a real pty.

Frame k shows the scene at t = k / rate_hz. The ground-truth displacement of
that instant (``Scene.displacement_at``: the indentation model now, the
Kelvin-Voigt skin later) is turned into what the taxels feel, its inward
normal component through the skin's compliance (``Compliance.counts``), and
encoded in the configured protocol. The ground truth of the recent frames is
kept by sequence number, so a test can compare what the hub recovered with
what was pressed.

Its line (``line.SimulatedLine``) paces it and stops while unplugged; a late writer sends the
frames it missed (each sampled at its own tick), so the frames' sequence numbers keep the board's
time: frame k goes out numbered k (from the tick the board was last plugged in), and a tick that was
never sent (a stall beyond the line's ``catch_up_s``, an overrun) is a gap in the numbers, which the
driver's clock reads as frames lost on the line. Plugged back in, the board restarts its sequence
at 0. ``scene_time(seq)`` says which scene instant a recent frame showed (the accuracy bench scores
each frame against it).
"""

from __future__ import annotations

from collections import OrderedDict
from pathlib import Path

import numpy as np

from wott_hub.plugin_api import Scene, SkinMesh

from .compliance import Compliance
from .line import SimulatedLine
from .matrix import encode_3dvitac, encode_flexitac
from .protocol import SEQ_MODULO, encode_frame, encode_line
from .pty_port import PtyPort

__all__ = ["REST_COUNTS", "TaxelSimulator"]

REST_COUNTS = 20
"""What an 8-bit matrix reads at rest (flexitac 0.3.1: "typical resting ADC values land around 10-40")."""


class TaxelSimulator:
    def __init__(
        self,
        scene: Scene,
        mesh: SkinMesh,
        shape: tuple[int, int],
        compliance: Compliance,
        *,
        rate_hz: float = 100.0,
        protocol: str = "binary",
        link: str | Path | None = None,
        history: int = 4096,
    ) -> None:
        rows, cols = shape
        if rows * cols != mesh.n_nodes:
            raise ValueError(f"a {rows} x {cols} array needs a mesh of {rows * cols} nodes, "
                             f"got {mesh.n_nodes}")
        if protocol not in ("binary", "ascii", "flexitac", "3dvitac"):
            raise ValueError(f"unknown protocol {protocol!r}")
        if not rate_hz > 0:
            raise ValueError(f"rate_hz must be positive, got {rate_hz}")
        self.scene = scene
        self.mesh = mesh
        self.shape = (rows, cols)
        self.compliance = compliance
        self.rate_hz = float(rate_hz)
        self.protocol = protocol
        self.line = SimulatedLine(PtyPort(link), rate_hz, self._make, on_replug=self._restart)
        self.port = self.line.port
        self._history = history
        self._truth: OrderedDict[int, tuple[int, np.ndarray]] = OrderedDict()  # seq -> (k, truth)
        self._k0: int | None = None  # the tick numbered 0 (the board's power-on); None: the next one
        self._normals = mesh.normals

    @property
    def frames_sent(self) -> int:
        return self.line.frames_sent

    @property
    def frames_dropped(self) -> int:
        return self.line.frames_dropped

    # -- the signal ------------------------------------------------------------
    def frame(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """(counts as rows x cols, ground-truth displacement N x 3) of frame ``k``."""
        truth = self.scene.displacement_at(k / self.rate_hz, self.mesh)
        inward = -np.einsum("ij,ij->i", truth, self._normals)
        return self.compliance.counts(inward).reshape(self.shape), truth

    def encode(self, seq: int, counts: np.ndarray) -> bytes:
        """One frame on the wire; an 8-bit matrix (no sequence number) reads its counts above its rest."""
        if self.protocol == "binary":
            return encode_frame(seq, counts)
        if self.protocol == "ascii":
            return encode_line(seq, counts)
        values = np.minimum(counts.astype(np.int64) + REST_COUNTS, 255)
        return encode_flexitac(values) if self.protocol == "flexitac" else encode_3dvitac(values)

    def truth(self, seq: int) -> np.ndarray | None:
        """Ground truth of the recent frame sent with sequence number ``seq`` (None if forgotten)."""
        with self.line.lock:
            kept = self._truth.get(seq)
        return None if kept is None else kept[1]

    def scene_time(self, seq: int) -> float | None:
        """Scene time (s) of the recent frame sent with sequence number ``seq`` (None if forgotten)."""
        with self.line.lock:
            kept = self._truth.get(seq)
        return None if kept is None else kept[0] / self.rate_hz

    def _make(self, k: int) -> bytes:
        """Frame ``k``, numbered (the line holds its lock)."""
        counts, truth = self.frame(k)
        if self._k0 is None:
            self._k0 = k
        seq = (k - self._k0) % SEQ_MODULO
        self._truth[seq] = (k, truth)
        while len(self._truth) > self._history:
            self._truth.popitem(last=False)
        return self.encode(seq, counts)

    def _restart(self) -> None:
        """Plugged back in: the board counts from 0 again."""
        self._k0 = None
        self._truth.clear()

    # -- the line --------------------------------------------------------------
    def write_raw(self, data: bytes) -> None:
        """Put arbitrary bytes on the line between frames (noise, a boot banner)."""
        self.line.write_raw(data)

    def unplug(self) -> None:
        self.line.unplug()

    def replug(self) -> str:
        return self.line.replug()

    def start(self) -> str:
        """Open the pty and start sending; returns the path a reader opens."""
        return self.line.start()

    def stop(self) -> None:
        self.line.stop()
