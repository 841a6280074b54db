"""The hub's one error tree: every error the hub raises on purpose derives from ``WottHubError``.

Why one root: an embedding program, the HTTP routes and the CLI each catch
``WottHubError`` once and translate it, in one place each (``HTTP_STATUS`` /
``http_status`` for the servient, ``EXIT_CODES`` / ``exit_code`` for the CLI),
instead of re-mapping the same class to different meanings at every call site.
Anything else that escapes is a bug, reported as such.

Subclasses also derive from the built-in they replace (``ValueError`` for bad
input, ``LookupError`` for a missing thing) so ``except ValueError`` written
before the tree existed keeps working. The errors of the pure domain (a bad
mesh, frame or material in ``tactile/``) and of a scene file are ``InvalidInput``
subclasses defined beside the code that raises them; a test (tests/test_errors.py)
keeps every public exception class of the package, and of the first-party
plugins, inside the tree.

``DriverError`` is a device that cannot be opened or run; a device whose table or
settings are wrong is a ``SettingsError``: a ``ConfigError`` (the person who wrote
them must change them: 400, exit 2) that is also a ``DriverError``, because that
is what ``except DriverError`` written before the two were told apart (plugins,
embedding programs) catches around opening a device.

This module imports nothing of the hub: every layer, the pure domain in
``tactile/`` included, may import it.
"""

from __future__ import annotations

__all__ = [
    "EXIT_CODES",
    "HTTP_STATUS",
    "Busy",
    "ConfigError",
    "Conflict",
    "DriverError",
    "HistoryError",
    "InvalidInput",
    "NotFound",
    "RecordRefused",
    "SettingsError",
    "WorkerDied",
    "WottHubError",
    "exit_code",
    "http_status",
]


class WottHubError(Exception):
    """The root: an error the hub reports with a message meant for a person."""


class InvalidInput(WottHubError, ValueError):
    """Input that can never be right as given (a frame with NaN, a bad mesh, a bad scene step)."""


class ConfigError(InvalidInput):
    """A configuration file, table or key is wrong; the message names file, table and key."""


class NotFound(WottHubError, LookupError):
    """Something asked for by name does not exist (a device, a recorded Thing, a replay)."""


class Conflict(WottHubError):
    """The request clashes with the current state (an id already served, a database in use)."""


class Busy(WottHubError):
    """The hub is doing as much of this as it allows at once (e.g. history exports): try again later."""


class DriverError(WottHubError):
    """A device cannot be opened or run at all (model contract mismatch, no port, a plugin's bug)."""


class SettingsError(ConfigError, DriverError):
    """A device's ``[[device]]`` table or settings are wrong (a key missing, an unknown family, a value
    out of bounds); the message names the device, family and setting."""


class WorkerDied(DriverError):
    """A device's worker process (``[hub] workers``) exited: its devices stopped, and what was asked of
    them there fails. A ``DriverError`` (422, exit 5): to whoever asked, the device cannot run now,
    whichever process it ran in; the class says why, for a program that handles it apart."""


class HistoryError(WottHubError):
    """The history database cannot be used (unknown URL scheme, newer schema, corrupted file)."""


class RecordRefused(HistoryError):
    """The history database refused a record's data (a duplicate seq, a value out of range, a Thing
    never registered): writing the same record again can never succeed."""


# The one translation table for each audience; the most specific class listed wins.
HTTP_STATUS: dict[type[WottHubError], int] = {
    InvalidInput: 400,
    NotFound: 404,
    Conflict: 409,
    Busy: 503,
    DriverError: 422,
    HistoryError: 503,
    WottHubError: 500,
}

EXIT_CODES: dict[type[WottHubError], int] = {
    ConfigError: 2,
    InvalidInput: 2,
    NotFound: 3,
    Conflict: 4,
    Busy: 4,
    DriverError: 5,
    HistoryError: 6,
    WottHubError: 1,
}


def _lookup(table: dict[type[WottHubError], int], exc: WottHubError) -> int:
    for cls in type(exc).__mro__:
        if cls in table:
            return table[cls]
    return table[WottHubError]


def http_status(exc: WottHubError) -> int:
    """The HTTP status a route answers for ``exc`` (with a problem+json body naming it)."""
    return _lookup(HTTP_STATUS, exc)


def exit_code(exc: WottHubError) -> int:
    """The exit code ``wott-hub`` ends with for ``exc`` (after one line on stderr)."""
    return _lookup(EXIT_CODES, exc)
