"""Export a region's reconstructed table: ``brdf.export``.

Copies the MERL ``.binary`` the run wrote (``scene.brdf.results``) to a path
the user picks, with the run's ``report.json`` beside it as
``<name>_report.json``. The file browser warns of an existing file (its name
turns red: ``check_existing``, from ``ExportHelper``); the operator itself
still refuses to replace an existing table or report unless Overwrite is
ticked. Both files are written through ``core.files.replacing`` (a temporary
name renamed when complete), so an error never leaves half a file.
"""

import os
import shutil

import bpy
from bpy.props import BoolProperty, IntProperty, StringProperty
from bpy_extras.io_utils import ExportHelper

from ..core import files


class BRDF_OT_export(bpy.types.Operator, ExportHelper):
    """Save a region's BRDF as a MERL .binary file (and its report.json)"""

    bl_idname = "brdf.export"
    bl_label = "Export MERL Table"

    # filepath and check_existing (True: the file browser warns of an existing
    # file) come from ExportHelper
    filename_ext = ".binary"
    filter_glob: StringProperty(default="*.binary", options={"HIDDEN"})
    index: IntProperty(default=0, options={"HIDDEN"}, description="Result entry to export")
    overwrite: BoolProperty(name="Overwrite", default=False,
                            description="Replace an existing file of that name (and its "
                            "_report.json)")

    @classmethod
    def poll(cls, context):
        s = getattr(context.scene, "brdf", None)
        return s is not None and any(r.status == "ok" for r in s.results)

    def invoke(self, context, _event):
        results = context.scene.brdf.results
        if 0 <= self.index < len(results):
            self.filepath = bpy.path.ensure_ext(bpy.path.clean_name(results[self.index].label),
                                                self.filename_ext)
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def execute(self, context):
        results = context.scene.brdf.results
        if not 0 <= self.index < len(results) or results[self.index].status != "ok":
            self.report({"ERROR"}, f"No reconstructed region number {self.index}")
            return {"CANCELLED"}
        source = bpy.path.abspath(results[self.index].table_path)
        target = bpy.path.abspath(bpy.path.ensure_ext(self.filepath, self.filename_ext))
        report = os.path.join(os.path.dirname(source), "report.json")
        report_target = os.path.splitext(target)[0] + "_report.json"
        if not os.path.isfile(source):
            self.report({"ERROR"}, f"The table file is gone: {source}")
            return {"CANCELLED"}
        if not os.path.isdir(os.path.dirname(target) or "."):
            self.report({"ERROR"}, f"The folder of {target} does not exist; choose an "
                        "existing folder")
            return {"CANCELLED"}
        if os.path.exists(target) and os.path.samefile(source, target):
            self.report({"ERROR"}, f"{target} is the run's own table; choose another name")
            return {"CANCELLED"}
        writes = [target] + ([report_target] if os.path.isfile(report) else [])
        if not self.overwrite:
            taken = [path for path in writes if os.path.exists(path)]
            if taken:
                self.report({"ERROR"}, f"{taken[0]} exists; choose another name, or tick "
                            "Overwrite to replace it")
                return {"CANCELLED"}
        try:
            for origin, destination in zip((source, report), writes, strict=False):
                with files.replacing(destination) as tmp:
                    shutil.copyfile(origin, tmp)
        except OSError as error:  # a full disk, no permission: one line, the old file kept
            self.report({"ERROR"}, f"Could not write {destination}: "
                        f"{error.strerror or error}")
            return {"CANCELLED"}
        self.report({"INFO"}, f"Saved {target}")
        return {"FINISHED"}


CLASSES = (BRDF_OT_export,)
