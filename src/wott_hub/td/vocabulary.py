"""The Tactile vocabulary: every affordance a Tactile TD carries and its data schema.

Field names are those of the WoTT proposal so existing clients keep working;
its slips are fixed here (``centerOfBottomCircle``, ``xAxis``...). Units are
declared with ``unit`` and defined as IRIs in the JSON-LD context
(``context/tactile-v1.jsonld``), so the TD is semantically valid, not only
schema-valid. Data schemas never carry empty placeholder keywords (node-wot
rejects ``"oneOf": []``).
"""

from __future__ import annotations

from typing import Any

from wott_hub.tactile.actions import ACTIONS

from .actions import DEVICE_ACTION_EVENT

__all__ = ["CONTACT_RADII", "DETAIL_EVENTS", "DETAIL_PROPERTIES", "EVENTS", "PROPERTIES", "TACTILE_NS",
           "TD_CONTEXT", "xyz"]

TACTILE_NS = "https://w3id.org/wott/tactile#"
TD_CONTEXT = ["https://www.w3.org/2019/wot/td/v1", "https://www.w3.org/2022/wot/td/v1.1"]


def xyz(unit: str | None = "mm") -> dict[str, Any]:
    axis: dict[str, Any] = {"type": "number"}
    if unit:
        axis["unit"] = unit
    return {
        "type": "object",
        "properties": {"x": dict(axis), "y": dict(axis), "z": dict(axis)},
        "required": ["x", "y", "z"],
    }


def _mm(description: str) -> dict[str, Any]:
    return {"type": "number", "minimum": 0, "unit": "mm", "description": description}


PROPERTIES: dict[str, dict[str, Any]] = {
    "skinMaterial": {
        "@type": "tac:SkinMaterial",
        "description": "What the skin is made of.",
        "type": "object",
        "properties": {
            "materialType": {"type": "string", "description": "e.g. ecoflex, dragonskin"},
            "materialShoreHardness": {"type": "string", "description": "e.g. Shore 00-30, Shore A20"},
        },
        "required": ["materialType", "materialShoreHardness"],
    },
    "skinShape": {
        "@type": "tac:SkinShape",
        "description": "Nominal shape and dimensions of the skin.",
        "type": "object",
        "properties": {
            "shapeType": {"type": "string", "enum": ["rectangularPrism", "cylinder", "barrel"]},
            "lengthDimension": _mm("Length (rectangular prism)."),
            "widthDimension": _mm("Width (rectangular prism)."),
            "heightDimension": _mm("Height along the skin's axis or thickness of a prism."),
            "baseRadiusDimension": _mm("Radius at both ends (cylinder, barrel)."),
            "middleRadiusDimension": _mm("Radius at mid-height (barrel)."),
        },
        "required": ["shapeType"],
    },
    "skinNodes": {
        "@type": "tac:SkinNodes",
        "description": "Rest positions of the skin's mesh nodes.",
        "observable": True,
        "type": "object",
        "properties": {
            "numOfNodes": {"type": "integer", "minimum": 0},
            "arrayOfNodes": {
                "type": "array",
                "items": {
                    "type": "object",
                    "properties": {
                        "nodeID": {"type": "integer", "minimum": 0},
                        "nodeLocation": xyz(),
                        "referenceTo": {
                            "type": "string",
                            "description": "The frame nodeLocation is given in.",
                        },
                    },
                    "required": ["nodeID", "nodeLocation"],
                },
            },
        },
        "required": ["numOfNodes", "arrayOfNodes"],
    },
    "skinCells": {
        "@type": "tac:SkinCells",
        "description": "Triangles or quads as node IDs, counter-clockwise seen from outside.",
        "type": "object",
        "properties": {
            "numOfCells": {"type": "integer", "minimum": 0},
            "arrayOfCells": {
                "type": "array",
                "items": {
                    "type": "object",
                    "properties": {
                        "cellID": {"type": "integer", "minimum": 0},
                        "connectedNodes": {
                            "type": "array",
                            "items": {"type": "integer", "minimum": 0},
                            "minItems": 3,
                            "maxItems": 4,
                        },
                    },
                    "required": ["cellID", "connectedNodes"],
                },
            },
        },
        "required": ["numOfCells", "arrayOfCells"],
    },
    "contactInformation": {
        "@type": "tac:ContactInformation",
        "description": "Current contacts: locations on the rest surface and the forces on the skin.",
        "observable": True,
        "type": "object",
        "properties": {
            "numOfContacts": {"type": "integer", "minimum": 0},
            "contactLocations": {"type": "array", "items": xyz("mm")},
            "contactForces": {"type": "array", "items": xyz("N")},
            # ours (issue 31), optional: a hub without tracking, or with no contact, leaves it out
            "contactIds": {"type": "array", "items": {"type": "integer", "minimum": 1},
                           "description": ("Each contact's id, in the order of contactLocations: the "
                                           "same finger keeps its id from one value to the next while "
                                           "it touches.")},
        },
        "required": ["numOfContacts", "contactLocations", "contactForces"],
    },
    "sensorCoordinateFrame": {
        "@type": "tac:SensorCoordinateFrame",
        "description": "Right-handed frame of every vector this Thing reports (x forward, y left, z up).",
        "type": "object",
        "properties": {
            "originLocation": {
                "type": "object",
                "properties": {
                    "originName": {"type": "string", "description": "e.g. centerOfBottomCircle"},
                    **xyz()["properties"],
                },
                "required": ["x", "y", "z"],
            },
            "axisOrientation": {
                "type": "object",
                "properties": {"xAxis": xyz(None), "yAxis": xyz(None), "zAxis": xyz(None)},
                "required": ["xAxis", "yAxis", "zAxis"],
            },
        },
        "required": ["originLocation", "axisOrientation"],
    },
}

