"""One error tree: every public exception class of ``wott_hub`` and of the first-party plugins derives from
``WottHubError``, so an embedding program, the HTTP routes and the CLI each catch one root (errors.py).

"Public" is every class deriving from ``BaseException`` that a module defines under a name without a
leading underscore; found by importing every module, so a class added anywhere is checked.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil
from pathlib import Path

import pytest

from wott_hub import errors
from wott_hub.errors import (
    ConfigError,
    DriverError,
    InvalidInput,
    SettingsError,
    WottHubError,
    exit_code,
    http_status,
)

ROOT = Path(__file__).resolve().parents[1]

PACKAGES = ["wott_hub", *sorted(p.parent.name for p in ROOT.glob("plugins/*/src/*/__init__.py"))]

OUTSIDE_THE_TREE = {
    # tornado's own mechanism, not an error of the hub: raised inside a request handler and turned into
    # the 405 response (with its Allow header) by servient/problem.py; it never reaches a caller.
    "wott_hub.servient.problem.MethodNotAllowed",
}


def public_exception_classes() -> dict[str, type[BaseException]]:
    found: dict[str, type[BaseException]] = {}
    for package in PACKAGES:
        top = importlib.import_module(package)
        names = [package, *(m.name for m in pkgutil.walk_packages(top.__path__, f"{package}."))]
        for name in names:
            module = importlib.import_module(name)
            for attr, value in vars(module).items():
                if (inspect.isclass(value) and issubclass(value, BaseException) and value.__module__ == name
                        and not attr.startswith("_")):
                    found[f"{name}.{attr}"] = value
    return found


def test_every_public_exception_class_is_in_the_tree():
    classes = public_exception_classes()
    assert "wott_hub.tactile.frame.FrameError" in classes and "wott_vision.camera.CameraError" in classes
    outside = sorted(name for name, cls in classes.items()
                     if not issubclass(cls, WottHubError) and name not in OUTSIDE_THE_TREE)
    assert outside == [], "derive these from a class of wott_hub.errors (plugins: via wott_hub.plugin_api)"
    assert OUTSIDE_THE_TREE <= set(classes), "an exclusion names a class that no longer exists"


@pytest.mark.parametrize("name", ["wott_hub.tactile.mesh.MeshError", "wott_hub.tactile.frame.FrameError",
                                  "wott_hub.tactile.materials.MaterialError",
                                  "wott_hub.tactile.mechanics.model.MechanicsError",
                                  "wott_hub.tactile.mechanics.model.StabilityError",
                                  "wott_hub.tactile.mechanics.model.ContactError",
                                  "wott_hub.sim.scene.SceneError"])
def test_domain_and_scene_errors_are_invalid_input(name):
    module, _, attr = name.rpartition(".")
    cls = getattr(importlib.import_module(module), attr)
    assert issubclass(cls, InvalidInput) and issubclass(cls, ValueError)  # `except ValueError` still works
    error = cls("x", 0.1) if attr == "StabilityError" else cls("x")
    assert http_status(error) == 400 and exit_code(error) == 2


def test_a_bad_device_setting_is_a_config_error_that_drivers_catch_as_before():
    error = SettingsError("device 'd' (family 'scene'): setting 'rate_hz': ...")
    assert isinstance(error, ConfigError) and isinstance(error, DriverError)
    assert http_status(error) == 400 and exit_code(error) == 2  # the person's mistake, not the device's
    assert http_status(DriverError("x")) == 422 and exit_code(DriverError("x")) == 5


def test_every_class_of_the_error_module_is_listed_and_mapped():
    classes = {n for n, c in vars(errors).items() if inspect.isclass(c) and issubclass(c, BaseException)}
    assert classes <= set(errors.__all__)
    for name in classes:
        cls = getattr(errors, name)
        assert isinstance(http_status(cls("x")), int) and isinstance(exit_code(cls("x")), int)
