"""Kelvin-Voigt skin mechanics: the model behind simulated ground truth and force estimation.

A skin is its mesh's edges as springs with parallel dashpots, a Winkler bed
and a shear layer under every node (``SkinModel``); indenters press it by
depth or force (``Press``, ``Sphere``, ``FlatPunch``); integrators advance it
(``SymplecticEuler``, ``BackwardEuler``, ``Trapezoidal``, ``QuasiStatic``);
``StiffnessForceModel`` turns measured displacements back into contact forces.
See docs/mechanics.md for the model, its sources and its limits.
"""

from .forces import DynamicForceEstimator, StiffnessForceModel, nodal_forces
from .indenters import FlatPunch, Press, PressGeometry, Sphere, press_geometry, press_on
from .integrators import (
    INTEGRATORS,
    BackwardEuler,
    Integrator,
    QuasiStatic,
    State,
    SymplecticEuler,
    Trapezoidal,
    make_integrator,
)
from .model import ContactError, MechanicsError, SkinModel, SkinParams, StabilityError
from .refine import subdivide

__all__ = [
    "INTEGRATORS", "BackwardEuler", "ContactError", "DynamicForceEstimator", "FlatPunch", "Integrator",
    "MechanicsError", "Press", "PressGeometry", "QuasiStatic", "SkinModel", "SkinParams", "Sphere",
    "StabilityError", "State", "StiffnessForceModel", "SymplecticEuler", "Trapezoidal", "make_integrator",
    "nodal_forces", "press_geometry", "press_on", "subdivide",
]
