"""A W3C WoT Thing Description Directory (WoT Discovery HTTP API) on tornado and SQLAlchemy.

Embed it in a tornado application::

    directory = Directory(DirectorySettings(base_url="http://hub:8080/tdd/", token=...), engine)
    await directory.start()
    app.add_handlers(r".*", directory_handlers(directory, prefix="/tdd"))

or run it alone with ``wott-directory`` (see ``wott_directory.cli``). Producers
register and refresh their TDs with ``Registrar``; clients use ``DirectoryClient``.
"""

from importlib import import_module
from typing import Any

# The public names, loaded on first use: ``wott_directory.validation`` (the W3C TD schema,
# used by ``wott-hub td validate``) must not pull in tornado and SQLAlchemy with the package.
_EXPORTS = {
    "DirectoryClient": ".client", "ProblemError": ".client", "Registrar": ".client", "SSEEvent": ".client",
    "Directory": ".directory", "DirectoryError": ".errors", "directory_handlers": ".handlers",
    "make_app": ".handlers", "create_schema": ".models", "DirectoryServer": ".server",
    "ConfigError": ".settings", "DirectorySettings": ".settings",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name not in _EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(_EXPORTS[name], __name__), name)
    globals()[name] = value
    return value
