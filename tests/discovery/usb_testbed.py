"""The USB tests' rig: a umockdev testbed process, programs run inside it, a board's bytes on a tty node.

``UsbTestbed`` starts ``umockdev_testbed.py`` under ``umockdev-wrapper`` with Debian's system Python
(``gi.repository.UMockdev``), and speaks its JSON lines. ``run``/``popen`` start a program with the
testbed's ``UMOCKDEV_DIR`` under ``umockdev-wrapper`` (the preload library must be in the hub's own
process: its libudev, its netlink socket and its opens of /dev are the ones redirected). ``pty``
receives the master side of the pty behind a tty node (``SCM_RIGHTS``), and ``NodePort`` lets a
board simulator (``AnySkinSimulator``) write into it as into its own pty.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
from pathlib import Path
from typing import Any

from wott_driver_taxel.pty_port import PtyPort

HERE = Path(__file__).resolve().parent
CONTROLLER = HERE / "umockdev_testbed.py"
SYSTEM_PYTHON = "/usr/bin/python3"  # Debian's, with python3-gi and gir1.2-umockdev-1.0
WRAPPER = "umockdev-wrapper"
WOTT_HUB = str(Path(sys.executable).with_name("wott-hub"))


class UsbTestbed:
    def __init__(self) -> None:
        self._here, there = socket.socketpair()
        self.proc = subprocess.Popen([WRAPPER, SYSTEM_PYTHON, str(CONTROLLER), str(there.fileno())],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                                     pass_fds=[there.fileno()])
        there.close()
        assert self.proc.stdout is not None
        first = self.proc.stdout.readline()
        assert first, f"the umockdev testbed did not start (exit {self.proc.poll()})"
        self.dir = json.loads(first)["dir"]

    def _ask(self, **msg: Any) -> dict[str, Any]:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.write(json.dumps(msg) + "\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        assert line, f"the umockdev testbed exited ({self.proc.poll()})"
        answer: dict[str, Any] = json.loads(line)
        assert "error" not in answer, answer["error"]
        return answer

    def load(self, record: str) -> None:
        """Devices present from the start (no event)."""
        self._ask(cmd="load", record=record)

    def plug(self, record: str) -> None:
        """Hot-plug: the devices appear, with an ``add`` event each."""
        self._ask(cmd="add", record=record)

    def unplug(self, record: str) -> None:
        self._ask(cmd="remove", record=record)

    def pty(self, node: str) -> int:
        """The master side of the pty behind ``node`` (a descriptor of this process now)."""
        self._ask(cmd="pty", node=node)
        _, fds, _, _ = socket.recv_fds(self._here, 256, 1)
        return fds[0]

    @property
    def env(self) -> dict[str, str]:
        return {**os.environ, "UMOCKDEV_DIR": self.dir, "COLUMNS": "200"}

    def run(self, *args: str, timeout: float = 120, columns: int = 200) -> subprocess.CompletedProcess[str]:
        """``wott-hub *args`` inside the testbed, on a terminal ``columns`` wide."""
        return subprocess.run([WRAPPER, WOTT_HUB, *args], env={**self.env, "COLUMNS": str(columns)},
                              capture_output=True, text=True, timeout=timeout)

    def popen(self, *args: str, **kw: Any) -> subprocess.Popen[str]:
        return subprocess.Popen([WRAPPER, WOTT_HUB, *args], env=self.env, text=True, **kw)

    def close(self) -> None:
        if self.proc.stdin is not None:
            self.proc.stdin.close()
        try:
            self.proc.wait(15)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(5)
        if self.proc.stdout is not None:
            self.proc.stdout.close()
        self._here.close()


class NodePort(PtyPort):
    """A ``PtyPort`` whose pty is the one umockdev made for a tty node: the simulator writes into the
    master it is given (``plug``); the reader opens the node. ``unplug`` closes this end."""

    def __init__(self, node: str) -> None:
        super().__init__()
        self.node = node

    @property
    def path(self) -> str:
        return self.node

    def open(self) -> str:
        return self.node

    def plug(self, master: int, node: str | None = None) -> None:
        os.set_blocking(master, False)
        self.unplug()
        self._master = master
        self.node = node or self.node
