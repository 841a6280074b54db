"""The client's one exception tree.

The client installs without the hub, so it cannot raise ``wott_hub.errors``; its
classes mirror that tree's meanings (a TD that does not say what we need is
``InvalidTD``, a name nobody answers for is ``NotFound``) under one root, and
httpx's own errors are translated where they happen (``_http.py``).
"""

from __future__ import annotations

__all__ = ["ClientError", "InvalidTD", "NotFound", "TransportError"]


class ClientError(Exception):
    """Root of every error the client raises."""


class InvalidTD(ClientError):
    """A Thing Description lacks what the client needs (a form, a Tactile property), named in the message."""


class NotFound(ClientError):
    """A URL, directory entry or mDNS name that does not lead to a Thing."""


class TransportError(ClientError):
    """The server could not be reached or answered with an error status."""
