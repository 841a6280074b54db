"""A camera's video written by a process of its own: ``CameraVideo``'s work off the export's process.

Why: a camera's frames cost ~11 ms an image (base64 2.6, PNG decode 6.5, x264 ~2 ms here), the rest of
the export ~8 s of CPU a recorded 10 minutes; in one process the video thread waited for the GIL half
its time and the export for the video thread (issue 46: an hour in 106 s, target 60). Here the video
has a core of its own. The child is ``python -m wott_hub.history.learning.video_process`` (not
``multiprocessing``: its spawn re-runs the caller's main module, which breaks a script without a
``__main__`` guard). It reads pickled messages on stdin, each with its length, and answers the ones
that return something on stdout:

- ``("open", (source, root, fps, settings))``: the ``CameraVideo`` it writes;
- ``("begin", frames)`` -> the episode's ``videos/<key>/*`` columns; ``("write", held)``: no answer;
  ``("end", None)`` -> (the columns of its end, its ``ImageStats``); ``("close", None)`` -> None.

A failure of ``write`` is kept and answered at the next message that has an answer, as
``("error", exception)``: the export raises it there, as it did from the video thread. A ``write`` is
sent by a thread of the export (``_sending``) while the export goes on with its next block: the
export waits only if the block before is not sent yet, that is while the child is still working on
the one before that (sent from the export's thread, a block was taken only once the child had
finished the one before it: each side waited for the other's slower blocks). Flow control is the
pipe's: memory stays a block being made and one being sent on the export's side, one on the
child's. The child runs in a process group of its own (a terminal's Ctrl-C reaches its foreground group:
the export, which stops the child; the child interrupted while it started printed a traceback), ignores
SIGINT all the same, and ends when its stdin closes, so it never outlives the export.
"""

from __future__ import annotations

import pickle
import signal
import struct
import subprocess
import sys
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

from wott_hub.errors import WottHubError

if TYPE_CHECKING:
    from .features import CameraSource
    from .resample import Held
    from .stats import ImageStats
    from .video import VideoSettings

__all__ = ["VideoProcess", "VideoProcessEnded"]


class VideoProcessEnded(WottHubError):
    """The child ended (killed, out of memory) or its pipe broke: the export cannot finish its video."""

_LEN = struct.Struct("<Q")
STOP_S = 30.0  # the child's end after close, at most; then it is killed


def _send(stream: IO[bytes], message: Any) -> None:
    data = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(_LEN.pack(len(data)))
    stream.write(data)
    stream.flush()


def _receive(stream: IO[bytes]) -> Any:
    head = stream.read(_LEN.size)
    if len(head) < _LEN.size:
        raise EOFError
    return pickle.loads(stream.read(_LEN.unpack(head)[0]))


class VideoProcess:
    """``CameraVideo``'s interface for ``LeRobotWriter`` (``begin``, ``write``, ``end``, ``stats``,
    ``close``), the work done in a child process (module doc)."""

    def __init__(self, source: CameraSource, root: Path, fps: int, settings: VideoSettings) -> None:
        self.source = source
        self.key = source.features[0].key
        self.height, self.width, _ = source.features[0].shape
        self.settings = settings
        self.stats: ImageStats | None = None
        self._proc: subprocess.Popen[bytes] | None = subprocess.Popen(
            [sys.executable, "-m", __name__], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
            process_group=0)  # a group of its own: a terminal's Ctrl-C is the export's alone
        self._sender = ThreadPoolExecutor(1, thread_name_prefix=f"video-{self.key}")
        self._sending: Future[None] | None = None  # the message being sent (at most one)
        self._call("open", (source, root, fps, settings), answer=False)

    def _sent(self) -> None:
        """Wait for the message being sent (its OSError if the pipe broke)."""
        if self._sending is not None:  # kept until sent: a Ctrl-C here leaves it for ``close``
            self._sending.result()
            self._sending = None

    def _call(self, kind: str, body: Any, *, answer: bool = True) -> Any:
        """Send a message; its answer if it has one. One without an answer is sent by the sending
        thread (module doc): this returns once the message before it is sent."""
        proc = self._proc
        assert proc is not None and proc.stdin is not None and proc.stdout is not None
        try:
            self._sent()
            if not answer:
                self._sending = self._sender.submit(_send, proc.stdin, (kind, body))
                return None
            _send(proc.stdin, (kind, body))
            status, value = _receive(proc.stdout)
        except (OSError, EOFError, pickle.UnpicklingError):
            raise VideoProcessEnded(f"the video process of {self.key} ended (exit code {proc.poll()})"
                                    ) from None
        if status == "error":
            raise value
        return value

    def begin(self, frames: int) -> dict[str, Any]:
        out: dict[str, Any] = self._call("begin", frames)
        return out

    def write(self, held: Held) -> None:
        self._call("write", held, answer=False)

    def end(self) -> dict[str, Any]:
        columns, self.stats = self._call("end", None)
        return columns  # type: ignore[no-any-return]

    def close(self) -> None:
        """The last file closed and the child ended (killed if it does not end in ``STOP_S``). A child
        already gone (an export stopped mid-message, by Ctrl-C) is only waited for: nothing to close."""
        proc = self._proc
        if proc is None:
            return
        try:
            if proc.poll() is None:
                self._call("close", None)
        except VideoProcessEnded:
            pass
        finally:
            self._proc = None
            assert proc.stdin is not None and proc.stdout is not None
            try:  # a message still being sent (Ctrl-C while sending): the child reads it, or is gone
                self._sent()
            except OSError:
                pass
            self._sender.shutdown()
            try:
                proc.stdin.close()
            except OSError:  # a broken pipe's unflushed bytes
                pass
            try:
                proc.wait(STOP_S)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
            proc.stdout.close()


def main() -> None:
    """The child: a ``CameraVideo`` driven by the messages on stdin (module doc)."""
    from .video import CameraVideo

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    inp, out = sys.stdin.buffer, sys.stdout.buffer
    video: CameraVideo | None = None
    failed: BaseException | None = None
    while True:
        try:
            kind, body = _receive(inp)
        except Exception:  # noqa: BLE001 - the end of stdin, or a message cut by the export's stop
            break
        try:
            if kind == "open":
                video = CameraVideo(*body)
            elif kind == "write":
                assert video is not None
                if failed is None:
                    video.write(body)
                continue
            elif failed is not None and kind != "close":
                raise failed
            elif kind == "begin":
                assert video is not None
                _send(out, ("ok", video.begin(body)))
            elif kind == "end":
                assert video is not None
                _send(out, ("ok", (video.end(), video.stats)))
            elif kind == "close":
                if video is not None:
                    video.close()
                _send(out, ("ok", None))
                break
        except BaseException as e:  # noqa: BLE001 - answered to the export, which raises it
            if kind in ("open", "write"):
                failed = e
            else:
                _send(out, ("error", e))
                if kind == "close":
                    break


if __name__ == "__main__":
    main()
