"""Build a device's Tactile TD (TD 1.1) and the values of its static properties."""

from __future__ import annotations

import copy
import json
from functools import cache
from importlib import resources
from typing import Any

from wott_hub.tactile.device import DeviceDescription, NodeSignal
from wott_hub.tactile.raw import RawSignal
from wott_hub.types import FormFactory

from .actions import declared_actions
from .defaults import state_defaults
from .forms import FormLayout
from .raw import raw_affordances, raw_events
from .vocabulary import CONTACT_RADII, EVENTS, PROPERTIES, TACTILE_NS, TD_CONTEXT

__all__ = ["build_tactile_td", "static_property_values", "tactile_context"]


@cache
def tactile_context() -> dict[str, Any]:
    """The Tactile vocabulary's JSON-LD context document (served by the hub)."""
    text = resources.files("wott_hub.td").joinpath("context/tactile-v1.jsonld").read_text()
    context: dict[str, Any] = json.loads(text)
    return context


def build_tactile_td(
    desc: DeviceDescription,
    *,
    base: str = "http://127.0.0.1:8080/",
    forms: FormFactory | None = None,
    context_url: str | None = None,
    actions: tuple[str, ...] = ("tare", "restart"),
    raw: tuple[RawSignal, ...] = (),
) -> dict[str, Any]:
    """The device's TD 1.1 document with the Tactile vocabulary.

    ``actions``: the device actions it declares (``wott_hub.td.actions``; the hub
    names those its driver can do); the ``deviceAction`` event recording them is in ``EVENTS``.
    ``raw``: the device's raw signals (its driver's ``ServesRawSignals``), declared as the
    properties of ``wott_hub.td.raw``.

    Forms follow the hub's layout at ``base`` (``wott_hub.td.forms``) unless a
    binding supplies its own ``forms``. ``context_url`` is where the Tactile
    JSON-LD context is served (by default the hub at ``base``). TD 1.1 allows
    only prefix maps inline, so the ``tac`` prefix is also given inline for
    processors that do not dereference. The TD 1.1 defaults a client decides by are stated
    (``wott_hub.td.defaults``).
    """
    layout = FormLayout(base.rstrip("/"))
    forms = forms or layout.factory(desc.id)
    ctx: list[Any] = [*TD_CONTEXT, context_url or layout.context_url, {"tac": TACTILE_NS}]
    properties = {}
    for name, schema in {**PROPERTIES, **raw_affordances(raw)}.items():
        aff = copy.deepcopy(schema)
        aff["title"] = name
        aff["forms"] = forms("property", name, aff)
        properties[name] = aff
    events = {}
    for name, schema in {**EVENTS, **raw_events(raw)}.items():
        aff = copy.deepcopy(schema)
        aff["title"] = name
        aff["forms"] = forms("event", name, aff)
        events[name] = aff
    declared = declared_actions(actions)
    for name, aff in declared.items():
        aff["forms"] = forms("action", name, aff)
    td: dict[str, Any] = {
        "@context": ctx,
        "@type": ["tac:TactileSensor"],
        "id": f"urn:wott-hub:device:{desc.id}",
        "title": desc.title,
        "description": desc.description or f"{desc.family} tactile skin ({desc.mesh.n_nodes} nodes)",
        "tac:family": desc.family,
        "tac:epsilon": desc.epsilon_mm,
        "base": base,
        "securityDefinitions": {"nosec_sc": {"scheme": "nosec"}},
        "security": "nosec_sc",
        "properties": properties,
        "events": events,
    }
    if declared:
        td["actions"] = declared
    if not desc.node_signal.is_displacement:
        _node_signal(td, desc.node_signal)
    if desc.measures_contacts:
        _measured_contacts(td, desc.force_estimate)
    if not desc.shear:  # a gel without markers: no in-plane motion measured, no vectors to give
        td["events"].pop("skinDisplacement", None)
    return state_defaults(td)


