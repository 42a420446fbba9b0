"""Blender side of Mocap Gap Fill. Registered by the root ``__init__``; modules are imported
when registering, so ``addon.commands`` (the command line's ``blend`` and scene demo) can be
imported without bpy until it needs it."""


def _modules():
    from . import operators, panels, prefs, props

    return (props, prefs, operators, panels)


def register():
    for module in _modules():
        module.register()
    from . import batch

    batch.register()


def unregister():
    from . import batch

    batch.unregister()
    for module in reversed(_modules()):
        module.unregister()
