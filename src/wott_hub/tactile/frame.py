"""The unit of data every driver produces: one snapshot of a skin's displacement."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wott_hub.errors import InvalidInput

from .measured import MeasuredContact

__all__ = ["FrameError", "TactileFrame"]

_INTEGER = (int, np.integer)


class FrameError(InvalidInput):
    """A frame that must not enter the pipeline (wrong shape, NaN/Inf, bad time)."""


@dataclass(frozen=True, slots=True, eq=False)
class TactileFrame:
    """Displacement ``D`` (N x 3, mm) of every mesh node at time ``t_ns``.

    Validation happens here, at the boundary, so nothing downstream ever sees
    NaN/Inf: a driver whose model diverges gets a clear error instead of a
    client receiving garbage.

    ``contacts``: the contacts a driver measured itself (``tactile.measured``; None: the hub
    finds them in the displacement field, as for every skin that does not declare
    ``measures_contacts``).
    """

    t_ns: int
    displacement: np.ndarray
    pressure: np.ndarray | None = None
    contacts: tuple[MeasuredContact, ...] | None = None

    def __post_init__(self) -> None:
        t = self.t_ns
        if not isinstance(t, _INTEGER) or t < 0:
            raise FrameError(f"t_ns must be a non-negative integer of nanoseconds, got {t!r}")
        d = np.asarray(self.displacement, dtype=np.float64)
        if d.ndim != 2 or d.shape[1] != 3:
            raise FrameError(f"displacement must be an (N, 3) array, got shape {d.shape}")
        if not np.isfinite(d).all():  # the one check every frame pays; the details only on failure
            bad = ~np.isfinite(d).all(axis=1)
            raise FrameError(
                f"displacement has NaN/Inf at {int(bad.sum())} node(s), first node {int(np.argmax(bad))}"
            )
        if type(t) is not int:
            object.__setattr__(self, "t_ns", int(t))
        if d is not self.displacement:
            object.__setattr__(self, "displacement", d)
        if self.pressure is not None:
            p = np.asarray(self.pressure, dtype=np.float64)
            if p.shape != (len(d),):
                raise FrameError(f"pressure must have shape ({len(d)},), got {p.shape}")
            if not np.isfinite(p).all():
                raise FrameError("pressure has NaN/Inf values")
            object.__setattr__(self, "pressure", p)
        if self.contacts is not None:
            if not all(isinstance(c, MeasuredContact) for c in self.contacts):
                raise FrameError("contacts must be MeasuredContact values")
            if type(self.contacts) is not tuple:
                object.__setattr__(self, "contacts", tuple(self.contacts))

    @property
    def n_nodes(self) -> int:
        return len(self.displacement)

    @classmethod
    def rest(cls, n_nodes: int, t_ns: int = 0) -> TactileFrame:
        return cls(t_ns, np.zeros((n_nodes, 3)))
