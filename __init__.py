"""BRDF Reconstruct: measured BRDFs of a scanned object from lit photos.

This is the entry Blender loads beside ``blender_manifest.toml``. Inside
Blender the package is ``bl_ext.<repo>.brdf_reconstruct``; for tests and
headless runs ``pyproject.toml`` maps this folder to ``brdf_reconstruct``.

Importing this package must stay free of ``bpy`` so that
``import brdf_reconstruct.core`` works (and is fast) outside Blender: the
Blender glue in ``brdf_addon`` is imported only when Blender calls
``register()``.
"""


def _classes() -> tuple:
    """Every class to register, in dependency order: ``brdf_addon``'s (preferences,
    property groups, panel), then the operators."""
    from . import brdf_addon, operators

    return brdf_addon.CLASSES + operators.CLASSES


def register() -> None:
    """Register the extension's classes and attach ``Scene.brdf``."""
    import bpy

    from .brdf_addon import props, versioning

    for cls in _classes():
        bpy.utils.register_class(cls)
    props.attach()
    versioning.attach()  # settings saved by 0.1.0: degrees -> radians


def unregister() -> None:
    """Undo ``register()``."""
    import bpy

    from .brdf_addon import props, versioning

    versioning.detach()
    props.detach()
    for cls in reversed(_classes()):
        bpy.utils.unregister_class(cls)
