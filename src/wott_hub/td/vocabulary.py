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

__all__ = ["EVENTS", "PROPERTIES", "TACTILE_NS", "TD_CONTEXT", "xyz"]

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