def _measured_contacts(td: dict[str, Any], force_estimate: str) -> None:
    """A device that measures its contacts (``DeviceDescription.measures_contacts``): their radii beside
    their locations, the value unknown (null) until its first frame with a rest reference, and its forces
    labelled as the estimate they are (or said to be absent)."""
    info = td["properties"]["contactInformation"]
    forces = info["properties"]["contactForces"]
    forces["description"] = (f"An estimate, not a measurement: {force_estimate}" if force_estimate else
                             "Always empty: this device measures no force.")
    info["description"] = (f"{info['description']} Measured by the device itself, with each contact's "
                           "radius; null (unknown) until its first frame with a rest reference.")
    info["properties"]["contactRadii"] = copy.deepcopy(CONTACT_RADII)


def _node_signal(td: dict[str, Any], signal: NodeSignal) -> None:
    """The TD of a device whose node vectors are no displacement (``NodeSignal``): its intensities and ε
    in the signal's unit, no ``skinDisplacement`` (no vector in mm to give), and ``contactForces`` said to
    be empty when the signal gives no force."""
    q, unit = signal.quantity, signal.unit
    td["tac:nodeSignal"] = q
    td["events"].pop("skinDisplacement", None)
    skin = td["events"]["skinDeformedDetection"]
    skin["description"] = (f"Nodes whose {q} change (its norm, {unit}) exceeds epsilon ({unit}); absent "
                           "nodes are at rest; one final packet lists the previously changed nodes with "
                           "intensity 0.")
    skin["data"]["properties"]["arrayOfDeformedNodes"]["items"]["properties"]["deformedNodeIntensity"][
        "unit"] = unit
    forces = td["properties"]["contactInformation"]["properties"]["contactForces"]
    forces["description"] = ("The sum of the contact's nodes' measured forces." if signal.gives_force else
                             f"Always empty: this device measures {q} ({unit}), which gives no force.")


def static_property_values(desc: DeviceDescription) -> dict[str, Any]:
    """Values of the properties that never change while the device runs.

    Computed once per device and served as they are: the mesh is never re-sent
    with events.
    """
    mesh, s, m, f = desc.mesh, desc.shape, desc.material, desc.frame

    def pt(v: tuple[float, float, float]) -> dict[str, float]:
        return {"x": float(v[0]), "y": float(v[1]), "z": float(v[2])}

    shape: dict[str, Any] = {"shapeType": s.shape_type}
    for key, value in (
        ("lengthDimension", s.length_mm),
        ("widthDimension", s.width_mm),
        ("heightDimension", s.height_mm),
        ("baseRadiusDimension", s.base_radius_mm),
        ("middleRadiusDimension", s.middle_radius_mm),
    ):
        if value is not None:
            shape[key] = float(value)
    nodes = mesh.nodes.round(4).tolist()
    return {
        "skinMaterial": {"materialType": m.material_type, "materialShoreHardness": m.shore_hardness},
        "skinShape": shape,
        "skinNodes": {
            "numOfNodes": mesh.n_nodes,
            "arrayOfNodes": [
                {"nodeID": i, "nodeLocation": {"x": x, "y": y, "z": z},
                 "referenceTo": "sensorCoordinateFrame"}
                for i, (x, y, z) in enumerate(nodes)
            ],
        },
        "skinCells": {
            "numOfCells": mesh.n_cells,
            "arrayOfCells": [
                {"cellID": i, "connectedNodes": c} for i, c in enumerate(mesh.cells.tolist())
            ],
        },
        "sensorCoordinateFrame": {
            "originLocation": {"originName": f.origin_name, **pt(f.origin)},
            "axisOrientation": {"xAxis": pt(f.x_axis), "yAxis": pt(f.y_axis), "zAxis": pt(f.z_axis)},
        },
        "contactInformation": (None if desc.measures_contacts else
                               {"numOfContacts": 0, "contactLocations": [], "contactForces": []}),
        "unavailableNodes": {"numOfUnavailableNodes": 0, "arrayOfUnavailableNodes": []},  # served live
    }
