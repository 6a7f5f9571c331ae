"""Sidebar panels in the 3D viewport (N panel, tab "BRDF"), in workflow order:
Scan -> Cameras -> Photos -> Light -> Settings -> Reconstruct -> Results.

Each panel's ``draw`` only reads ``scene.brdf`` and lays out widgets, so the
tests drive every ``draw`` through a stand-in layout that records the calls
(pip ``bpy`` has no window system), for each state: nothing set, photos added,
running, results.

Translation: a constant label is a plain string (Blender translates it as it
draws). A label with values in it is a constant format string translated with
``iface_`` (``bpy.app.translations.pgettext_iface``) and then filled, drawn with
``translate=False``; names and messages from the data (photo, camera, region
names, reasons, notes) are drawn with ``translate=False`` too.
"""

import json

import bpy
from bpy.app.translations import pgettext_iface as iface_
from bpy.types import Panel, UIList

from . import presets


class BRDF_UL_photos(UIList):
    """The lit photos: image name, camera, light source."""

    def draw_item(self, _context, layout, _data, item, _icon, _active_data, _active_prop,
                  _index=0, _flt_flag=0):
        row = layout.row(align=True)
        if item.name:
            row.label(text=item.name, translate=False, icon="IMAGE_DATA")
        else:
            row.label(text="(no image)", icon="IMAGE_DATA")
        if item.camera:
            row.label(text=item.camera.name, translate=False, icon="CAMERA_DATA")
        else:
            row.label(text="no camera", icon="ERROR")
        # the light source's own UI name (constant, so translated as it draws)
        light = item.bl_rna.properties["light_source"].enum_items[item.light_source]
        row.label(text=light.name, icon="LIGHT_SUN")


class _BRDFPanel:
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "BRDF"

    @classmethod
    def poll(cls, context):
        return getattr(context.scene, "brdf", None) is not None


class BRDF_PT_main(_BRDFPanel, Panel):
    """Scan: the target object and how it is split into regions."""

    bl_idname = "BRDF_PT_main"
    bl_label = "BRDF Reconstruct"

    def draw(self, context):
        layout = self.layout
        s = context.scene.brdf
        layout.label(text="Scan", icon="MESH_DATA")
        layout.prop(s, "target")
        layout.prop(s, "region_mode")
        if s.target is not None and s.target.type == "MESH" and s.region_mode == "MATERIAL_SLOT":
            regions = max(len(s.target.material_slots), 1)
            layout.label(text=iface_("{count} region(s)").format(count=regions),
                         translate=False)


class BRDF_PT_cameras(_BRDFPanel, Panel):
    bl_idname = "BRDF_PT_cameras"
    bl_label = "Cameras"
    bl_parent_id = "BRDF_PT_main"

    def draw(self, context):
        layout = self.layout
        cameras = [o for o in context.scene.objects if o.type == "CAMERA"]
        layout.operator("brdf.import_colmap", icon="IMPORT")
        layout.label(text=iface_("{count} camera(s) in the scene").format(count=len(cameras)),
                     translate=False)


class BRDF_PT_photos(_BRDFPanel, Panel):
    bl_idname = "BRDF_PT_photos"
    bl_label = "Photos"
    bl_parent_id = "BRDF_PT_main"

    def draw(self, context):
        layout = self.layout
        s = context.scene.brdf
        row = layout.row()
        row.template_list("BRDF_UL_photos", "", s, "photos", s, "active_photo", rows=3)
        col = row.column(align=True)
        col.operator("brdf.add_photos", icon="ADD", text="")
        col.operator("brdf.remove_photo", icon="REMOVE", text="")
        if 0 <= s.active_photo < len(s.photos):
            photo = s.photos[s.active_photo]
            layout.prop(photo, "filepath")
            layout.prop(photo, "camera")
            layout.prop(photo, "color_space")
            layout.prop(photo, "exposure")
            layout.prop(photo, "mask_path")
            layout.prop(photo, "silhouette_margin")
            layout.prop(photo, "irradiance")
            layout.prop(photo, "reference_kind")
            if photo.reference_kind != "NONE":
                layout.prop(photo, "reference_mask_path")
        elif not len(s.photos):
            layout.label(text="Add the photos taken under one distant light")


class BRDF_PT_light(_BRDFPanel, Panel):
    bl_idname = "BRDF_PT_light"
    bl_label = "Light"
    bl_parent_id = "BRDF_PT_main"

    def draw(self, context):
        layout = self.layout
        s = context.scene.brdf
        if not 0 <= s.active_photo < len(s.photos):
            layout.label(text="Select a photo to set its light")
            return
        photo = s.photos[s.active_photo]
        layout.prop(photo, "light_source")
        if photo.light_source == "SUN_OBJECT":
            layout.prop(photo, "sun")
            layout.operator("brdf.light_from_sun", icon="LIGHT_SUN")
        elif photo.light_source == "DIRECTION":
            layout.prop(photo, "direction")
        elif photo.light_source == "PROBE":
            layout.prop(photo, "probe_path")
            layout.prop(photo, "probe_radius")
            if photo.probe_radius > 0:
                layout.prop(photo, "probe_center")
            layout.operator("brdf.light_from_probe", icon="SHADING_RENDERED")
        else:
            layout.prop(photo, "time_from_exif")
            if not photo.time_from_exif:
                layout.prop(photo, "when")
            layout.prop(photo, "utc_offset")
            layout.prop(photo, "place_from_exif")
            if not photo.place_from_exif:
                layout.prop(photo, "latitude")
                layout.prop(photo, "longitude")
            layout.prop(photo, "north_offset")
            row = layout.row()
            row.prop(s, "scene_up")
            layout.operator("brdf.up_from_cameras", icon="ORIENTATION_GLOBAL")
            layout.operator("brdf.light_from_time", icon="TIME")


