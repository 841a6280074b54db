"""What of the history spool cannot be read, set aside (renamed, never deleted) and named: entries that
are not regular files (a FIFO, a device, a symlink: never opened blocking, never followed) and
segments found damaged (issue 48). ``spool.py`` holds the contract; this is its bookkeeping."""

from __future__ import annotations

import errno
import logging
import os
import stat
from pathlib import Path
from typing import IO, Any, Protocol

from wott_hub.errors import HistoryError

__all__ = ["NotRegular", "SetAside", "kind", "open_lock"]

log = logging.getLogger("wott_hub.history.spool")


class ReadOutcome(Protocol):
    """What reading a segment gave (``spool.Read``)."""

    rows: list[Any]
    lost: int
    lost_bytes: int
    unknown_bytes: int
    header: bool


class NotRegular(HistoryError):
    """A spool entry that is not a regular file (a FIFO, a device, a symlink): never read."""


class SetAside:
    """The entries set aside this run (at most 64 kept), each with what it held and why."""

    def __init__(self) -> None:
        self.items: list[dict[str, Any]] = []

    def current(self) -> list[dict[str, Any]]:
        """Those still set aside (``keptAs`` exists): deleting that file says it has been seen to."""
        return [d for d in self.items if os.path.lexists(d["keptAs"])]

    def segment(self, path: Path, size: int, got: ReadOutcome, reason: str) -> Path:
        """A segment read with damage (``got``): renamed ``.damaged`` and named; where it is now."""
        per_record = (size - got.lost_bytes) / len(got.rows) if got.rows else 0.0
        guessed = -(-got.unknown_bytes // max(1, int(per_record))) if got.unknown_bytes and per_record else 0
        estimated = bool(got.unknown_bytes)
        if not reason:
            parts = [f"{got.lost} records failed their checksum"] if got.lost else []
            if got.unknown_bytes:
                parts.append(f"{got.unknown_bytes} bytes had no readable frame header"
                             + (f" (about {guessed} records)" if guessed else ""))
            if not got.header:
                parts.append("its header was broken")
            reason = "; ".join(parts)
        return self.entry(path, reason, suffix=".damaged", records=got.lost + guessed, estimated=estimated,
                          lost_bytes=got.lost_bytes, kept=len(got.rows))

    def entry(self, path: Path, reason: str, *, suffix: str = ".notfile", records: int = 0,
              estimated: bool = False, lost_bytes: int = 0, kept: int | None = None) -> Path:
        """Rename ``path`` out of the spool's way (never deleted), name it in the log and ``damage``."""
        target = path.with_name(path.name + suffix)
        n = 1
        while os.path.lexists(target) and n < 100:
            target = path.with_name(f"{path.name}.{n}{suffix}")
            n += 1
        try:
            os.rename(path, target)
        except OSError as e:
            log.warning("history: cannot set %s aside: %s", path, e.strerror or e)
            target = path
        what = (f"{records} records" + (" (estimated)" if estimated else "")) if records or estimated \
            else "no records"
        if suffix == ".notfile":
            log.error("history: the spool entry %s is not a regular file (%s): not read, moved to %s",
                      path, reason, target.name)
        else:
            log.error("history: the spool segment %s is damaged: %s could not be read (%s); %s "
                      "kept and forwarded; the segment is kept as %s", path, what, reason,
                      "nothing" if not kept else f"{kept} records", target)
        self.items.append({"path": str(path), "keptAs": str(target), "records": records,
                           "estimated": estimated, "bytes": lost_bytes,
                           "reason": reason if suffix != ".notfile" else f"not a regular file ({reason})"})
        del self.items[:-64]  # one per damaged segment: bounded all the same
        return target


def open_lock(path: Path, aside: SetAside) -> IO[bytes]:
    """``lock``, a regular file: a FIFO, a device or a symlink there is set aside (never opened
    blocking: a FIFO without a reader fails ``ENXIO`` at once)."""
    flags = os.O_WRONLY | os.O_CREAT | os.O_APPEND | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC
    for _ in range(3):
        try:
            fd = os.open(path, flags, 0o644)
        except OSError as e:
            if e.errno not in (errno.ELOOP, errno.ENXIO, errno.EISDIR):
                raise
            aside.entry(path, kind(path))
            continue
        if stat.S_ISREG(os.fstat(fd).st_mode):
            return os.fdopen(fd, "ab")
        os.close(fd)
        aside.entry(path, kind(path))
    raise OSError(errno.EEXIST, f"{path} is not a regular file and cannot be set aside")


def kind(path: Path) -> str:
    try:
        mode = os.lstat(path).st_mode
    except OSError:
        return "gone"
    for test, name in ((stat.S_ISLNK, "a symbolic link"), (stat.S_ISFIFO, "a FIFO"),
                       (stat.S_ISSOCK, "a socket"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISDIR, "a folder")):
        if test(mode):
            return name
    return "not a regular file"
