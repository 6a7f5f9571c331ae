"""Import cameras from a COLMAP model: ``brdf.import_colmap``.

What each camera carries is described in ``brdf_addon/colmap_import.py``;
importing a model again updates the cameras of its images (one camera per
image). The report names the model folder by its last two parts: "Imported 6
cameras from sparse/0", "Updated 6 cameras from sparse/0".
"""

import bpy
from bpy.props import BoolProperty, StringProperty

from ..brdf_addon import colmap_import


class BRDF_OT_import_colmap(bpy.types.Operator):
    """Import cameras (and optionally sparse points) from a COLMAP model folder"""

    bl_idname = "brdf.import_colmap"
    # one line: a wrapped docstring would carry its line break into the tooltip
    bl_description = ("Import cameras (and optionally sparse points) from a COLMAP model "
                      "folder; cameras already imported for the same images are updated")
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
            done = colmap_import.import_model(context, self.directory,
                                              point_cloud=self.point_cloud)
        except ValueError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        cameras = done.cameras
        distorted = sum(bool(obj["brdf_colmap_distorted"]) for obj in cameras)
        if distorted:
            summary = done.summary()
            self.report(
                {"WARNING"},
                f"{distorted} of {len(cameras)} cameras have lens distortion; their lit "
                f"photos will be undistorted automatically before use "
                f"({summary[0].lower()}{summary[1:]})",
            )
        else:
            self.report({"INFO"}, done.summary())
        return {"FINISHED"}


CLASSES = (BRDF_OT_import_colmap,)
