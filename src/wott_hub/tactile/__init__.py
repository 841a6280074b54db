"""The tactile domain: meshes, frames, processing and the skin model. No I/O here
beyond reading a mesh file, so everything is testable and fast to import."""

from .actions import ACTIONS, ActionDetector, ActionParams
from .contacts import Contact, WinklerForceModel, find_contacts
from .device import CoordinateFrame, DeviceDescription, NodeSignal, SkinShape
from .frame import FrameError, TactileFrame
from .materials import MATERIALS, Material, MaterialError, shore_to_modulus_mpa
from .measured import MeasuredContact
from .mesh import (
    MeshError,
    SkinMesh,
    barrel,
    cylinder,
    flat_pad,
    load_taclink_barrel,
    taclink_barrel,
)
from .processing import FrameProcessor, FrameResult, ProcessingParams

__all__ = [
    "ACTIONS", "ActionDetector", "ActionParams", "Contact", "CoordinateFrame", "DeviceDescription",
    "FrameError", "FrameProcessor", "FrameResult", "MATERIALS", "Material", "MaterialError",
    "MeasuredContact", "MeshError", "NodeSignal", "ProcessingParams", "SkinMesh", "SkinShape", "TactileFrame",
    "WinklerForceModel", "barrel", "cylinder", "find_contacts", "flat_pad", "load_taclink_barrel",
    "shore_to_modulus_mpa", "taclink_barrel",
]
