"""Bearer tokens: their format, how they are hashed and stored, and how one is verified.

A token is ``wott_<id>_<secret>``: ``id`` (8 hex digits) is public and names the
stored entry, so verifying a presented token costs one lookup and one hash, never a
scan; ``secret`` (32 random bytes, URL-safe base64) is shown once, when the token is
created, and never stored: the store keeps ``scrypt`` of it with a per-token salt,
compared in constant time.

A verified token is remembered (keyed by a keyed BLAKE2b of the whole token, in
memory only) so scrypt runs once per token, not once per request; a wrong one is
remembered as wrong the same way (bounded); both memories are dropped whenever the
store changes (a token revoked in the file stops working within a second, without
restarting the hub).

What a check costs, and where it runs (docs/security.md, "What a token check costs"):

- ``verify_async`` (what the gate calls) runs scrypt on a thread of its own
  (``hashlib.scrypt`` releases the GIL), never on the event loop that carries every
  device's frames; at most ``MAX_PENDING_CHECKS`` checks wait for it, beyond that
  ``TooManyChecks`` (the gate answers 503 with ``Retry-After``). Concurrent checks of
  one token share one hash.
- An unknown id costs what a known one does: its secret is hashed against a dummy
  entry with the same parameters, so the time of an answer says nothing about which
  ids exist (no id oracle). A malformed token (the format is public) is refused
  without hashing.

Reloading the file is atomic: a file that cannot be read or parsed while the hub
runs (half written by an editor, a stray character) leaves the last good set in
force, is reported once per version of the file (a warning, no traceback) and is
read again a second later.
"""

from __future__ import annotations

import asyncio
import base64
import hashlib
import hmac
import json
import logging
import os
import secrets
import stat
import threading
import time
from collections.abc import Iterable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path

from wott_hub.errors import ConfigError, Conflict, InvalidInput, NotFound, WottHubError

from .scopes import Scope

__all__ = ["MAX_PENDING_CHECKS", "MAX_TOKEN_FILE_BYTES", "PREFIX", "StoredToken", "TokenFile", "TokenStore",
           "TooManyChecks", "hash_secret", "new_token", "split_token"]

log = logging.getLogger("wott_hub.security")

PREFIX = "wott"
_SCRYPT = {"n": 2**14, "r": 8, "p": 1}
_NAME_CHARS = set("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789._-")
_RELOAD_EVERY_S = 1.0
_CACHE_MAX = 4096
MAX_PENDING_CHECKS = 16
"""Token checks (scrypt) waiting for the checking thread at most; more are refused at once."""
MAX_TOKEN_FILE_BYTES = 4 * 1024 * 1024
"""A token file is a few hundred bytes per token; anything larger is not one."""


class TooManyChecks(WottHubError):
    """``MAX_PENDING_CHECKS`` token checks are already waiting: this one is refused, not queued (the
    gate answers 503 with ``Retry-After``), so a flood of wrong secrets costs a bounded queue."""


@dataclass(frozen=True)
class StoredToken:
    """What the hub keeps of a token: never its secret."""

    id: str
    name: str
    scope: str
    hash: str
    created: str = ""

    @property
    def scope_level(self) -> Scope:
        return Scope.parse(self.scope)


def _b64(raw: bytes) -> str:
    return base64.urlsafe_b64encode(raw).decode().rstrip("=")


def _unb64(text: str) -> bytes:
    return base64.urlsafe_b64decode(text + "=" * (-len(text) % 4))


def hash_secret(secret: str, salt: bytes | None = None) -> str:
    """``scrypt$n$r$p$salt$digest``, all needed to verify ``secret`` later."""
    salt = salt or os.urandom(16)
    digest = hashlib.scrypt(secret.encode(), salt=salt, dklen=32, maxmem=64 * 1024 * 1024, **_SCRYPT)
    return f"scrypt${_SCRYPT['n']}${_SCRYPT['r']}${_SCRYPT['p']}${_b64(salt)}${_b64(digest)}"


def _verify_hash(secret: str, stored: str) -> bool:
    try:
        kind, n, r, p, salt, digest = stored.split("$")
        if kind != "scrypt":
            return False
        got = hashlib.scrypt(secret.encode(), salt=_unb64(salt), n=int(n), r=int(r), p=int(p), dklen=32,
                             maxmem=64 * 1024 * 1024)
    except (ValueError, TypeError):
        return False
    return hmac.compare_digest(got, _unb64(digest))


