"""Add and remove lit photos: ``brdf.add_photos``, ``brdf.remove_photo``.

Matching a photo to its camera is ``brdf_addon/photo_list.py``.
"""

import os

import bpy
from bpy.props import CollectionProperty, IntProperty, StringProperty
from bpy.types import OperatorFileListElement

from ..brdf_addon import photo_list


class BRDF_OT_add_photos(bpy.types.Operator):
    """Add lit photos; each is matched to a camera by image name"""

    bl_idname = "brdf.add_photos"
    bl_label = "Add Lit Photos"
    bl_options = {"REGISTER", "UNDO"}

    directory: StringProperty(subtype="DIR_PATH", description="Folder of the chosen photos")
    files: CollectionProperty(type=OperatorFileListElement,
                              description="The chosen photo files")
    filter_image: bpy.props.BoolProperty(default=True, options={"HIDDEN"})

    @classmethod
    def poll(cls, context):
        return hasattr(context.scene, "brdf") and not context.scene.brdf.running

    def invoke(self, context, _event):
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def execute(self, context):
        paths = [os.path.join(self.directory, f.name) for f in self.files if f.name]
        if not paths:
            self.report({"ERROR"}, "Choose one or more photo files")
            return {"CANCELLED"}
        added, unmatched = photo_list.add_photos(context.scene, paths)
        for message in unmatched:
            self.report({"WARNING"}, message)
        if not added:
            self.report({"ERROR"}, f"No photo added: {len(unmatched)} not matched to a camera")
            return {"CANCELLED"}
        self.report({"INFO"}, f"Added {len(added)} photo(s), {len(unmatched)} not matched")
        return {"FINISHED"}


class BRDF_OT_remove_photo(bpy.types.Operator):
    """Remove the photo from the list (the file is not touched)"""

    bl_idname = "brdf.remove_photo"
    bl_label = "Remove Photo"
    bl_options = {"REGISTER", "UNDO"}

    index: IntProperty(default=-1, description="Entry to remove (-1 = the active one)")

    @classmethod
    def poll(cls, context):
        return (hasattr(context.scene, "brdf") and len(context.scene.brdf.photos) > 0
                and not context.scene.brdf.running)

    def execute(self, context):
        settings = context.scene.brdf
        index = settings.active_photo if self.index < 0 else self.index
        if not 0 <= index < len(settings.photos):
            self.report({"ERROR"}, f"No photo number {index}")
            return {"CANCELLED"}
        settings.photos.remove(index)
        settings.active_photo = min(settings.active_photo, max(len(settings.photos) - 1, 0))
        return {"FINISHED"}


CLASSES = (BRDF_OT_add_photos, BRDF_OT_remove_photo)
