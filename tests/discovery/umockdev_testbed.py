"""A umockdev testbed driven over stdin: the mock sysfs/udev the USB tests plug devices into.

Run by the tests as ``umockdev-wrapper /usr/bin/python3 umockdev_testbed.py`` (Debian's system
Python: its ``gi.repository.UMockdev``; not the project's venv). umockdev's testbed must itself
run under the preload library, so that its uevent sender sees the mock /sys. It prints one JSON
line ``{"dir": UMOCKDEV_DIR}``; a program started with that ``UMOCKDEV_DIR`` under
``umockdev-wrapper`` (the hub, the CLI) sees the testbed's devices instead of the machine's,
and its udev monitor gets the events sent here. Each command is one JSON line, each answer too
(``{"ok": true, ...}`` or ``{"error": "..."}``):

- ``{"cmd": "add", "record": TEXT}``: the devices of a umockdev record (``P:``/``E:``/``A:``
  lines, udev's own properties), then an ``add`` uevent for each (a hot-plug); answers the
  sysfs paths.
- ``{"cmd": "load", "record": TEXT}``: the same without events (present at start).
- ``{"cmd": "remove", "record": TEXT}``: a ``remove`` uevent for each device of the record,
  children first, each then gone from the mock sysfs (an unplug). umockdev keeps a removed tty
  node's pty: a board plugged in again comes back on another node (``/dev/ttyACM1``), as Linux
  gives it when the old one is still held.
- ``{"cmd": "pty", "node": "/dev/ttyACM0"}``: the master side of the pty umockdev backs a tty node
  with (set raw, as a USB CDC port is), sent over the socket whose descriptor is the first argument
  (``SCM_RIGHTS``): the test writes a board's bytes into it, the hub reads them from the node.
"""

from __future__ import annotations

import json
import os
import socket
import sys
import termios
import tty

import gi

gi.require_version("UMockdev", "1.0")
from gi.repository import UMockdev  # noqa: E402  (the version is chosen first, as gi requires)


def _paths(record: str) -> list[str]:
    return ["/sys" + line[3:].strip() for line in record.splitlines() if line.startswith("P: ")]


def _tty_nodes(record: str) -> list[str]:
    """The DEVNAMEs of the record's tty devices."""
    out, tty_dev, node = [], False, ""
    for line in [*record.splitlines(), ""]:
        if not line.strip():
            if tty_dev and node:
                out.append(node)
            tty_dev, node = False, ""
        elif line.startswith("E: SUBSYSTEM="):
            tty_dev = line.split("=", 1)[1].strip() == "tty"
        elif line.startswith("E: DEVNAME="):
            node = line.split("=", 1)[1].strip()
    return out


def _send_pty(testbed: UMockdev.Testbed, node: str, channel: socket.socket) -> None:
    master = testbed.get_dev_fd(node)
    if master < 0:
        raise ValueError(f"{node} is not a tty node of the testbed")
    # the testbed's node is a symlink to the pty's slave side
    slave = os.open(os.path.realpath(testbed.get_root_dir() + node), os.O_RDWR | os.O_NOCTTY)
    try:
        tty.setraw(slave, termios.TCSANOW)
    finally:
        os.close(slave)
    socket.send_fds(channel, [node.encode()], [master])


def _passthrough(handler: UMockdev.IoctlBase, client: UMockdev.IoctlClient) -> bool:
    """Every ioctl on a tty node done on its pty (umockdev's default handler refuses what it does not
    emulate, e.g. ``TIOCINQ``: pyserial's ``in_waiting``)."""
    result, errno = client.execute()
    client.complete(result, errno)
    return True


def main() -> None:
    channel = socket.socket(fileno=int(sys.argv[1])) if len(sys.argv) > 1 else None
    testbed = UMockdev.Testbed.new()
    handlers: dict[str, UMockdev.IoctlBase] = {}  # kept: the testbed holds them weakly
    print(json.dumps({"dir": testbed.get_root_dir()}), flush=True)
    for line in sys.stdin:
        try:
            msg = json.loads(line)
            if msg["cmd"] in ("add", "load"):
                if not testbed.add_from_string(msg["record"]):
                    raise ValueError("umockdev did not take the record")
                paths = _paths(msg["record"])
                for node in _tty_nodes(msg["record"]):
                    handler = UMockdev.IoctlBase()
                    handler.connect("handle-ioctl", _passthrough)
                    testbed.attach_ioctl(node, handler)
                    handlers[node] = handler
                if msg["cmd"] == "add":
                    for path in paths:  # parents first, as the kernel announces them
                        testbed.uevent(path, "add")
                answer: dict[str, object] = {"ok": True, "paths": paths}
            elif msg["cmd"] == "remove":
                paths = _paths(msg["record"])
                for node in _tty_nodes(msg["record"]):
                    if handlers.pop(node, None) is not None:
                        testbed.detach_ioctl(node)
                for path in reversed(paths):
                    testbed.uevent(path, "remove")
                    testbed.remove_device(path)
                answer = {"ok": True, "paths": paths}
            elif msg["cmd"] == "pty":
                if channel is None:
                    raise ValueError("no socket to send a pty over (first argument)")
                _send_pty(testbed, msg["node"], channel)
                answer = {"ok": True}
            else:
                answer = {"error": f"unknown command {msg['cmd']!r}"}
        except Exception as e:  # the test reads why, the testbed stays up
            answer = {"error": f"{type(e).__name__}: {e}"}
        print(json.dumps(answer), flush=True)


if __name__ == "__main__":
    main()
