"""What the client reads from a Thing Description: forms chosen by ``op``, and the mesh.

Nothing here knows a server's URL layout. A form is chosen by its operation
(``readproperty``, ``observeproperty``, ``subscribeevent``, and the Thing-level
``subscribeallevents`` / ``observeallproperties``), its protocol (HTTP, SSE for
streams) and resolved against the TD's ``base`` or, without one, the URL the TD
came from; so a TD from another server works as well as the hub's.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any
from urllib.parse import quote, urljoin

import numpy as np

from ._errors import InvalidTD

__all__ = ["Form", "Mesh", "find_form", "is_tactile", "parse_mesh"]


@dataclass(frozen=True)
class Form:
    href: str  # absolute (a URI template's variables, if any, still in it: ``expand``)
    ops: tuple[str, ...]
    subprotocol: str | None
    content_type: str = "application/json"

    def expand(self, **variables: Any) -> str:
        """The href with its URI template expanded (RFC 6570 ``{?a,b}`` and ``{&a}``; None: left out)."""
        href = self.href
        while "{" in href:
            start = href.index("{")
            end = href.index("}", start)
            expr = href[start + 1:end]
            op, names = (expr[0], expr[1:]) if expr[:1] in "?&" else ("", expr)
            pairs = [(k, variables[k]) for k in names.split(",") if variables.get(k) is not None]
            if op:
                text = "&".join(f"{k}={quote(str(v), safe='')}" for k, v in pairs)
                text = (op + text) if text else ""
            else:
                text = ",".join(quote(str(v), safe="") for _, v in pairs)
            href = href[:start] + text + href[end + 1:]
        return href


def _forms(td: dict[str, Any], holder: dict[str, Any], url: str | None) -> list[Form]:
    base = td.get("base") or url or ""
    out = []
    for f in holder.get("forms") or []:
        if not isinstance(f, dict) or "href" not in f:
            continue
        op = f.get("op") or []
        ops = (op,) if isinstance(op, str) else tuple(op)
        out.append(Form(urljoin(base, f["href"]), ops, f.get("subprotocol"),
                        str(f.get("contentType") or "application/json")))
    return out


def find_form(td: dict[str, Any], op: str, kind: str | None = None, name: str | None = None,
              url: str | None = None, stream: bool = False, content_type: str | None = None,
              subprotocol: str | None = None) -> Form | None:
    """The first HTTP form for ``op`` (of affordance ``kind``/``name``, or of the Thing when ``kind`` is
    None); ``stream``: an SSE one (``subprotocol: sse``); ``content_type``: of that media type (without
    it, any but the binary ones, ``_NOT_JSON``); ``subprotocol``: with that subprotocol."""
    holder = td if kind is None else (td.get(kind) or {}).get(name) or {}
    for form in _forms(td, holder, url):
        if op not in form.ops or not form.href.startswith(("http://", "https://")):
            continue
        if stream and form.subprotocol not in ("sse", None):
            continue
        if subprotocol is not None and form.subprotocol != subprotocol:
            continue
        media = form.content_type.split(";")[0].strip()
        if media != content_type if content_type is not None else media.startswith(_NOT_JSON):
            continue
        return form
    return None


_NOT_JSON = ("image/", "multipart/", "application/x-npy", "application/vnd.wott.")
"""Media types of the binary forms a Tactile TD may offer besides its JSON ones (skipped unless asked)."""


def is_tactile(td: dict[str, Any]) -> bool:
    """A Thing the client can stream: the Tactile mesh and deformation affordances."""
    return ("skinNodes" in (td.get("properties") or {})
            and "skinDeformedDetection" in (td.get("events") or {}))


@dataclass(frozen=True)
class Mesh:
    """The skin's rest mesh, rows in the order of ``skinNodes``.

    ``cells`` holds row indices into ``nodes`` (not node ids), padded with -1 where
    triangles and quads mix; ``free`` is None when the TD does not say which nodes are clamped.
    """

    nodes: np.ndarray  # (N, 3) float64, mm, in the sensor's coordinate frame
    node_ids: np.ndarray  # (N,) int64
    cells: np.ndarray  # (M, k) int64
    free: np.ndarray | None  # (N,) bool

    def __len__(self) -> int:
        return len(self.nodes)

    def index_of(self, ids: Any) -> np.ndarray:
        """Rows of the given node ids (ValueError naming an id the mesh lacks)."""
        return _NodeIndex(self.node_ids).rows(ids)


class _NodeIndex:
    """Node id -> row, as one array lookup (ids are small non-negative integers on every server seen)."""

    __slots__ = ("identity", "lookup", "n")

    def __init__(self, node_ids: np.ndarray) -> None:
        self.n = len(node_ids)
        self.identity = bool(np.array_equal(node_ids, np.arange(self.n)))
        top = int(node_ids.max()) + 1 if self.n else 0
        self.lookup = np.full(top, -1, dtype=np.intp)
        if self.n:
            self.lookup[node_ids] = np.arange(self.n)

    def rows(self, ids: Any) -> np.ndarray:
        arr = np.asarray(ids, dtype=np.intp)
        if self.identity:
            if arr.size and (arr.min() < 0 or arr.max() >= self.n):
                raise ValueError(f"node id {int(arr[(arr < 0) | (arr >= self.n)][0])} is not in the mesh")
            return arr
        if arr.size and (arr.min() < 0 or arr.max() >= len(self.lookup)):
            bad = arr[(arr < 0) | (arr >= len(self.lookup))][0]
            raise ValueError(f"node id {int(bad)} is not in the mesh")
        rows = self.lookup[arr]
        if arr.size and rows.min() < 0:
            raise ValueError(f"node id {int(arr[rows < 0][0])} is not in the mesh")
        return rows


def parse_mesh(skin_nodes: dict[str, Any], skin_cells: dict[str, Any] | None) -> Mesh:
    """``skinNodes`` and ``skinCells`` property values -> arrays (InvalidTD naming the field at fault)."""
    try:
        items = skin_nodes["arrayOfNodes"]
        ids = np.fromiter((n["nodeID"] for n in items), dtype=np.int64, count=len(items))
        nodes = np.array([(n["nodeLocation"]["x"], n["nodeLocation"]["y"], n["nodeLocation"]["z"])
                          for n in items], dtype=np.float64).reshape(-1, 3)
    except (KeyError, TypeError, ValueError) as e:
        msg = f"skinNodes.arrayOfNodes: not a list of {{nodeID, nodeLocation {{x,y,z}}}} ({e!r})"
        raise InvalidTD(msg) from None
    if len(np.unique(ids)) != len(ids) or (ids.size and ids.min() < 0):
        raise InvalidTD("skinNodes.arrayOfNodes: nodeID values must be distinct non-negative integers")
    free = None
    if items and all(isinstance(n.get("fixed"), bool) for n in items):
        free = np.array([not n["fixed"] for n in items])
    index = _NodeIndex(ids)
    cells = np.zeros((0, 3), dtype=np.int64)
    if skin_cells is not None:
        try:
            conn = [c["connectedNodes"] for c in skin_cells["arrayOfCells"]]
            k = max((len(c) for c in conn), default=3)
            cells = np.full((len(conn), k), -1, dtype=np.int64)
            for row, c in enumerate(conn):
                cells[row, : len(c)] = index.rows(c)
        except (KeyError, TypeError, ValueError) as e:
            raise InvalidTD(f"skinCells.arrayOfCells: {e}") from None
    return Mesh(nodes, ids, cells, free)
