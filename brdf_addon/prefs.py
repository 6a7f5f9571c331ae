"""Add-on preferences: BRDF database folder, cache location, Cycles device.

The preferences exist only when Blender loads the package as an add-on or
extension (``bpy.context.preferences.addons[<package>]``). Headless runs that
call ``register()`` themselves (pytest with pip ``bpy``, the batch entry) get
the same defaults through :func:`get`.
"""

import pathlib

import bpy
from bpy.props import EnumProperty, StringProperty
from bpy.types import AddonPreferences

# "bl_ext.<repo>.brdf_reconstruct" inside Blender, "brdf_reconstruct" in tests
PACKAGE = __package__.rpartition(".")[0]

DEVICES = [("CPU", "CPU", "Render with the CPU"),
           ("GPU", "GPU", "Render with the GPU set in Blender's Cycles preferences; "
            "falls back to the CPU when there is none")]


class BRDFPreferences(AddonPreferences):
    bl_idname = PACKAGE

    database_folder: StringProperty(
        name="BRDF Database", subtype="DIR_PATH", default="",
        description="Folder of MERL .binary files for the PCA basis (empty = built-in basis)")
    cache_folder: StringProperty(
        name="Cache", subtype="DIR_PATH", default="",
        description="Where the basis cache goes (empty = the extension's user folder)")
    device: EnumProperty(name="Cycles Device", items=DEVICES, default="CPU",
                         description="What renders the G-buffers and the Cycles selection")

    def draw(self, _context):
        layout = self.layout
        layout.prop(self, "database_folder")
        layout.prop(self, "cache_folder")
        layout.prop(self, "device")


CLASSES = (BRDFPreferences,)


class _Defaults:
    database_folder = ""
    cache_folder = ""
    device = "CPU"


def get():
    """The preferences, or an object with the defaults when not loaded as an add-on."""
    addon = bpy.context.preferences.addons.get(PACKAGE)
    return addon.preferences if addon is not None and addon.preferences else _Defaults()


def cache_dir() -> pathlib.Path:
    """Cache folder: the preference, else the extension's user folder (never the
    extension's own folder), else ``$BRDF_RECONSTRUCT_CACHE`` or ~/.cache."""
    chosen = get().cache_folder
    if chosen:
        return pathlib.Path(bpy.path.abspath(chosen))
    if PACKAGE.startswith("bl_ext."):
        return pathlib.Path(bpy.utils.extension_path_user(PACKAGE, path="cache", create=True))
    from ..core.brdf import basis

    return basis.default_cache_dir()


def load_basis(progress=None, cancelled=None):
    """The PCA basis the preferences ask for (built-in, or a MERL folder), cached.
    progress(fraction, message), cancelled(): as in ``core.brdf.basis.build``,
    used when the cache misses and the basis is built (first run)."""
    from ..core.brdf import basis

    folder = get().database_folder
    if folder:
        return basis.load_merl_folder(bpy.path.abspath(folder), cache_dir=cache_dir(),
                                      progress=progress, cancelled=cancelled)
    return basis.load_default(cache_dir=cache_dir(), progress=progress, cancelled=cancelled)


def cycles_device() -> str:
    """'GPU' only when the preference asks for it and Cycles has a usable GPU."""
    if get().device != "GPU":
        return "CPU"
    try:
        cycles = bpy.context.preferences.addons["cycles"].preferences
        cycles.refresh_devices()
        if cycles.compute_device_type != "NONE" and any(
                d.use and d.type != "CPU" for d in cycles.devices):
            return "GPU"
    except (KeyError, AttributeError):
        pass
    return "CPU"
