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


MEASURED_TERMS = ("the MERL measurements behind it are for research use: for other "
                  "use read MERL's terms first, or choose Analytic")
BASES = [("ANALYTIC", "Analytic (Built-In)", "150 analytic materials made by the extension: "
          "no data license, less accurate on real materials (median sphere error 0.19 "
          "against 0.12 at 20 samples, cross-validated)"),
         ("MEASURED", "Measured (MERL)", "The default: 80 measured MERL materials shipped "
          "as Sztrajman et al. (2021) neural BRDFs (MIT license); " + MEASURED_TERMS),
         ("FOLDER", "MERL Folder", "Your own folder of MERL .binary files (BRDF Database)")]
MEASURED_PACK_VARIABLE = "BRDF_MEASURED_PACK"  # the pack file when the preference is empty


class BRDFPreferences(AddonPreferences):
    bl_idname = PACKAGE

    basis: EnumProperty(name="Basis", items=BASES, default="MEASURED",
                        description="The PCA basis of BRDFs every reconstruction stands on "
                        "(a scene can choose its own)")
    measured_pack: StringProperty(
        name="Measured Pack", subtype="FILE_PATH", default="",
        description="A pack of measured materials' networks like merl_nbrdf.npz (empty = "
        "$BRDF_MEASURED_PACK, else the pack shipped with the extension)")
    database_folder: StringProperty(
        name="BRDF Database", subtype="DIR_PATH", default="",
        description="Folder of MERL .binary files, the source of the MERL Folder basis")
    cache_folder: StringProperty(
        name="Cache", subtype="DIR_PATH", default="",
        description="Where the basis cache goes (empty = the extension's user folder)")
    device: EnumProperty(name="Cycles Device", items=DEVICES, default="CPU",
                         description="What renders the G-buffers and the Cycles selection")

    def draw(self, _context):
        layout = self.layout
        layout.prop(self, "basis")
        if self.basis == "MEASURED":
            layout.prop(self, "measured_pack")
            layout.label(text="The MERL measurements are for research use; for other use "
                         "read MERL's terms or choose Analytic", icon="INFO")
        layout.prop(self, "database_folder")
        layout.prop(self, "cache_folder")
        layout.prop(self, "device")


CLASSES = (BRDFPreferences,)


class _Defaults:
    basis = "MEASURED"
    measured_pack = ""
    database_folder = ""

    def is_property_set(self, _name) -> bool:
        return False
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


def basis_choice(scene=None) -> tuple[str, str]:
    """(kind, source) of the basis a run uses: the scene's choice
    (``scene.brdf.basis``) unless it defers to the preferences. kind is "ANALYTIC",
    "MEASURED" or "FOLDER"; source the pack file or folder (absolute; "" for the
    analytic basis). A preference file of 0.1.0 that set only the database folder
    keeps meaning that folder. ValueError (one sentence) when a source is missing."""
    p = get()
    kind, folder = p.basis, p.database_folder
    if folder and not p.is_property_set("basis"):
        kind = "FOLDER"  # 0.1.0's preferences: a folder given meant its basis
    if scene is not None and scene.brdf.basis != "PREFERENCES":
        kind, folder = scene.brdf.basis, scene.brdf.basis_folder
    if kind == "FOLDER":
        if not folder:
            raise ValueError("the MERL Folder basis needs a folder of .binary files: set "
                             "the basis folder, or choose another basis")
        return kind, bpy.path.abspath(folder)
    if kind == "MEASURED":
        import os

        from ..core.brdf import nbrdf

        pack = bpy.path.abspath(p.measured_pack) if p.measured_pack else os.environ.get(
            MEASURED_PACK_VARIABLE, "")
        if not pack:
            pack = str(nbrdf.BUNDLED_PACK)
        if not os.path.isfile(pack):
            raise ValueError(f"the measured basis needs a pack like merl_nbrdf.npz, and {pack} "
                             "is not a file: correct Measured Pack in the preferences (or "
                             f"${MEASURED_PACK_VARIABLE}), or choose another basis")
        return kind, pack
    return "ANALYTIC", ""


def basis_plan(scene=None) -> dict:
    """What :func:`load_planned` needs, read from Blender (main thread): the basis
    :func:`basis_choice` names and the cache folder. ValueError (one sentence) when
    its source is missing, so a run refuses it before any work."""
    kind, source = basis_choice(scene)
    return {"kind": kind, "source": source, "cache_dir": str(cache_dir())}


def load_planned(plan: dict, progress=None, cancelled=None):
    """The basis of a :func:`basis_plan`, cached (no bpy: a worker thread may call it);
    and its description for the report ({"kind", "source", "fingerprint",
    "n_columns", "n_components"}). progress(fraction, message), cancelled(): as in
    ``core.brdf.basis.build``, used when the cache misses (first run)."""
    from ..core.brdf import basis

    kind, source = plan["kind"], plan["source"]
    options = dict(cache_dir=plan["cache_dir"], progress=progress, cancelled=cancelled)
    if kind == "FOLDER":
        B = basis.load_merl_folder(source, **options)
    elif kind == "MEASURED":
        B = basis.load_measured(source, **options)
    else:
        B = basis.load_default(**options)
    return B, {"kind": kind.lower(), "source": source, "fingerprint": B.fingerprint,
               "n_columns": int(B.info.get("n_columns", 0)), "n_components": B.n_components}


def load_basis(scene=None, progress=None, cancelled=None):
    """:func:`load_planned` of :func:`basis_plan` in one call (main thread)."""
    return load_planned(basis_plan(scene), progress=progress, cancelled=cancelled)


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
