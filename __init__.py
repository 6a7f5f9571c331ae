"""BRDF Reconstruct: measured BRDFs of a scanned object from lit photos.

This is the entry Blender loads beside ``blender_manifest.toml``. Inside
Blender the package is ``bl_ext.<repo>.brdf_reconstruct``; for tests and
headless runs ``pyproject.toml`` maps this folder to ``brdf_reconstruct``.

Importing this package must stay free of ``bpy`` so that
``import brdf_reconstruct.core`` works (and is fast) outside Blender: the
Blender glue in ``brdf_addon`` is imported only when Blender calls
``register()``.
"""


def register() -> None:
    """Register the add-on's classes and properties with Blender."""
    from . import brdf_addon

    brdf_addon.register()


def unregister() -> None:
    """Undo ``register()``."""
    from . import brdf_addon

    brdf_addon.unregister()
