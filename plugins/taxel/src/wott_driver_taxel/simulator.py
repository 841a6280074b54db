"""A simulated taxel board: plays a scene and sends its pressure frames over a real pty.

Frame k shows the scene at t = k / rate_hz. The ground-truth displacement of
that instant (``Scene.displacement_at``: the indentation model now, the
Kelvin-Voigt skin later) is turned into what the taxels feel, its inward
normal component through the skin's compliance (``Compliance.counts``), and
encoded in the configured protocol. The ground truth of the recent frames is
kept by sequence number, so a test can compare what the hub recovered with
what was pressed.

Like a board powered from the USB cable, it stops sending while unplugged and
restarts its sequence at 0 when plugged back in. A late writer thread skips
scene time rather than bursting, but never skips sequence numbers.
"""

from __future__ import annotations

import threading
import time
from collections import OrderedDict
from pathlib import Path

import numpy as np

from wott_hub.plugin_api import Scene, SkinMesh

from .compliance import Compliance
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
        self.port = PtyPort(link)
        self.frames_sent = 0
        self.frames_dropped = 0  # the line was busy (nobody reading): a real UART overruns too
        self._history = history
        self._truth: OrderedDict[int, np.ndarray] = OrderedDict()
        self._seq = 0
        self._out = bytearray()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._normals = mesh.normals

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
        with self._lock:
            return self._truth.get(seq)

    # -- the line --------------------------------------------------------------
    def _send(self, k: int) -> None:
        counts, truth = self.frame(k)
        with self._lock:
            if not self.port.plugged:
                return
            seq = self._seq
            self._seq = (seq + 1) % SEQ_MODULO
            self._truth[seq] = truth
            while len(self._truth) > self._history:
                self._truth.popitem(last=False)
            data = self.encode(seq, counts)
            if len(self._out) > 4 * len(data):
                self.frames_dropped += 1
            else:
                self._out += data
                self.frames_sent += 1
            del self._out[: self.port.write(bytes(self._out))]

    def _run(self) -> None:
        period = 1.0 / self.rate_hz
        t0 = time.monotonic()
        k = 0
        while not self._stop.is_set():
            delay = t0 + k * period - time.monotonic()
            if delay > 0:
                if self._stop.wait(delay):
                    break
            elif delay < -period:
                k += int(-delay / period)  # late: skip scene time, keep the sequence gapless
                continue
            self._send(k)
            k += 1

    def write_raw(self, data: bytes) -> None:
        """Put arbitrary bytes on the line between frames (noise, a boot banner)."""
        with self._lock:
            self._out += data
            del self._out[: self.port.write(bytes(self._out))]

    def unplug(self) -> None:
        with self._lock:
            self.port.unplug()
            self._out.clear()

    def replug(self) -> str:
        with self._lock:
            path = self.port.replug()
            self._seq = 0
            self._truth.clear()
            return path

    # -- lifecycle -------------------------------------------------------------
    def start(self) -> str:
        """Open the pty and start sending; returns the path a reader opens."""
        path = self.port.open()
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name=f"taxel-sim {path}", daemon=True)
            self._thread.start()
        return path

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5.0)
        with self._lock:
            self.port.close()
