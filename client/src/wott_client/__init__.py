"""wott-client: Tactile WoT Things in Python, the mesh and every frame as NumPy arrays.

Consumes any Tactile Thing Description (a wott-hub's or another server's) by
reading its forms; streams ``skinDeformedDetection`` packets as dense per-node
fields, ``skinDisplacement`` packets as node ids and N x 3 float32 vectors (from the
binary form, no JSON), ``contactInformation`` and ``actionDetection`` as dataclasses;
reads raw images (H x W x C uint8) and pressure grids, history ranges as arrays,
invokes actions; resumes each stream with ``Last-Event-ID`` after a disconnect.
``AsyncClient`` is the core; ``Client`` runs it on a background thread for blocking code.
"""

from ._client import AsyncClient
from ._directory import AsyncDirectory
from ._errors import ClientError, InvalidTD, NotFound, TransportError
from ._fields import Displacement, PacketParser
from ._frames import Action, ActionDetails, Contacts, Frame, Item, ProtocolError
from ._history import AsyncHistory, FieldRange
from ._mdns import Resolved, async_resolve
from ._sse import Message, SSEParser
from ._stream import ResumableStream
from ._sync import Client, Directory, History, Thing
from ._td import Mesh, parse_mesh
from ._thing import AsyncThing

__all__ = [
    "Action",
    "ActionDetails",
    "AsyncClient",
    "AsyncDirectory",
    "AsyncHistory",
    "AsyncThing",
    "Client",
    "ClientError",
    "Contacts",
    "Directory",
    "Displacement",
    "FieldRange",
    "Frame",
    "History",
    "InvalidTD",
    "Item",
    "Mesh",
    "Message",
    "NotFound",
    "PacketParser",
    "ProtocolError",
    "ResumableStream",
    "SSEParser",
    "Thing",
    "TransportError",
    "Resolved",
    "async_resolve",
    "parse_mesh",
]
