"""``--stress N``: the recordings made beside ``stress-ng --cpu N`` (a robot's computer is never idle).

The CPU burners start before the first recording and are stopped (SIGTERM to their process group,
then SIGKILL) when the recordings are done, whatever happened: they never outlive the bench.
Processing and scoring run after them (what is scored is what a busy machine recorded: the frames
it read late, merged or missed, with the time stamps it gave them).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import time
from collections.abc import Iterator

__all__ = ["stress"]


@contextlib.contextmanager
def stress(workers: int) -> Iterator[None]:
    """``stress-ng --cpu workers`` for the duration of the block (nothing for 0)."""
    if workers <= 0:
        yield
        return
    exe = shutil.which("stress-ng")
    if exe is None:
        raise SystemExit("bench accuracy: --stress needs stress-ng on the PATH (apt-get install stress-ng)")
    # --timeout: even a bench killed outright leaves no burner behind for long
    proc = subprocess.Popen([exe, "--cpu", str(workers), "--timeout", "3600s", "--quiet"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        time.sleep(0.5)  # its workers running before the first frame
        if proc.poll() is not None:
            raise SystemExit(f"bench accuracy: stress-ng --cpu {workers} exited with {proc.returncode}")
        yield
    finally:
        _stop(proc)


def _stop(proc: subprocess.Popen[bytes]) -> None:
    for sig, wait in ((signal.SIGTERM, 5.0), (signal.SIGKILL, 5.0)):
        if proc.poll() is not None:
            return
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, sig)
        with contextlib.suppress(subprocess.TimeoutExpired):
            proc.wait(wait)
