"""From a frame to what clients receive: deformed-node packets, contacts, actions.

The processor keeps the little state a frame sequence needs (which nodes were
deformed and their split into patches, the action state machine) and does no
work a frame does not need: a frame with no node above ε costs one norm per node
(and one max over the free nodes' norms, for the note below).

A press too light to report (issue 14: a Kelvin-Voigt 4 N press on Dragon Skin
30 peaks below ε) must not be silent: while the largest node norm stays in
[``below_threshold_floor`` x ε, ε] for ``below_threshold_s`` of frame time,
``below_note`` says so (the hub appends it to the device's health reason). The
floor keeps rest noise out: 0.25 by default; a driver whose rest readings are
noisier declares its own (``below_threshold_floor``, the camera skins: 0.75),
and the hub passes it here (``set_below_threshold``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from .actions import ActionDetector, ActionEvidence, ActionParams
from .contacts import Contact, ContactFinder, ForceModel, WinklerForceModel
from .frame import FrameError, TactileFrame
from .measured import MeasuredContact
from .mesh import SkinMesh, mesh_spacing
from .tracking import ContactTracker

if TYPE_CHECKING:
    from .device import DeviceDescription

__all__ = ["BELOW_THRESHOLD_FLOOR", "FrameProcessor", "FrameResult", "ProcessingParams", "processing_params"]

BELOW_THRESHOLD_FLOOR = 0.25  # x epsilon: the floor of a noise-free skin (scene, taxel)


@dataclass(frozen=True, slots=True)
class ProcessingParams:
    """Per-device processing settings (defaults documented in docs/processing.md)."""

    epsilon_mm: float = 0.1
    intensity_decimals: int = 3  # µm resolution in packets: smaller JSON, no visible loss
    min_contact_nodes: int = 1
    modulus_mpa: float = 0.118  # Ecoflex 00-30 (MATERIALS); the hub passes each device's material
    thickness_mm: float = 3.0
    actions: ActionParams = field(default_factory=ActionParams)
    # "winkler": independent springs under each node (cheap); "stiffness": the Kelvin-Voigt skin's
    # assembled stiffness (wott_hub.tactile.mechanics), exact for quasi-static presses; "sum": the node
    # vectors are forces (N), a contact's is their sum; "none": they give no force (contactForces empty)
    force_model: str = "winkler"
    unit: str = "mm"  # of ε and the node vectors (tactile.device.NodeSignal): in the below-threshold note
    below_threshold_s: float = 1.0  # a press this long in [floor x ε, ε] gets a health note; 0: never
    below_threshold_floor: float = BELOW_THRESHOLD_FLOOR  # x epsilon: the device's declared rest noise
    # contacts (docs/processing.md, "Contacts"): "peaks" (a watershed) or "components" (connected sets)
    segmentation: str = "peaks"
    merge_noise: float = 2.0  # two peaks stay apart if their valley is this many noise floors below the lower
    merge_ratio: float = 0.1  # ... and this fraction of it
    birth_noise: float = 1.0  # a new contact's peak rises this many noise floors above its base
    side_lobe_ratio: float = 0.0  # contacts weaker than this fraction of the strongest: artefacts
    track_gate_mm: float | None = None  # None: 3 mesh spacings
    measured_contacts: bool = False  # the driver measures contacts and their radii (tactile.measured)


def processing_params(desc: DeviceDescription) -> ProcessingParams:
    """Processing settings from what the device says about itself. Node vectors that are no
    displacement (``desc.node_signal``) get no force from the material, and no collision: its speed
    threshold is in mm/s of the deepest node."""
    signal = desc.node_signal
    extra: dict[str, Any] = {}
    if not signal.is_displacement:
        extra = {"force_model": "sum" if signal.gives_force else "none", "unit": signal.unit,
                 "actions": ActionParams(collision_speed_mm_s=math.inf)}
    if desc.measures_contacts and not desc.force_estimate:  # measured contacts without a force
        extra["force_model"] = "none"
    return ProcessingParams(epsilon_mm=desc.epsilon_mm, modulus_mpa=desc.material.modulus_mpa,
                            thickness_mm=desc.thickness_mm, side_lobe_ratio=desc.side_lobe_ratio,
                            measured_contacts=desc.measures_contacts, **extra)


@dataclass(slots=True, eq=False)
class FrameResult:
    """What one frame produced. ``deformed`` is None when no packet is due.

    Read-only once made (the pipeline's records of a frame share it); not frozen because a
    frozen dataclass of eight fields takes about 1 µs more to build, on every frame.
    """

    t_ns: int
    deformed_nodes: np.ndarray  # indices with ‖D‖ > ε, ascending
    intensity: np.ndarray  # their ‖D‖, mm
    is_release: bool  # the packet is the final all-zero one
    contacts: list[Contact]
    actions: list[str]
    packet_due: bool
    details: tuple[ActionEvidence, ...] = ()  # one per action, same order
    forces: bool = True  # the contacts' forces are measured or modelled (False: contactForces is empty)
    radii: bool = False  # the contacts were measured with their radii: ``contactRadii`` (tactile.measured)

    def action_details(self) -> list[dict[str, Any]]:
        """The ``actionDetails`` event payloads of this frame's actions (built only when asked)."""
        return [e.payload() for e in self.details]

    def skin_deformed_detection(self) -> dict[str, Any] | None:
        """The ``skinDeformedDetection`` event payload, or None if nothing to send.

        A packet lists every node currently above ε (clients treat absent nodes
        as at rest); the release packet lists the previously deformed nodes with
        intensity 0.
        """
        if not self.packet_due:
            return None
        return {
            "timeStamp": self.t_ns,
            "numOfDeformedNodes": int(len(self.deformed_nodes)),
            "arrayOfDeformedNodes": [
                {"deformedNodeID": int(i), "deformedNodeIntensity": float(v)}
                for i, v in zip(self.deformed_nodes.tolist(), self.intensity.tolist(), strict=True)
            ],
        }

    def contact_information(self) -> dict[str, Any]:
        """The ``contactInformation`` property value for this frame (``contactIds`` while touched)."""
        info: dict[str, Any] = {
            "numOfContacts": len(self.contacts),
            "contactLocations": [_xyz(c.location) for c in self.contacts],
            "contactForces": [_xyz(c.force) for c in self.contacts] if self.forces else [],
        }
        if self.radii:
            info["contactRadii"] = [round(c.radius, 4) for c in self.contacts]
        if self.contacts:
            info["contactIds"] = [c.id for c in self.contacts]
        return info


def _xyz(v: np.ndarray) -> dict[str, float]:
    x, y, z = v.tolist()
    return {"x": round(x, 4), "y": round(y, 4), "z": round(z, 4)}


class FrameProcessor:
    """Stateful per-device processing of a frame sequence."""

    def __init__(self, mesh: SkinMesh, params: ProcessingParams | None = None) -> None:
        self.mesh = mesh
        self.params = p = params or ProcessingParams()
        if not p.epsilon_mm > 0:
            raise ValueError(f"epsilon must be positive, got {p.epsilon_mm}")
        self._n_nodes, self._free_mask = mesh.n_nodes, mesh.free
        self._threshold = np.where(mesh.free, p.epsilon_mm, np.inf)  # clamped nodes: never above
        self._force: ForceModel
        if p.force_model == "winkler":
            self._force = WinklerForceModel(mesh, p.modulus_mpa, p.thickness_mm)
        elif p.force_model == "stiffness":
            from .mechanics.forces import StiffnessForceModel  # assembles K once, here

            self._force = StiffnessForceModel(mesh, p.modulus_mpa, p.thickness_mm)
        elif p.force_model in ("sum", "none"):
            self._force = WinklerForceModel.uniform(mesh, 1.0 if p.force_model == "sum" else 0.0)
        else:
            raise ValueError(f"force_model must be 'winkler', 'stiffness', 'sum' or 'none', "
                             f"got {p.force_model!r}")
        self._forces = p.force_model != "none"
        self._contacts = ContactFinder(mesh, self._force, p.min_contact_nodes, p.segmentation, p.epsilon_mm)
        self._tracker = ContactTracker(p.track_gate_mm or 3.0 * mesh_spacing(mesh))
        self._actions = ActionDetector(p.actions)
        # np.round multiplies by 10**decimals, rints and divides; 10**k is exact as a float up to 22
        k = p.intensity_decimals
        self._round_factor = float(10**k) if 0 <= k <= 22 else None
        self._prev_deformed = np.empty(0, dtype=np.int64)
        self._field = np.full(mesh.n_nodes + 1, -np.inf)  # every node's norm, then -inf (contacts.find)
        self._norm = self._field[:-1]
        self._merge_ratio, self._side_lobes = p.merge_ratio, p.side_lobe_ratio
        self._last_t: int | None = None
        self.below_note = ""  # see the module doc; "" while nothing is pressed below ε for long
        self._below_since: int | None = None
        self.set_below_threshold(p.below_threshold_floor, p.below_threshold_s)

    def set_below_threshold(self, floor: float, seconds: float) -> None:
        """Floor (x ε) and duration (s, 0: never) of the below-threshold note (the driver's, if it says)."""
        eps = self.params.epsilon_mm
        self._below_lo, self._below_ns = floor * eps, int(seconds * 1e9)
        p = self.params
        self._merge_mm, self._birth_mm = p.merge_noise * self._below_lo, p.birth_noise * self._below_lo
        u, verb = p.unit, "displaced" if p.unit == "mm" else "changed"
        self._below_text = (f"below threshold: {verb} {floor * eps:g}-{eps:g} {u} (epsilon {eps:g} {u}) "
                            f"for over {seconds:g} s: not reported")
        self.below_note, self._below_since = "", None

    @property
    def noise_mm(self) -> float:
        """The noise floor the contact thresholds scale with (mm): the device's rest noise as it
        declares it (``below_threshold_floor`` x ε; docs/processing.md, "Contacts")."""
        return self._below_lo

    def process(self, frame: TactileFrame) -> FrameResult:
        d = frame.displacement
        if len(d) != self._n_nodes:
            raise FrameError(f"frame has {frame.n_nodes} nodes, the mesh has {self.mesh.n_nodes}")
        t_ns = frame.t_ns
        if self._last_t is not None and t_ns < self._last_t:
            raise FrameError(f"frame time {t_ns} ns goes back from {self._last_t} ns")
        self._last_t = t_ns
        # every node's norm, then the clamped ones masked out: cheaper than gathering the free rows
        norm = np.einsum("ij,ij->i", d, d, out=self._norm)
        np.sqrt(norm, out=norm)
        deformed = (norm > self._threshold).nonzero()[0]
        if deformed.size:
            norms = norm[deformed]
            peak = float(np.maximum.reduce(norms))
            if not math.isfinite(peak):  # finite but huge displacements overflow ‖D‖
                raise FrameError("displacement too large: its norm overflows (check the driver's scale)")
            contacts = self._tracker.update(t_ns, self._contacts.find(
                deformed, norms, d, peak, self._field, self._merge_mm, self._merge_ratio), self._birth_mm,
                self._side_lobes)
            intensity = self._round(norms)
            is_release, due = False, True
            self._below_since, self.below_note = None, ""
            self._prev_deformed = deformed
        else:
            contacts = []
            self._tracker.reset()
            if self._below_ns:  # one max over the norms already computed; NaN compares false
                if norm.max(initial=0.0, where=self._free_mask) > self._below_lo:
                    if self._below_since is None:
                        self._below_since = t_ns
                    elif t_ns - self._below_since >= self._below_ns:
                        self.below_note = self._below_text
                else:
                    self._below_since, self.below_note = None, ""
            is_release = due = bool(self._prev_deformed.size)
            if is_release:
                deformed, self._prev_deformed = self._prev_deformed, deformed
            intensity = np.zeros(len(deformed))
        if self.params.measured_contacts:  # the driver's own contacts, not the field's
            contacts = self._measured(t_ns, frame.contacts or ())
        actions = self._actions.update(t_ns, contacts)
        details = tuple(self._actions.details) if actions else ()
        return FrameResult(t_ns, deformed, intensity, is_release, contacts, actions, due, details,
                           self._forces, self.params.measured_contacts)

    def _measured(self, t_ns: int, measured: tuple[MeasuredContact, ...]) -> list[Contact]:
        """The driver's measured contacts as ``Contact`` values, tracked (ids) like any other; every one
        is kept (it was measured, not inferred from a noisy field: no birth threshold, no side lobes)."""
        if not measured:
            self._tracker.reset()
            return []
        empty = np.empty(0, dtype=np.int64)
        contacts = []
        for m in measured:
            loc = np.asarray(m.location, dtype=np.float64)
            force = np.asarray(m.force_n, dtype=np.float64)
            contacts.append(Contact(empty, loc, force, m.depth_mm, m.depth_mm, np.zeros(3), m.depth_mm,
                                    math.pi * m.radius_mm**2, 0.0, radius=m.radius_mm))
        return self._tracker.update(t_ns, contacts, -math.inf, 0.0)

    def _round(self, norms: np.ndarray) -> np.ndarray:
        """``np.round(norms, decimals)`` as the three ufuncs it runs, without its call overhead."""
        f = self._round_factor
        if f is None:
            return np.round(norms, self.params.intensity_decimals)
        out = norms * f
        np.rint(out, out=out)
        out /= f
        return out
