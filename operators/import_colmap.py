"""Import cameras from a COLMAP model: ``brdf.import_colmap``.

What each camera carries is described in ``brdf_addon/colmap_import.py``.
"""

import os

import bpy
from bpy.props import BoolProperty, StringProperty

from ..brdf_addon import colmap_import


class BRDF_OT_import_colmap(bpy.types.Operator):
    """Import cameras (and optionally sparse points) from a COLMAP model folder"""

    bl_idname = "brdf.import_colmap"
    bl_label = "Import COLMAP Cameras"
    bl_options = {"REGISTER", "UNDO"}

    directory: StringProperty(
        name="Model Folder",
        description="COLMAP model folder holding cameras, images and points3D (.bin or .txt)",
        subtype="DIR_PATH",
    )
    filter_folder: BoolProperty(default=True, options={"HIDDEN", "SKIP_SAVE"})
    point_cloud: BoolProperty(
        name="Point Cloud",
        description="Also create a mesh object of the model's sparse 3D points",
        default=False,
    )

    def invoke(self, context, event):
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def execute(self, context):
        try:
            cameras = colmap_import.import_cameras(context, self.directory,
                                                   point_cloud=self.point_cloud)
        except ValueError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        distorted = sum(bool(obj["brdf_colmap_distorted"]) for obj in cameras)
        if distorted:
            self.report(
                {"WARNING"},
                f"{distorted} of {len(cameras)} cameras have lens distortion; their lit "
                "photos will be undistorted automatically before use",
            )
        else:
            folder = os.path.basename(os.path.normpath(bpy.path.abspath(self.directory)))
            self.report({"INFO"}, f"Imported {len(cameras)} cameras from {folder}")
        return {"FINISHED"}


CLASSES = (BRDF_OT_import_colmap,)
