"""A UV map on a copy of the scan: ``brdf.uv_copy`` (``brdf_addon/uv_copy.py``).

For a scan without a UV map that the user wants textured: the copy gets the map and
becomes the run's scan; the original object and mesh are unchanged (undoable).
"""

import bpy

from ..brdf_addon import uv_copy


class BRDF_OT_uv_copy(bpy.types.Operator):
    """Give a copy of the scan a UV map (Smart UV Project) to reconstruct on; the scan stays"""

    bl_idname = "brdf.uv_copy"
    bl_label = "Make UV Map on a Copy"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        s = getattr(context.scene, "brdf", None)
        obj = None if s is None else s.target
        return (s is not None and not s.running and obj is not None and obj.type == "MESH"
                and not len(obj.data.uv_layers))

    def execute(self, context):
        s = context.scene.brdf
        original = s.target
        try:
            copy = uv_copy.make_uv_copy(context.scene, original)
        except (ValueError, RuntimeError) as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        s.target, s.uv_map = copy, uv_copy.UV_NAME
        self.report({"INFO"}, f"The scan is now {copy.name}, a copy with a UV map; "
                    f"{original.name} is unchanged")
        return {"FINISHED"}


CLASSES = (BRDF_OT_uv_copy,)
