"""Settings of the reconstruction, held by one PropertyGroup on the scene.

The names match the ``[settings]`` table of the batch job file, so the panel,
the batch entry and the tests share one vocabulary.
"""

import bpy
from bpy.props import IntProperty, PointerProperty
from bpy.types import PropertyGroup


class BRDFSettings(PropertyGroup):
    """Scene-wide settings, reached as ``scene.brdf``."""

    seed: IntProperty(
        name="Seed",
        description="Seed of every random choice (sampling trials); same seed, same result",
        default=0,
        min=0,
    )


CLASSES = (BRDFSettings,)


def attach() -> None:
    """Attach the settings as ``bpy.types.Scene.brdf`` (after class registration)."""
    bpy.types.Scene.brdf = PointerProperty(type=BRDFSettings)


def detach() -> None:
    """Remove ``bpy.types.Scene.brdf`` (before class unregistration)."""
    del bpy.types.Scene.brdf
