"""Export a region's reconstructed table: ``brdf.export``.

Copies the MERL ``.binary`` the run wrote (``scene.brdf.results``) to a path
the user picks, with ``report.json`` beside it. Refuses to overwrite an
existing file unless asked (the file browser's own overwrite check applies).
"""

import os
import shutil

import bpy
from bpy.props import BoolProperty, IntProperty, StringProperty


class BRDF_OT_export(bpy.types.Operator):
    """Save a region's BRDF as a MERL .binary file (and its report.json)"""

    bl_idname = "brdf.export"
    bl_label = "Export MERL Table"

    filepath: StringProperty(subtype="FILE_PATH")
    filter_glob: StringProperty(default="*.binary", options={"HIDDEN"})
    index: IntProperty(default=0, description="Result entry to export")
    overwrite: BoolProperty(default=False, description="Replace an existing file")

    @classmethod
    def poll(cls, context):
        s = getattr(context.scene, "brdf", None)
        return s is not None and any(r.status == "ok" for r in s.results)

    def invoke(self, context, _event):
        result = context.scene.brdf.results[self.index]
        self.filepath = bpy.path.ensure_ext(bpy.path.clean_name(result.label), ".binary")
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def execute(self, context):
        results = context.scene.brdf.results
        if not 0 <= self.index < len(results) or results[self.index].status != "ok":
            self.report({"ERROR"}, f"No reconstructed region number {self.index}")
            return {"CANCELLED"}
        source = bpy.path.abspath(results[self.index].table_path)
        target = bpy.path.abspath(bpy.path.ensure_ext(self.filepath, ".binary"))
        if not os.path.isfile(source):
            self.report({"ERROR"}, f"The table file is gone: {source}")
            return {"CANCELLED"}
        if os.path.exists(target) and not self.overwrite:
            self.report({"ERROR"}, f"{target} exists; choose another name")
            return {"CANCELLED"}
        shutil.copyfile(source, target)
        report = os.path.join(os.path.dirname(source), "report.json")
        if os.path.isfile(report):
            shutil.copyfile(report, os.path.splitext(target)[0] + "_report.json")
        self.report({"INFO"}, f"Saved {target}")
        return {"FINISHED"}


CLASSES = (BRDF_OT_export,)
