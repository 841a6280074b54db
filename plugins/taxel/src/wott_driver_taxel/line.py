"""A simulated device's serial line: frames written to a real pty at the device's own pace.

Frame ``k`` is made by ``make(k)`` and sent at ``t0 + k / rate_hz``. Like a board powered from the USB
cable, it sends nothing while unplugged (``make`` is not called) and, plugged back in, starts afresh
(``on_replug``). A UART does not wait for its reader: when more than four frames are still unread in
the pty the new one is dropped (and counted).

A real board's clock does not stop when the computer simulating it is busy: every frame it would have
sent was sampled at its own instant. So a writer thread that wakes up late (a loaded machine stalls a
thread for tens of milliseconds, now and then for longer) sends the frames it missed, each ``make(k)``
for its own ``k``, rather than skipping them: the reader sees a burst of frames that were sampled at
their right times, exactly what a serial link delivers after the reader stalled. Only a stall longer
than ``catch_up_s`` (1 s: a suspended process) skips time, and those ticks are counted
(``ticks_skipped``): ``k`` jumps, so a board that numbers its frames by ``k`` shows the gap.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from .pty_port import PtyPort

__all__ = ["SimulatedLine"]


class SimulatedLine:
    def __init__(self, port: PtyPort, rate_hz: float, make: Callable[[int], bytes],
                 on_replug: Callable[[], None] | None = None, *, catch_up_s: float = 1.0) -> None:
        if not rate_hz > 0:
            raise ValueError(f"rate_hz must be positive, got {rate_hz}")
        self.port = port
        self.rate_hz = float(rate_hz)
        self.frames_sent = 0
        self.frames_dropped = 0  # the line was busy (nobody reading): a real UART overruns too
        self.ticks_skipped = 0  # the writer stalled longer than catch_up_s: time skipped, nothing sent
        self.catch_up_s = float(catch_up_s)
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
            elif delay < -self.catch_up_s:  # stalled for long: skip to now (the missed ticks are lost)
                skip = int(-delay / period)
                self.ticks_skipped += skip
                k += skip
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