class BRDF_PT_settings(_BRDFPanel, Panel):
    bl_idname = "BRDF_PT_settings"
    bl_label = "Settings"
    bl_parent_id = "BRDF_PT_main"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout = self.layout
        s = context.scene.brdf
        layout.prop(s, "preset")
        if s.preset != "CUSTOM":
            layout.label(text=presets.HINTS[s.preset], icon="INFO")
        col = layout.column(heading="Reliable Region")
        col.prop(s, "use_curvature")
        sub = col.column()
        sub.active = s.use_curvature
        sub.prop(s, "curvature_threshold")
        col.prop(s, "use_monotonicity")
        sub = col.column()
        sub.active = s.use_monotonicity
        sub.prop(s, "monotonicity_tolerance")
        col.prop(s, "use_brightest")
        sub = col.column()
        sub.active = s.use_brightest
        sub.prop(s, "peak_max_angle")
        col.prop(s, "clip_level")
        col.prop(s, "min_cosine")
        col = layout.column(heading="Sampling")
        for name in ("samples", "sampler", "trials", "subset_fraction",
                     "min_reliable_samples", "keep_highlight_energy"):
            col.prop(s, name)
        sub = col.column()
        sub.active = s.keep_highlight_energy and not s.refine_to_photos
        sub.prop(s, "photo_consistent")
        col.prop(s, "refine_to_photos")
        sub = col.column()
        sub.active = s.keep_highlight_energy or s.refine_to_photos
        sub.prop(s, "pixel_footprint")
        layout.prop(s, "material_model")
        layout.prop(s, "export_gltf")
        col = layout.column(heading="Texture")
        col.prop(s, "texture")
        sub = col.column()
        sub.active = s.texture
        sub.prop(s, "texture_size")
        sub.prop(s, "uv_map")
        if s.texture and s.target is not None and s.target.type == "MESH" and not len(
                s.target.data.uv_layers):
            sub.label(text="The scan has no UV map", icon="ERROR")
            sub.operator("brdf.uv_copy")
        col = layout.column(heading="Selection")
        col.prop(s, "kl_path")
        col.prop(s, "kl_bins")
        if s.kl_path == "CYCLES":
            col.prop(s, "kl_samples")
        layout.prop(s, "seed")
        layout.prop(s, "basis")
        if s.basis == "FOLDER":
            layout.prop(s, "basis_folder")
        layout.prop(s, "output_dir")
        layout.prop(s, "overwrite")


class BRDF_PT_reconstruct(_BRDFPanel, Panel):
    bl_idname = "BRDF_PT_reconstruct"
    bl_label = "Reconstruct"
    bl_parent_id = "BRDF_PT_main"

    def draw(self, context):
        layout = self.layout
        s = context.scene.brdf
        if s.running:
            layout.prop(s, "progress", text=s.status or iface_("Running"), translate=False,
                        slider=True)
            layout.label(text="Press Esc to cancel", icon="CANCEL")
            return
        row = layout.row()
        row.scale_y = 1.5
        row.operator("brdf.reconstruct", icon="PLAY")
        if s.target is None:
            layout.label(text="Choose the scan first", icon="INFO")
        elif not len(s.photos):
            layout.label(text="Add lit photos first", icon="INFO")


class BRDF_PT_results(_BRDFPanel, Panel):
    bl_idname = "BRDF_PT_results"
    bl_label = "Results"
    bl_parent_id = "BRDF_PT_main"

    def draw(self, context):
        layout = self.layout
        s = context.scene.brdf
        if not len(s.results):
            layout.label(text="No results yet")
            return
        notes = json.loads(s.capture_notes or "[]")
        if notes:
            box = layout.box()
            box.label(text="Photos", icon="IMAGE_DATA")
            for line in notes:
                box.label(text=line, translate=False)
        for i, r in enumerate(s.results):
            box = layout.box()
            box.label(text=r.label, translate=False,
                      icon="MATERIAL" if r.status == "ok" else "ERROR")
            if r.status != "ok":
                box.label(text=r.reason, translate=False)
                continue
            box.label(text=iface_("Trial {trial}, KL {kl:.4f}").format(trial=r.winner, kl=r.kl),
                      translate=False)
            for line in json.loads(r.notes or "[]"):
                box.label(text=line, translate=False, icon="ERROR")
            counts = json.loads(r.counts or "{}")
            removed = "".join(iface_(", -{count} {stage}").format(count=v, stage=k)
                              for k, v in counts.get("removed", {}).items())
            box.label(text=iface_("Samples: {observed} observed{removed}, {reliable} reliable")
                      .format(observed=counts.get("observed", 0), removed=removed,
                              reliable=counts.get("reliable", 0)), translate=False)
            if r.bake_error >= 0:
                box.label(text=iface_("Bake error {error:.3f}").format(error=r.bake_error),
                          translate=False)
            if r.material is not None:
                box.prop(r, "material", text="")
            row = box.row()
            row.label(text=bpy.path.basename(r.table_path), translate=False, icon="FILE")
            row.operator("brdf.export", icon="EXPORT", text="").index = i
            for name in ("slice_plot", "plot"):
                if getattr(r, name) is not None:
                    box.label(text=r.bl_rna.properties[name].name)
                    box.template_ID_preview(r, name, hide_buttons=True)


CLASSES = (BRDF_UL_photos, BRDF_PT_main, BRDF_PT_cameras, BRDF_PT_photos, BRDF_PT_light,
           BRDF_PT_settings, BRDF_PT_reconstruct, BRDF_PT_results)
