"""One serial port, read in a thread, decoded, handed to asyncio; it survives unplugging.

pyserial is blocking and portable (Linux ttys and ptys, Windows COM ports,
``socket://`` and ``rfc2217://`` URLs), so the port lives in its own thread
that blocks in ``read`` with a short timeout. Decoded frames cross into the
event loop through ``call_soon_threadsafe`` into a bounded queue: if the
consumer falls behind, the oldest frames are dropped (and counted), never the
newest, and the reader never blocks on the consumer.

When the port fails (unplugged adapter, pty hung up, device reset) the reader
closes it, counts a frame in progress as truncated, reports ``disconnected``
with the reason and re-opens it with exponential backoff; after a re-open the
decoder starts afresh (the sequence may restart with the device).

The decoder is the taxel array's (``make_decoder``: its four protocols) or any ``Decoder``: bytes in,
items out, with counters whose ``FAULTS`` make the link ``degraded`` (the AnySkin plugin's frames).
"""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import AsyncIterator, Callable
from typing import Any, ClassVar, Protocol

import serial

from wott_hub.plugin_api import Backoff, Health

from .matrix import FlexiTacDecoder, VitacDecoder
from .protocol import Counters, FrameDecoder, LineDecoder

__all__ = ["PROTOCOLS", "Decoder", "LinkCounters", "SerialReader", "make_decoder"]

_STOP = object()

PROTOCOLS: dict[str, Callable[..., Decoder]] = {
    "binary": FrameDecoder, "ascii": LineDecoder, "flexitac": FlexiTacDecoder, "3dvitac": VitacDecoder}


class LinkCounters(Protocol):
    """What a decoder counts: ``FAULTS`` name the fields that make the link degraded while they grow."""

    FAULTS: ClassVar[tuple[str, ...]]
    dropped: int
    reconnects: int

    @property
    def faults(self) -> int: ...

    def as_dict(self) -> dict[str, int]: ...


class Decoder(Protocol):
    counters: Any  # a LinkCounters (Any: a dataclass's fields are not the protocol's attributes to mypy)

    def feed(self, data: bytes | bytearray) -> list[Any]: ...

    def reset(self) -> None: ...


def make_decoder(protocol: str, expect: tuple[int, int], counters: Counters | None = None) -> Decoder:
    """The taxel array's decoder, joining: a port is usually opened in the middle of a frame."""
    try:
        kind = PROTOCOLS[protocol]
    except KeyError:
        raise ValueError(f"unknown protocol {protocol!r}: expected one of {', '.join(PROTOCOLS)}") from None
    return kind(expect, counters, joining=True)


