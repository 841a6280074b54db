"""A W3C WoT Thing Description Directory (WoT Discovery HTTP API) on tornado and SQLAlchemy.

Embed it in a tornado application::

    directory = Directory(DirectorySettings(base_url="http://hub:8080/tdd/", token=...), engine)
    await directory.start()
    app.add_handlers(r".*", directory_handlers(directory, prefix="/tdd"))

or run it alone with ``wott-directory`` (see ``wott_directory.cli``). Producers
register and refresh their TDs with ``Registrar``; clients use ``DirectoryClient``.
"""

from .client import DirectoryClient, ProblemError, Registrar, SSEEvent
from .directory import Directory
from .errors import DirectoryError
from .handlers import directory_handlers, make_app
from .models import create_schema
from .server import DirectoryServer
from .settings import ConfigError, DirectorySettings

__all__ = [
    "ConfigError", "Directory", "DirectoryClient", "DirectoryError", "DirectoryServer", "DirectorySettings",
    "ProblemError", "Registrar", "SSEEvent", "create_schema", "directory_handlers", "make_app",
]
