"""A throw-away PostgreSQL cluster for the tests (and the engine benchmark).

Debian's ``postgresql`` package (installed by ``.ci/run``) provides ``initdb``, ``pg_ctl`` and
``postgres`` under ``/usr/lib/postgresql/<version>/bin``. The cluster lives in a temporary
folder, listens on a unix socket there and on 127.0.0.1 (a free port), and is removed at the
end of the session. PostgreSQL refuses to run as root (CI runs as root): then ``initdb`` and
``pg_ctl`` run as the unprivileged user ``postgres`` (the package creates it) through
``runuser``, and the folder is handed to that user.

Contract:
- The binaries missing is a test *failure* naming ``.ci/run``, never a skip.
- ``pg_cluster`` (session) starts one server; ``pg_url`` (per test) creates an empty schema
  in the cluster's ``postgres`` database and returns an SQLAlchemy URL (``postgresql+psycopg://...``)
  whose ``search_path`` is that schema alone, dropped afterwards. To the code under test it is
  an empty database (tables, Alembic's version table, sequences all land in it); a schema takes
  milliseconds where ``CREATE DATABASE`` takes about a second on a busy machine.
- Durability is off in the test cluster (``fsync``, ``synchronous_commit``): tests check
  behaviour, not crash safety of PostgreSQL itself. ``PgCluster(durable=True)`` keeps
  ``fsync`` (the benchmark).

Registered for every test folder (``tests/``, ``directory/tests/``) by the root ``conftest.py``.
"""

from __future__ import annotations

import glob
import itertools
import os
import shutil
import socket
import subprocess
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest

__all__ = ["PgCluster", "PgMissing", "find_bindir", "pg_cluster", "pg_url"]

INSTALL_HINT = ("PostgreSQL server binaries not found (/usr/lib/postgresql/*/bin/initdb): "
                ".ci/run installs them (apt-get install postgresql); install the `postgresql` "
                "package to run the PostgreSQL tests")


class PgMissing(RuntimeError):
    """The PostgreSQL server binaries are not installed."""


def find_bindir() -> Path:
    """The newest ``/usr/lib/postgresql/<v>/bin`` with ``initdb``, or ``$PG_BINDIR``."""
    if os.environ.get("PG_BINDIR"):
        candidates = [os.environ["PG_BINDIR"] + "/initdb"]
    else:
        candidates = sorted(glob.glob("/usr/lib/postgresql/*/bin/initdb"),
                            key=lambda p: int(Path(p).parts[-3]) if Path(p).parts[-3].isdigit() else 0)
    for initdb in reversed(candidates):
        if os.access(initdb, os.X_OK):
            return Path(initdb).parent
    raise PgMissing(INSTALL_HINT)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class PgCluster:
    """One ``initdb``-ed cluster in a temporary folder, started with ``pg_ctl``."""

    def __init__(self, *, durable: bool = False) -> None:
        self.bindir = find_bindir()
        self.durable = durable
        self.as_root = os.geteuid() == 0
        self.user = "postgres" if self.as_root else (os.environ.get("USER") or "postgres")
        self.root = Path(tempfile.mkdtemp(prefix="wott-pg-"))
        self.data = self.root / "data"
        self.port = _free_port()
        self._names = itertools.count(1)
        self.started = False

    def _run(self, *args: str) -> None:
        cmd = [str(self.bindir / args[0]), *args[1:]]
        if self.as_root:
            cmd = ["runuser", "-u", "postgres", "--", *cmd]
        res = subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=False)
        if res.returncode != 0:
            raise RuntimeError(f"{' '.join(cmd)} failed ({res.returncode}): "
                               f"{(res.stderr or res.stdout).strip()[-2000:]}")

    def start(self) -> PgCluster:
        if self.as_root:
            shutil.chown(self.root, "postgres", "postgres")
        self._run("initdb", "-D", str(self.data), "-U", self.user, "--auth=trust", "-E", "UTF8",
                  "--locale=C", "--no-sync")
        opts = [f"-c listen_addresses=127.0.0.1 -c port={self.port}",
                f"-c unix_socket_directories={self.root}", "-c max_connections=200",
                "-c shared_buffers=128MB", "-c synchronous_commit=off"]
        if not self.durable:
            opts += ["-c fsync=off", "-c full_page_writes=off"]
        self._run("pg_ctl", "-D", str(self.data), "-l", str(self.root / "server.log"), "-w",
                  "-t", "60", "-o", " ".join(opts), "start")
        self.started = True
        return self

    def url(self, dbname: str = "postgres", *, tcp: bool = False, schema: str | None = None) -> str:
        """An SQLAlchemy URL (psycopg 3) of ``dbname``: on the unix socket, or 127.0.0.1;
        ``schema``: the only schema on its ``search_path``."""
        query = [] if tcp else [f"host={self.root}", f"port={self.port}"]
        if schema is not None:
            query.append(f"options=-csearch_path%3D{schema}")
        where = f"127.0.0.1:{self.port}" if tcp else ""
        return f"postgresql+psycopg://{self.user}@{where}/{dbname}" + ("?" + "&".join(query) if query else "")

    def _admin(self, sql: str) -> None:
        import psycopg

        with psycopg.connect(host=str(self.root), port=self.port, user=self.user, dbname="postgres",
                             autocommit=True) as conn:
            conn.execute(sql)

    def create_database(self, prefix: str = "t") -> str:
        """A new empty database; returns its name."""
        name = f"{prefix}_{os.getpid()}_{next(self._names)}"
        self._admin(f'CREATE DATABASE "{name}"')
        return name

    def drop_database(self, name: str) -> None:
        self._admin(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)')

    def create_schema(self, prefix: str = "t") -> str:
        """A new empty schema in the ``postgres`` database; returns its name."""
        name = f"{prefix}_{os.getpid()}_{next(self._names)}"
        self._admin(f'CREATE SCHEMA "{name}"')
        return name

    def drop_schema(self, name: str) -> None:
        self._admin(f'DROP SCHEMA IF EXISTS "{name}" CASCADE')

    def stop(self) -> None:
        try:
            if self.started:
                self._run("pg_ctl", "-D", str(self.data), "-m", "immediate", "-w", "stop")
        finally:
            self.started = False
            shutil.rmtree(self.root, ignore_errors=True)


@pytest.fixture(scope="session")
def pg_cluster() -> Iterator[PgCluster]:
    """One PostgreSQL server for the whole session (fails, never skips, without the binaries)."""
    try:
        cluster = PgCluster()
    except PgMissing as e:
        pytest.fail(str(e), pytrace=False)
    try:
        cluster.start()
    except BaseException:
        cluster.stop()
        raise
    yield cluster
    cluster.stop()


@pytest.fixture
def pg_url(pg_cluster: PgCluster) -> Iterator[str]:
    """A fresh empty schema on the session's cluster: an SQLAlchemy URL that sees only it."""
    name = pg_cluster.create_schema()
    yield pg_cluster.url(schema=name)
    try:
        pg_cluster.drop_schema(name)
    except Exception:  # e.g. a lock a test left behind: the cluster goes away at the end anyway
        pass
