"""The add-on's tooltips read as Blender's own: short, sentence case, the verb first for an
operator; each description listed and checked."""

import importlib
import inspect

LOCAL_MODULE = "bl_ext.mocap_gapfill_tests.mocap_gapfill"  # conftest.extension loads it
#: characters: Blender's own tooltips are a line or two
LONGEST = 120
#: the verbs an operator's tooltip starts with
VERBS = {"Build", "Repair", "Choose", "Fill", "Find", "Import", "Mark", "Open", "Read", "Remove", "Show",
         "Take", "Use"}


def descriptions(bpy):
    """``[(kind, name, text), ...]``: every operator's and property's description, and each
    enum item's."""
    out = []
    for module in ("operators", "props", "prefs", "panels"):
        mod = importlib.import_module(f"{LOCAL_MODULE}.addon.{module}")
        for _, cls in inspect.getmembers(mod, inspect.isclass):
            if cls.__module__ != mod.__name__:
                continue
            if issubclass(cls, bpy.types.Operator):
                text = getattr(cls, "bl_description", "") or cls.__doc__ or ""
                out.append(("operator", cls.bl_idname, " ".join(text.split())))
            for name, prop in getattr(cls, "__annotations__", {}).items():
                keywords = getattr(prop, "keywords", None)
                if keywords is None:
                    continue
                out.append(("property", f"{cls.__name__}.{name}",
                            " ".join(keywords.get("description", "").split())))
                items = keywords.get("items")
                for item in items if isinstance(items, (list, tuple)) else ():
                    if len(item) > 2:
                        out.append(("item", f"{cls.__name__}.{name}.{item[0]}", item[2]))
    return out


def test_every_tooltip_is_short_and_reads_as_blenders(extension):
    found = descriptions(extension)
    for kind, name, text in found:
        print(f"{kind:8s} {name}: {text}")
    assert sum(kind == "operator" for kind, _, _ in found) >= 10
    for kind, name, text in found:
        if not text:  # no description: Blender shows the name alone
            assert kind != "operator", name
            continue
        assert len(text) <= LONGEST, (name, len(text), text)
        assert not text[0].islower() and not text.endswith("."), (name, text)
        if kind == "operator":  # what it does, the verb first
            assert text.split()[0] in VERBS, (name, text)