class SerialReader:
    """Frames from ``port`` as ``(t_ns, item)``, ``t_ns`` the wall-clock time they were read; an item is
    a ``RawFrame`` of the taxel protocols (``shape``, ``protocol``), or what ``decoder`` gives.

    ``opener`` replaces ``serial.serial_for_url(port, baudrate, timeout=...)``
    (e.g. to hand over a ``loop://`` port); ``on_health(state, reason)`` is
    called from the reader thread whenever the link's health changes.
    """

    def __init__(
        self,
        port: str,
        *,
        shape: tuple[int, int] | None = None,
        baudrate: int = 921600,
        protocol: str = "binary",
        counters: Counters | None = None,
        decoder: Decoder | None = None,
        backoff: Backoff | None = None,
        opener: Callable[[], Any] | None = None,
        on_health: Callable[[Health, str], None] | None = None,
        read_timeout_s: float = 0.05,
        silence_s: float = 2.0,
        degrade_window_s: float = 1.0,
        queue_size: int = 64,
    ) -> None:
        self.port = port
        self.baudrate = baudrate
        if decoder is None:
            if shape is None:
                raise ValueError("a taxel protocol's reader needs the array's shape")
            decoder = make_decoder(protocol, shape, counters if counters is not None else Counters())
        self.decoder = decoder
        self.counters: LinkCounters = decoder.counters
        self.backoff = backoff or Backoff()
        self.read_timeout_s = read_timeout_s
        self.silence_s = silence_s
        self.degrade_window_s = degrade_window_s
        self.connected = False
        self._opener = opener or self._open
        self._on_health = on_health or (lambda state, reason: None)
        self._state: tuple[Health, str] | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._serial: Any = None
        self._queue: asyncio.Queue[Any] | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._queue_size = queue_size
        self._ok_snapshot = self.counters.as_dict()
        self._last_fault_t = -float("inf")
        self._faults_seen = self.counters.faults

    def _open(self) -> Any:
        return serial.serial_for_url(self.port, self.baudrate, timeout=self.read_timeout_s)

    # -- health --------------------------------------------------------------
    def _health(self, state: Health, reason: str = "") -> None:
        if self._state != (state, reason):
            self._state = (state, reason)
            self._on_health(state, reason)

    def _update_health(self, now: float, last_frame_t: float) -> None:
        faults = self.counters.faults
        if faults != self._faults_seen:
            self._faults_seen = faults
            self._last_fault_t = now
        if now - last_frame_t > self.silence_s:
            self._health(Health.degraded, f"no frames from {self.port} for more than {self.silence_s:g} s")
        elif now - self._last_fault_t < self.degrade_window_s:
            c = self.counters.as_dict()
            parts = [f"{c[k] - self._ok_snapshot[k]} {k.replace('_', ' ')}" for k in self.counters.FAULTS
                     if c[k] != self._ok_snapshot[k]]
            self._health(Health.degraded, "link errors: " + ", ".join(parts))
        else:
            self._ok_snapshot = self.counters.as_dict()
            self._health(Health.ok)

    # -- the thread ------------------------------------------------------------
    def _push(self, item: Any) -> None:
        loop = self._loop
        if loop is None:
            return
        try:
            loop.call_soon_threadsafe(self._enqueue, item)
        except RuntimeError:  # the loop is closed: nobody is listening any more
            self._stop.set()

    def _enqueue(self, item: Any) -> None:
        q = self._queue
        if q is None:
            return
        if q.full():
            q.get_nowait()
            self.counters.dropped += 1
        q.put_nowait(item)

    def _run(self) -> None:
        was_connected = False
        while not self._stop.is_set():
            try:
                ser = self._opener()
            except Exception as e:  # SerialException, OSError, ValueError: all mean "not now"
                self._health(Health.disconnected, f"cannot open {self.port}: {e}")
                if self.backoff.wait(self._stop):
                    break
                continue
            self._serial = ser
            reason = ""
            try:
                ser.reset_input_buffer()  # bytes queued while nobody listened are stale
                self.connected = True
                if was_connected:
                    self.counters.reconnects += 1
                was_connected = True
                last_frame_t = time.monotonic()
                self._health(Health.degraded, f"{self.port} open, waiting for frames")
                while not self._stop.is_set():
                    data = ser.read(min(max(ser.in_waiting, 1), 1 << 16))
                    now = time.monotonic()
                    if data:
                        t_ns = time.time_ns()
                        frames = self.decoder.feed(data)
                        if frames:
                            last_frame_t = now
                            self.backoff.reset()
                            for f in frames:
                                self._push((t_ns, f))
                    self._update_health(now, last_frame_t)
            except Exception as e:  # SerialException / OSError: the port went away
                reason = f"lost {self.port}: {e}"
            finally:
                self._serial = None
                self.connected = False
                try:
                    ser.close()
                except Exception:
                    pass
            if self._stop.is_set():
                break
            self.decoder.reset()
            self._health(Health.disconnected, reason)
            if self.backoff.wait(self._stop):
                break
        self._push(_STOP)

    # -- lifecycle -------------------------------------------------------------
    def start(self) -> None:
        if self._thread is not None:
            return
        self._loop = asyncio.get_running_loop()
        self._queue = asyncio.Queue(self._queue_size)
        self._thread = threading.Thread(target=self._run, name=f"serial-reader {self.port}", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Ask the thread to finish (it leaves within one read timeout); does not wait."""
        self._stop.set()
        ser = self._serial
        if ser is not None and hasattr(ser, "cancel_read"):
            try:
                ser.cancel_read()
            except Exception:
                pass

    async def close(self) -> None:
        self.stop()
        if self._thread is not None:
            await asyncio.to_thread(self._thread.join, 5.0)

    async def frames(self) -> AsyncIterator[tuple[int, Any]]:
        self.start()
        assert self._queue is not None
        try:
            while True:
                item = await self._queue.get()
                if item is _STOP:
                    return
                yield item
        finally:
            self.stop()
