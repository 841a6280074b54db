"""Nagle's algorithm off on the Foxglove endpoint's sockets: an adapter around ``foxglove-sdk``.

Why: the SDK (0.30) accepts its clients without ``TCP_NODELAY``. Its messages are small (a skin
packet is ~300 bytes) and sent back to back, so Nagle holds each behind the previous one's ACK,
and the client's delayed ACK (up to 40 ms on Linux) sets the pace: frame in -> Foxglove client
p50 ~17 ms, p99 ~34 ms at 8 devices x 120 Hz, against 10 ms (issue 30; docs/benchmarks.md). ROS's
own ``foxglove_bridge`` sets the option on every client socket for this reason.

How: the SDK exposes neither its listener nor its accepted sockets, but Linux copies
``TCP_NODELAY`` from a listening socket to every socket it accepts. So the listener bound to our
port is found among this process's descriptors (``/proc/self/net/tcp*`` gives the listening
socket's inode, ``/proc/self/fd`` the descriptor holding it) and the option set on a duplicate
of that descriptor (the same socket; the SDK's descriptor is never closed or changed). Clients
that connected before this call keep Nagle: it runs right after the server is bound, before the
address is announced. Elsewhere than Linux (no ``/proc``) nothing is found and the caller logs it.
"""

from __future__ import annotations

import os
import socket
from pathlib import Path

__all__ = ["ESTABLISHED", "LISTEN", "descriptors", "descriptors_of", "disable_nagle", "tcp_sockets"]

LISTEN, ESTABLISHED = "0A", "01"  # the kernel's TCP states as /proc/net/tcp writes them


def tcp_sockets(port: int, state: str) -> dict[str, list[str]]:
    """This process's TCP sockets on local ``port`` in ``state``: inode -> their ``/proc/net/tcp``
    fields (2: the remote address, 4: ``tx_queue:rx_queue``, in hex)."""
    found: dict[str, list[str]] = {}
    for table in ("tcp", "tcp6"):
        try:
            lines = Path(f"/proc/self/net/{table}").read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            fields = line.split()
            if fields[3] == state and int(fields[1].rpartition(":")[2], 16) == port:
                found[fields[9]] = fields
    return found


def descriptors_of(inodes: set[str] | dict[str, list[str]], pid: int | str = "self") -> list[int]:
    """This process's (or process ``pid``'s) descriptors of the sockets with these inodes."""
    found = []
    for fd in os.listdir(f"/proc/{pid}/fd") if inodes else ():
        try:
            target = os.readlink(f"/proc/{pid}/fd/{fd}")
        except OSError:  # closed since listed
            continue
        if target.startswith("socket:[") and target[8:-1] in inodes:
            found.append(int(fd))
    return found


def descriptors(port: int, state: str = LISTEN, pid: int | str = "self") -> list[int]:
    """This process's (or process ``pid``'s) descriptors of TCP sockets on local ``port`` in ``state``
    (the sockets of the network namespace's table: the Foxglove relay's, seen from the hub)."""
    return descriptors_of(tcp_sockets(port, state), pid)


def disable_nagle(port: int) -> int:
    """Set ``TCP_NODELAY`` on this process's sockets listening on ``port``; how many were found."""
    fds = descriptors(port)
    for fd in fds:
        dup = socket.socket(fileno=os.dup(fd))
        try:
            dup.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        finally:
            dup.close()
    return len(fds)
