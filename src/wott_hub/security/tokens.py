"""Bearer tokens: their format, how they are hashed and stored, and how one is verified.

A token is ``wott_<id>_<secret>``: ``id`` (8 hex digits) is public and names the
stored entry, so verifying a presented token costs one lookup and one hash, never a
scan; ``secret`` (32 random bytes, URL-safe base64) is shown once, when the token is
created, and never stored: the store keeps ``scrypt`` of it with a per-token salt,
compared in constant time.

A verified token is remembered (keyed by a keyed BLAKE2b of the whole token, in
memory only) so scrypt runs once per token, not once per request; the memory is
dropped whenever the store changes (a token revoked in the file stops working
within a second, without restarting the hub).
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import json
import os
import secrets
import threading
import time
from collections.abc import Iterable
from dataclasses import asdict, dataclass
from pathlib import Path

from wott_hub.errors import ConfigError, Conflict, InvalidInput, NotFound

from .scopes import Scope

__all__ = ["PREFIX", "StoredToken", "TokenFile", "TokenStore", "hash_secret", "new_token", "split_token"]

PREFIX = "wott"
_SCRYPT = {"n": 2**14, "r": 8, "p": 1}
_NAME_CHARS = set("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789._-")
_RELOAD_EVERY_S = 1.0
_CACHE_MAX = 4096


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
            data = json.loads(self.path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            return []
        except OSError as e:
            raise ConfigError(f"{self.path}: cannot read the token file: {e.strerror or e}") from None
        except ValueError as e:
            raise ConfigError(f"{self.path}: not a token file (JSON): {e}") from None
        try:
            out = [StoredToken(**entry) for entry in data["tokens"]]
            for t in out:
                t.scope_level  # noqa: B018 -- a bad scope is a ConfigError now, not at the first request
        except (KeyError, TypeError, InvalidInput) as e:
            raise ConfigError(f"{self.path}: not a token file: {e}") from None
        return out

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
        self._stamp: tuple[float, int] | None = None
        self._checked = 0.0
        self._verified: dict[bytes, StoredToken] = {}
        self._key = os.urandom(32)
        self._lock = threading.Lock()
        self._reload(force=True)

    def __len__(self) -> int:
        return len(self._by_id)

    def _file_stamp(self) -> tuple[float, int] | None:
        try:
            st = self.file.path.stat() if self.file is not None else None
        except OSError:
            return None
        return (st.st_mtime, st.st_size) if st is not None else None

    def _reload(self, force: bool = False) -> None:
        now = time.monotonic()
        if not force and now - self._checked < _RELOAD_EVERY_S:
            return
        self._checked = now
        stamp = self._file_stamp()
        if not force and stamp == self._stamp:
            return
        entries = list(self.clients) + (self.file.load() if self.file is not None else [])
        with self._lock:
            self._by_id = {t.id: t for t in entries}
            self._verified.clear()
            self._stamp = stamp

    def verify(self, token: str) -> StoredToken | None:
        """The stored entry ``token`` proves, or None (malformed, unknown, revoked or wrong)."""
        self._reload()
        key = hashlib.blake2b(token.encode(), key=self._key, digest_size=32).digest()
        hit = self._verified.get(key)
        if hit is not None:
            return hit
        parts = split_token(token)
        if parts is None:
            return None
        stored = self._by_id.get(parts[0])
        if stored is None or not _verify_hash(parts[1], stored.hash):
            return None
        with self._lock:
            if len(self._verified) >= _CACHE_MAX:
                self._verified.clear()
            self._verified[key] = stored
        return stored
