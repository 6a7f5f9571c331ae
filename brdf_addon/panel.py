"""Sidebar panels in the 3D viewport (N panel, tab "BRDF")."""

from bpy.types import Panel


class BRDF_PT_main(Panel):
    bl_idname = "BRDF_PT_main"
    bl_label = "BRDF Reconstruct"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "BRDF"

    def draw(self, context):
        layout = self.layout
        layout.label(text="The reconstruction workflow comes in later versions.")
        layout.prop(context.scene.brdf, "seed")


CLASSES = (BRDF_PT_main,)
