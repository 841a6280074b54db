"""A real pseudo-terminal standing in for a USB-serial taxel board.

The hub opens ``path`` with pyserial exactly as it would open /dev/ttyUSB0;
the simulator (or a test) writes the device's bytes into the master side.
With a ``link`` (a symlink, like socat's ``link=``), the device can be
unplugged (the path vanishes and both pty ends close: the reader's next
read fails) and plugged back in (a fresh pty behind the same path), which is
what a reader's reconnect logic must survive.
"""

from __future__ import annotations

import os
import time
import tty
from pathlib import Path

__all__ = ["PtyPort"]


class PtyPort:
    def __init__(self, link: str | Path | None = None) -> None:
        self.link = Path(link) if link is not None else None
        self._master: int | None = None
        self._slave: int | None = None
        self._slave_name: str | None = None

    @property
    def plugged(self) -> bool:
        return self._master is not None

    @property
    def path(self) -> str:
        """What a reader opens: the link if there is one, else the pty's slave device."""
        if self.link is not None:
            return str(self.link)
        if self._slave_name is None:
            raise RuntimeError("the pty is not open")
        return self._slave_name

    def open(self) -> str:
        """Create the pty (raw, non-blocking master) and point the link at it."""
        if self._master is not None:
            return self.path
        master, slave = os.openpty()
        # Raw from the start: a cooked slave would echo bytes back into the master and
        # translate CR/LF before the reader gets to configure the port.
        tty.setraw(slave)
        os.set_blocking(master, False)
        self._master, self._slave, self._slave_name = master, slave, os.ttyname(slave)
        if self.link is not None:
            tmp = self.link.with_name(f".{self.link.name}.{os.getpid()}.tmp")
            tmp.unlink(missing_ok=True)
            os.symlink(self._slave_name, tmp)
            os.replace(tmp, self.link)  # atomic: a reader never sees the link missing mid-swap
        return self.path

    def write(self, data: bytes) -> int:
        """Write what fits without blocking (a UART does not wait either); returns bytes written."""
        if self._master is None or not data:
            return 0
        try:
            return os.write(self._master, data)
        except (BlockingIOError, InterruptedError):
            return 0
        except OSError:  # EIO while the slave side is being torn down
            return 0

    def write_all(self, data: bytes, timeout_s: float = 5.0) -> None:
        """Write everything, waiting for the reader to drain the pty (tests)."""
        view = memoryview(data)
        deadline = time.monotonic() + timeout_s
        while view:
            n = self.write(bytes(view[:4096]))
            view = view[n:]
            if view:
                if time.monotonic() > deadline:
                    raise TimeoutError(f"pty {self.path}: {len(view)} bytes not drained in {timeout_s} s")
                time.sleep(0.001)

    def unplug(self) -> None:
        """The device disappears: the link goes (as udev removes /dev/ttyUSB0), both ends close.

        Removing the link also keeps a reader from opening whatever new pty
        reuses the freed /dev/pts number.
        """
        if self.link is not None and self.link.is_symlink():
            self.link.unlink(missing_ok=True)
        for fd in (self._master, self._slave):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._master = self._slave = None

    def replug(self) -> str:
        """The device comes back: a new pty behind the same link."""
        if self.link is None:
            raise RuntimeError("replug needs a link path: without one the device would come back elsewhere")
        self.unplug()
        return self.open()

    def close(self) -> None:
        self.unplug()
