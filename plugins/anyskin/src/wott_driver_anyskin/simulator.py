"""A simulated AnySkin / ReSkin board: the firmware's burst frames on a real pty, pressed on demand.

Each chip reads a resting field (a few hundred µT, as a magnetised skin gives) plus, while a chip is
pressed (``press``), a change along the board's z at that chip and a quarter of it at its
neighbours, plus a little noise; the change is turned into each chip's own axes (the inverse of
``Board.rotations``), so the driver's board frame sees it where it was put. A toy for tests, the
benchmark and a demo, not a model of the skin's magnetics. ``repeat_every``: every so many frames the
sample before is sent again (the firmware's repeats).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from wott_driver_taxel.line import SimulatedLine
from wott_driver_taxel.pty_port import PtyPort

from .boards import Board
from .protocol import N_MAGS, encode_sample

__all__ = ["AnySkinSimulator"]

REST_UT = np.array([[-60.0, 35.0, -420.0], [45.0, -80.0, -390.0], [-30.0, -25.0, -450.0],
                    [70.0, 20.0, -400.0], [-50.0, 65.0, -410.0]])


class AnySkinSimulator:
    def __init__(self, board: Board, *, rate_hz: float = 200.0, link: str | Path | None = None,
                 repeat_every: int = 0, noise_ut: float = 1.0, seed: int = 0) -> None:
        self.board = board
        self.rate_hz = rate_hz
        self.repeat_every = repeat_every
        self.noise_ut = noise_ut
        self.line = SimulatedLine(PtyPort(link), rate_hz, self._make)
        self._to_chip = np.transpose(board.rotations, (0, 2, 1))  # board -> each chip's axes
        self._rng = np.random.default_rng(seed)
        self._pressed = np.zeros((N_MAGS, 3))  # the change, board frame
        self._last = b""
        self._near = self._neighbours()

    def _neighbours(self) -> np.ndarray:
        p = self.board.positions_mm
        d = np.linalg.norm(p[:, None, :] - p[None, :, :], axis=2)
        near: np.ndarray = np.abs(d - d[d > 0].min()) < 1e-6  # chips one pitch apart
        return near.astype(float)

    def press(self, chip: int | None, change_ut: float = 400.0) -> None:
        """Press at ``chip`` (its index in the firmware's order; None: release): its field grows by
        ``change_ut`` along the board's z (into the board: the skin's magnet comes closer)."""
        change = np.zeros((N_MAGS, 3))
        if chip is not None:
            weights = np.eye(N_MAGS)[chip] + 0.25 * self._near[chip]
            change[:, 2] = -change_ut * weights
        with self.line.lock:
            self._pressed = change

    def sample(self) -> tuple[np.ndarray, np.ndarray]:
        """(temperature °C (5,), field µT (5, 3) in each chip's axes) of the next frame."""
        board = REST_UT + self._pressed + self._rng.normal(0.0, self.noise_ut, (N_MAGS, 3))
        chip = np.einsum("kij,kj->ki", self._to_chip, board)
        return 25.0 + self._rng.normal(0.0, 0.05, N_MAGS), chip

    def _make(self, k: int) -> bytes:
        if self.repeat_every and self._last and k % self.repeat_every == 0:
            return self._last
        self._last = encode_sample(*self.sample())
        return self._last

    @property
    def frames_sent(self) -> int:
        return self.line.frames_sent

    def start(self) -> str:
        return self.line.start()

    def stop(self) -> None:
        self.line.stop()