# Properties beyond the paper's (issue 14), declared in every TD (part of PROPERTIES) but not required of
# one (a TD from an older hub stays valid). A vision skin's markers missing, merged or occluded at rest:
# their nodes' value is unknown (read 0, never reported deformed); other families always serve it empty.
DETAIL_PROPERTIES: dict[str, dict[str, Any]] = {
    "unavailableNodes": {
        "@type": "tac:UnavailableNodes",
        "description": ("Nodes whose value is unknown (a vision skin's markers missing, merged or occluded "
                        "at rest): never reported in skinDeformedDetection, which is not the same as at "
                        "rest. Empty on a skin that can always read every node."),
        "observable": True,
        "type": "object",
        "properties": {
            "numOfUnavailableNodes": {"type": "integer", "minimum": 0},
            "arrayOfUnavailableNodes": {"type": "array", "items": {"type": "integer", "minimum": 0},
                                        "description": "nodeID of each, ascending"},
        },
        "required": ["numOfUnavailableNodes", "arrayOfUnavailableNodes"],
    },
}
PROPERTIES.update(DETAIL_PROPERTIES)

CONTACT_RADII: dict[str, Any] = {
    "type": "array", "items": {"type": "number", "minimum": 0, "unit": "mm"},
    "description": ("Ours (issue 44), on devices that measure their contacts: each contact's radius (mm), in "
                    "the order of contactLocations (the radius of the patch of skin it deforms)."),
}
"""``contactInformation.contactRadii``: declared only by devices that measure it (``measures_contacts``)."""
for _p in PROPERTIES.values():
    _p["readOnly"] = True

EVENTS: dict[str, dict[str, Any]] = {
    "actionDetection": {
        "@type": "tac:ActionDetection",
        "description": "What just happened to the skin.",
        "data": {"type": "string", "enum": list(ACTIONS)},
    },
    "skinDeformedDetection": {
        "@type": "tac:SkinDeformedDetection",
        "description": (
            "Nodes whose displacement norm exceeds epsilon (absent nodes are at rest); "
            "one final packet lists the previously deformed nodes with intensity 0."
        ),
        "data": {
            "type": "object",
            "properties": {
                "timeStamp": {"type": "integer", "minimum": 0, "unit": "ns"},
                "numOfDeformedNodes": {"type": "integer", "minimum": 0},
                "arrayOfDeformedNodes": {
                    "type": "array",
                    "items": {
                        "type": "object",
                        "properties": {
                            "deformedNodeID": {"type": "integer", "minimum": 0},
                            "deformedNodeIntensity": {"type": "number", "minimum": 0, "unit": "mm"},
                        },
                        "required": ["deformedNodeID", "deformedNodeIntensity"],
                    },
                },
            },
            "required": ["timeStamp", "numOfDeformedNodes", "arrayOfDeformedNodes"],
        },
    },
}


# Events beyond the paper's two (issue 14), declared in every TD (part of EVENTS) but not required of one
# (a TD from an older hub without them stays valid): the evidence behind each action.
DETAIL_EVENTS: dict[str, dict[str, Any]] = {
    "actionDetails": {
        "@type": "tac:ActionDetails",
        "description": ("Sibling of actionDetection, one per action in the same order: the action, a "
                        "confidence in [0.5, 1] (0.5: its deciding quantity just crossed the threshold) "
                        "and the evidence it was taken on."),
        "data": {
            "type": "object",
            "properties": {
                "action": {"type": "string", "enum": list(ACTIONS)},
                "confidence": {"type": "number", "minimum": 0, "maximum": 1},
                "evidence": {
                    "type": "object",
                    "properties": {
                        "contacts": {"type": "integer", "minimum": 0},
                        "durationS": {"type": "number", "minimum": 0, "unit": "s"},
                        "speedMmPerS": {"type": "number", "minimum": 0, "unit": "mm.s-1"},
                        "moveMm": {"type": "number", "minimum": 0, "unit": "mm"},
                        "approachMm": {"type": "number", "unit": "mm"},
                        "contactId": {"type": "integer", "minimum": 1,
                                      "description": "The contact (contactIds) the action was decided on."},
                    },
                    "required": ["contacts", "durationS", "speedMmPerS"],
                },
            },
            "required": ["action", "confidence", "evidence"],
        },
    },
}
DETAIL_EVENTS["skinDisplacement"] = {
    "@type": "tac:SkinDisplacement",
    "description": (
        "The nodes and frames of skinDeformedDetection with each node's displacement vector (mm, in the "
        "sensorCoordinateFrame; its norm is that node's deformedNodeIntensity within the 1 µm "
        "quantisation of both), so that direction and shear leave the hub; one final packet lists the "
        "previously displaced nodes with zero vectors. Also in a binary form (the form's contentType "
        "application/vnd.wott.skin-displacement; byte layout in docs/tactile-td.md)."
    ),
    "data": {
        "type": "object",
        "properties": {
            "timeStamp": {"type": "integer", "minimum": 0, "unit": "ns"},
            "numOfDisplacedNodes": {"type": "integer", "minimum": 0},
            "arrayOfDisplacedNodes": {
                "type": "array",
                "items": {
                    "type": "object",
                    "properties": {
                        "nodeID": {"type": "integer", "minimum": 0},
                        "displacement": xyz("mm"),
                    },
                    "required": ["nodeID", "displacement"],
                },
            },
        },
        "required": ["timeStamp", "numOfDisplacedNodes", "arrayOfDisplacedNodes"],
    },
}
DETAIL_EVENTS.update(DEVICE_ACTION_EVENT)  # each device action invoked (tare, restart...: td/actions.py)
EVENTS.update(DETAIL_EVENTS)  # declared with the paper's events; validate.py does not require them
