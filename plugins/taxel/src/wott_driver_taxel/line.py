"""A simulated device's serial line: frames written to a real pty at the device's own pace.

Frame ``k`` is made by ``make(k)`` and sent at ``t0 + k / rate_hz``. Like a board powered from the USB
cable, it sends nothing while unplugged (``make`` is not called) and, plugged back in, starts afresh
(``on_replug``). A UART does not wait for its reader: when more than four frames are still unread in
the pty the new one is dropped (and counted), and a late writer thread skips time rather than bursting.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from .pty_port import PtyPort

__all__ = ["SimulatedLine"]


class SimulatedLine:
    def __init__(self, port: PtyPort, rate_hz: float, make: Callable[[int], bytes],
                 on_replug: Callable[[], None] | None = None) -> None:
        if not rate_hz > 0:
            raise ValueError(f"rate_hz must be positive, got {rate_hz}")
        self.port = port
        self.rate_hz = float(rate_hz)
        self.frames_sent = 0
        self.frames_dropped = 0  # the line was busy (nobody reading): a real UART overruns too
        self.lock = threading.Lock()  # held while a frame is made and sent
        self._make = make
        self._on_replug = on_replug
        self._out = bytearray()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def _send(self, k: int) -> None:
        with self.lock:
            if not self.port.plugged:
                return
            data = self._make(k)
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
                k += int(-delay / period)  # late: skip time, keep the frames' own numbering gapless
                continue
            self._send(k)
            k += 1

    def write_raw(self, data: bytes) -> None:
        """Put arbitrary bytes on the line between frames (noise, a boot banner)."""
        with self.lock:
            self._out += data
            del self._out[: self.port.write(bytes(self._out))]

    def unplug(self) -> None:
        with self.lock:
            self.port.unplug()
            self._out.clear()

    def replug(self) -> str:
        with self.lock:
            path = self.port.replug()
            if self._on_replug is not None:
                self._on_replug()
            return path

    def start(self) -> str:
        """Open the pty and start sending; returns the path a reader opens."""
        path = self.port.open()
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name=f"simulated line {path}", daemon=True)
            self._thread.start()
        return path

    def halt(self) -> None:
        """Stop sending; the line stays open (what was sent can still be read)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5.0)

    def stop(self) -> None:
        self.halt()
        with self.lock:
            self.port.close()