def new_token(name: str, scope: Scope) -> tuple[str, StoredToken]:
    """A fresh token (shown once) and what is stored of it."""
    check_name(name)
    tid = secrets.token_hex(4)
    secret = secrets.token_urlsafe(32)
    stored = StoredToken(tid, name, str(scope), hash_secret(secret),
                         time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()))
    return f"{PREFIX}_{tid}_{secret}", stored


def split_token(token: str) -> tuple[str, str] | None:
    """``(id, secret)`` of a well-formed token, else None."""
    parts = token.strip().split("_", 2)
    if len(parts) != 3 or parts[0] != PREFIX or len(parts[1]) != 8 or not parts[2]:
        return None
    return parts[1], parts[2]


def check_name(name: str) -> str:
    if not name or len(name) > 64 or set(name) - _NAME_CHARS:
        raise InvalidInput(f"token name: 1 to 64 letters, digits, '.', '_' or '-', got {name!r}")
    return name


class TokenFile:
    """A JSON file of hashed tokens (``wott-hub tokens create --file``), written atomically, mode 0600."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)

    def load(self) -> list[StoredToken]:
        try:
            data = json.loads(self._read())
        except FileNotFoundError:
            return []
        except OSError as e:
            raise ConfigError(f"{self.path}: cannot read the token file: {e.strerror or e}") from None
        except ValueError as e:
            raise ConfigError(f"{self.path}: not a token file (JSON): {e}") from None
        if not isinstance(data, dict):
            raise ConfigError(f"{self.path}: not a token file: a JSON object with 'tokens' is expected")
        try:
            out = [StoredToken(**entry) for entry in data["tokens"]]
            for t in out:
                t.scope_level  # noqa: B018 -- a bad scope is a ConfigError now, not at the first request
        except (KeyError, TypeError, InvalidInput) as e:
            raise ConfigError(f"{self.path}: not a token file: {e}") from None
        return out

    def _read(self) -> str:
        """The file's text; a FIFO, a device or a file larger than ``MAX_TOKEN_FILE_BYTES`` is refused
        without blocking (opened non-blocking, checked before reading)."""
        fd = os.open(self.path, os.O_RDONLY | os.O_NONBLOCK)
        with os.fdopen(fd, "rb") as f:
            st = os.fstat(fd)
            if not stat.S_ISREG(st.st_mode):
                raise ConfigError(f"{self.path}: not a token file: not a regular file")
            raw = f.read(MAX_TOKEN_FILE_BYTES + 1)
        if len(raw) > MAX_TOKEN_FILE_BYTES:
            raise ConfigError(f"{self.path}: not a token file: larger than {MAX_TOKEN_FILE_BYTES} bytes")
        return raw.decode("utf-8")

    def save(self, tokens: Iterable[StoredToken]) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.path.with_name(self.path.name + ".tmp")
        text = json.dumps({"tokens": [asdict(t) for t in tokens]}, indent=1)
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text + "\n")
        os.replace(tmp, self.path)

    def create(self, name: str, scope: Scope) -> tuple[str, StoredToken]:
        tokens = self.load()
        if any(t.name == name for t in tokens):
            raise Conflict(f"a token named {name!r} exists in {self.path}; revoke it first or choose "
                           "another name")
        token, stored = new_token(name, scope)
        self.save([*tokens, stored])
        return token, stored

    def revoke(self, name: str) -> StoredToken:
        tokens = self.load()
        gone = [t for t in tokens if t.name == name]
        if not gone:
            raise NotFound(f"no token named {name!r} in {self.path}")
        self.save([t for t in tokens if t.name != name])
        return gone[0]


class TokenStore:
    """Every token the hub accepts: the ``[[security.client]]`` entries and the token file's."""

    def __init__(self, clients: Iterable[StoredToken] = (), file: str | Path | None = None) -> None:
        self.clients = list(clients)
        self.file = TokenFile(file) if file is not None else None
        self._by_id: dict[str, StoredToken] = {}
        self._stamp: tuple[int, int, int] | None = None
        self._bad_stamp: tuple[int, int, int] | None = None  # a file version that failed: reported once
        self._checked = 0.0
        self._verified: dict[bytes, StoredToken] = {}
        self._refused: set[bytes] = set()  # tokens checked and found wrong (until the store changes)
        self._key = os.urandom(32)
        self._lock = threading.Lock()
        # an unknown id is hashed against this: the same parameters, so the same cost as a known one
        self._dummy = hash_secret(secrets.token_urlsafe(32))
        self._checks: dict[bytes, asyncio.Future[StoredToken | None]] = {}
        self._executor: ThreadPoolExecutor | None = None
        self.refusals = 0  # checks refused for ``MAX_PENDING_CHECKS``
        self._reload(force=True)

    def __len__(self) -> int:
        return len(self._by_id)

    def _file_stamp(self) -> tuple[int, int, int] | None:
        try:
            st = self.file.path.stat() if self.file is not None else None
        except OSError:
            return None
        return (st.st_ino, st.st_mtime_ns, st.st_size) if st is not None else None

    def _reload(self, force: bool = False) -> None:
        """Read the file again when it changed (checked at most once a second). At start a bad file
        is a ``ConfigError``; later it keeps the last good set (module docstring)."""
        now = time.monotonic()
        if not force and now - self._checked < _RELOAD_EVERY_S:
            return
        self._checked = now
        stamp = self._file_stamp()
        if not force and stamp == self._stamp:
            return
        try:
            entries = list(self.clients) + (self.file.load() if self.file is not None else [])
        except ConfigError as e:
            if force:
                raise
            if stamp != self._bad_stamp:
                self._bad_stamp = stamp
                log.warning("%s; keeping the %d token(s) loaded before (read again in %g s)", e,
                            len(self._by_id), _RELOAD_EVERY_S)
            return
        with self._lock:
            self._by_id = {t.id: t for t in entries}
            self._verified.clear()
            self._refused.clear()
            self._stamp = stamp
            self._bad_stamp = None

    def _key_of(self, token: str) -> bytes:
        return hashlib.blake2b(token.encode(), key=self._key, digest_size=32).digest()

    def _remember(self, key: bytes, stored: StoredToken | None) -> None:
        with self._lock:
            if stored is None:
                if len(self._refused) >= _CACHE_MAX:
                    self._refused.clear()
                self._refused.add(key)
                return
            if len(self._verified) >= _CACHE_MAX:
                self._verified.clear()
            self._verified[key] = stored

    def known(self, token: str) -> tuple[bool, StoredToken | None]:
        """``(True, entry or None)`` when ``token``'s answer needs no hash (remembered, or malformed);
        ``(False, None)`` when it must be checked (``verify_async``)."""
        self._reload()
        if split_token(token) is None:
            return True, None
        key = self._key_of(token)
        hit = self._verified.get(key)
        if hit is not None:
            return True, hit
        return (key in self._refused), None

    def _check(self, token: str) -> StoredToken | None:
        """The hash itself (scrypt): against the entry of the token's id, or the dummy one."""
        parts = split_token(token)
        if parts is None:
            return None
        stored = self._by_id.get(parts[0])
        good = _verify_hash(parts[1], stored.hash if stored is not None else self._dummy)
        return stored if good and stored is not None else None

    def verify(self, token: str) -> StoredToken | None:
        """The stored entry ``token`` proves, or None (malformed, unknown, revoked or wrong). Hashes
        in the calling thread: the hub's servers use ``verify_async``."""
        done, stored = self.known(token)
        if done:
            return stored
        stored = self._check(token)
        self._remember(self._key_of(token), stored)
        return stored

    async def verify_async(self, token: str) -> StoredToken | None:
        """``verify`` with the hash on the checking thread; ``TooManyChecks`` when
        ``MAX_PENDING_CHECKS`` are already waiting."""
        done, stored = self.known(token)
        if done:
            return stored
        key = self._key_of(token)
        pending = self._checks.get(key)
        if pending is None:
            if len(self._checks) >= MAX_PENDING_CHECKS:
                self.refusals += 1
                raise TooManyChecks(f"{MAX_PENDING_CHECKS} token checks are already waiting; "
                                    "try again in a second")
            if self._executor is None:
                self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="wott-token-check")
            loop = asyncio.get_running_loop()
            pending = self._checks[key] = loop.create_future()
            by_id = self._by_id
            try:
                stored = await loop.run_in_executor(self._executor, self._check, token)
            except BaseException as e:
                del self._checks[key]
                pending.set_exception(e)
                pending.exception()  # retrieved: the waiters (if any) re-raise it
                raise
            del self._checks[key]
            if by_id is self._by_id:  # not reloaded meanwhile: the answer is still the store's
                self._remember(key, stored)
            pending.set_result(stored)
            return stored
        return await asyncio.shield(pending)
