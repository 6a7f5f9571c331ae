"""Settings saved by an older version, read as they were meant.

Version 0.1.0 stored ``scene.brdf.peak_max_angle`` and each photo's
``north_offset`` as plain floats in degrees; they are Blender angles (radians)
since settings version 1. A file's scenes carry ``scene.brdf.settings_version``
from the first save with this version on (:func:`mark`, a ``save_pre`` handler);
a file without it is older, and :func:`upgrade` (a ``load_post`` handler, and
once at registration for the file already open) converts the values it stored
(``is_property_set``; RNA access, since Blender 5.0 keeps ``bpy.props`` values
out of the ``scene["..."]`` dictionary). A value the user never changed is not
stored, so it reads the new default and needs nothing. Nothing is written to
disk: the file changes only when the user saves it.
"""

from __future__ import annotations

import math

import bpy
from bpy.app.handlers import persistent

SETTINGS_VERSION = 1  # BRDFSettings.settings_version of files this version saves


def _to_radians(group, key: str) -> bool:
    """Convert ``group``'s stored degree value ``key`` to radians; False if not stored."""
    if not group.is_property_set(key):
        return False
    setattr(group, key, math.radians(getattr(group, key)))
    return True


def upgrade_scene(scene) -> int:
    """Bring one scene's settings to :data:`SETTINGS_VERSION`; returns how many values
    were converted (0 for a scene already current or never set)."""
    brdf = scene.brdf
    if brdf.is_property_set("settings_version") and brdf.settings_version >= SETTINGS_VERSION:
        return 0
    converted = int(_to_radians(brdf, "peak_max_angle"))
    for photo in brdf.photos:
        converted += _to_radians(photo, "north_offset")
    brdf.settings_version = SETTINGS_VERSION
    return converted


@persistent
def upgrade(_file=None) -> None:
    """``load_post``: every scene of the file just opened."""
    scenes = getattr(bpy.data, "scenes", None)  # restricted while Blender starts
    if scenes is None or not hasattr(bpy.types.Scene, "brdf"):
        return
    for scene in scenes:
        upgrade_scene(scene)


@persistent
def mark(_file=None) -> None:
    """``save_pre``: the scenes that hold settings say which version wrote them."""
    if hasattr(bpy.types.Scene, "brdf"):
        for scene in bpy.data.scenes:
            scene.brdf.settings_version = SETTINGS_VERSION


def attach() -> None:
    """Install the handlers (idempotent) and upgrade the file already open."""
    if upgrade not in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.append(upgrade)
    if mark not in bpy.app.handlers.save_pre:
        bpy.app.handlers.save_pre.append(mark)
    upgrade()


def detach() -> None:
    for handlers, handler in ((bpy.app.handlers.load_post, upgrade),
                              (bpy.app.handlers.save_pre, mark)):
        while handler in handlers:
            handlers.remove(handler)
