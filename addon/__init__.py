"""Blender side of Mocap Gap Fill: operators and panels. Registered by the root ``__init__``."""

from . import operators, panels

_modules = (operators, panels)


def register():
    for module in _modules:
        module.register()


def unregister():
    for module in reversed(_modules):
        module.unregister()
