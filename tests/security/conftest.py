"""A client that is not on loopback: a network namespace joined to the host by a veth pair.

The namespace and both ends of the pair are made by the fixture (root is available
in CI) and removed after the tests: addresses in 10.231.k.0/30 (k: the pytest-xdist worker's
number, so that workers running at once never share a subnet), traffic only between the host
end (the hub binds it) and the namespace (the clients run there with ``ip netns exec``). The
hub is the real ``wott-hub run`` in a subprocess, so its start-up refusal, its logs and its
history database are the ones a user gets.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
WORKER = int(os.environ.get("PYTEST_XDIST_WORKER", "gw0").removeprefix("gw"))
"""This process's pytest-xdist worker (0 without xdist): its subnet and its namespace's name."""
HOST_IP = f"10.231.{WORKER}.1"
NS_IP = f"10.231.{WORKER}.2"
WOTT_HUB = str(Path(sys.executable).with_name("wott-hub"))


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], capture_output=True, text=True, check=check)


def _remove_stale() -> None:
    """Namespaces of a test run that was killed before its clean-up: their host end holds an address
    this run may need, and the kernel would route this run's packets to it (every request from the
    namespace fails). A name is ``wottsec<run>x<worker>``; the run's own are left to its workers."""
    for line in _ip("netns", "list", check=False).stdout.splitlines():
        name = line.split()[0] if line.strip() else ""
        run, _, worker = name[7:].partition("x")
        ours = name.startswith("wottsec") and run.isdigit() and (worker.isdigit() or not worker)
        if ours and not _alive(int(run)):
            _ip("link", "del", f"wsh{name[7:]}", check=False)
            _ip("netns", "del", name, check=False)


def _run_tag() -> int:
    """The pytest run's pid modulo 100,000: the controller's under pytest-xdist (a worker's own command
    line does not say pytest), else this process's."""
    return (os.getppid() if "PYTEST_XDIST_WORKER" in os.environ else os.getpid()) % 100000


def _alive(tag: int) -> bool:
    """Whether a process whose pid ends in ``tag`` (the pid modulo 100,000) still runs pytest."""
    for pid in (p for p in os.listdir("/proc") if p.isdigit() and int(p) % 100000 == tag):
        try:
            if b"pytest" in Path(f"/proc/{pid}/cmdline").read_bytes():
                return True
        except OSError:
            continue
    return False


@pytest.fixture(scope="session")
def netns():
    """(namespace name, the host end's address). Fails, never skips, without iproute2 or root.
    Session-scoped: made once however a shuffled order interleaves this package with others."""
    assert shutil.which("ip"), "iproute2 is needed (apt-get install iproute2)"
    _remove_stale()
    tag = f"{_run_tag()}x{WORKER}"
    ns, host_if, ns_if = f"wottsec{tag}", f"wsh{tag}", f"wsn{tag}"
    _ip("netns", "add", ns)
    try:
        _ip("link", "add", host_if, "type", "veth", "peer", "name", ns_if)
        _ip("link", "set", ns_if, "netns", ns)
        _ip("addr", "add", f"{HOST_IP}/30", "dev", host_if)
        _ip("link", "set", host_if, "up")
        _ip("netns", "exec", ns, "ip", "addr", "add", f"{NS_IP}/30", "dev", ns_if)
        _ip("netns", "exec", ns, "ip", "link", "set", ns_if, "up")
        _ip("netns", "exec", ns, "ip", "link", "set", "lo", "up")
        yield ns, HOST_IP
    finally:
        _ip("link", "del", host_if, check=False)
        _ip("netns", "del", ns, check=False)


def in_ns(ns: str, requests: list[dict]) -> dict:
    """Make ``requests`` from inside the namespace (``nsclient.py``)."""
    out = subprocess.run(["ip", "netns", "exec", ns, sys.executable, str(HERE / "nsclient.py"),
                          json.dumps(requests)], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


class HubProcess:
    """``wott-hub run --json`` in a subprocess: its describe() line, its log, then a clean stop."""

    def __init__(self, args: list[str], cwd: Path) -> None:
        self.log_path = cwd / "hub.log"
        self.log = self.log_path.open("w")
        self.proc = subprocess.Popen([WOTT_HUB, "run", "--json", "--log-level", "info", *args], cwd=cwd,
                                     stdout=subprocess.PIPE, stderr=self.log, text=True)
        line = self.proc.stdout.readline()
        if not line:
            self.proc.wait(10)
            raise AssertionError(f"the hub did not start: {self.log_path.read_text()[-2000:]}")
        self.info = json.loads(line)

    def stop(self) -> None:
        self.proc.terminate()
        try:
            self.proc.wait(20)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        self.log.close()


def wait_for(pred, timeout: float = 10.0, every: float = 0.1):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        got = pred()
        if got:
            return got
        time.sleep(every)
    raise AssertionError("timed out")
