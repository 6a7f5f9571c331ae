"""The light of a photo, set from the panel: ``brdf.light_from_sun``,
``brdf.light_from_probe``, ``brdf.light_from_time``, ``brdf.up_from_cameras``.

The directions and their conventions are in ``brdf_addon/light_sources.py``.
"""

import math

import bpy
import numpy as np

from ..brdf_addon import light_sources


def _active_photo(context):
    settings = context.scene.brdf
    if not 0 <= settings.active_photo < len(settings.photos):
        return None
    return settings.photos[settings.active_photo]


class _PhotoOperator(bpy.types.Operator):
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return (hasattr(context.scene, "brdf") and not context.scene.brdf.running
                and _active_photo(context) is not None)


class BRDF_OT_light_from_sun(_PhotoOperator):
    """Use the active Sun object as the active photo's light"""

    bl_idname = "brdf.light_from_sun"
    bl_label = "Light from Sun Object"

    def execute(self, context):
        photo = _active_photo(context)
        obj = context.active_object
        if obj is None or obj.type != "LIGHT" or obj.data.type != "SUN":
            suns = [o for o in context.scene.objects
                    if o.type == "LIGHT" and o.data.type == "SUN"]
            if len(suns) != 1:
                self.report({"ERROR"}, "Select the Sun light to use (the scene has "
                            f"{len(suns)} Sun objects)")
                return {"CANCELLED"}
            obj = suns[0]
        photo.light_source = "SUN_OBJECT"
        photo.sun = obj
        self.report({"INFO"}, f"{photo.name}: light from {obj.name}")
        return {"FINISHED"}


class BRDF_OT_light_from_probe(_PhotoOperator):
    """Find the light direction from the active photo's sphere-probe photo"""

    bl_idname = "brdf.light_from_probe"
    bl_label = "Light from Sphere Probe"

    def execute(self, context):
        photo = _active_photo(context)
        try:
            result = light_sources.probe_result(context.scene, photo)
        except ValueError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        direction = result.direction_world
        photo.direction = direction.tolist()
        photo.light_source = "DIRECTION"
        self.report({"INFO"}, f"{photo.name}: light {np.round(direction, 4).tolist()}, "
                    f"uncertainty {math.degrees(result.uncertainty_rad):.2f} deg")
        return {"FINISHED"}


class BRDF_OT_light_from_time(_PhotoOperator):
    """Set the active photo's light from date, time and place"""

    bl_idname = "brdf.light_from_time"
    # one line: a wrapped docstring would carry its line break into the tooltip
    bl_description = ("Set the active photo's light from date, time and place; creates or "
                      "updates the Sun object \"BRDF Sun\" to show it")
    bl_label = "Light from Date, Time, Place"

    def execute(self, context):
        photo = _active_photo(context)
        try:
            direction = light_sources.sun_position_direction(photo, context.scene)
        except ValueError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        obj = light_sources.update_sun_object(context.scene, direction)
        photo.light_source = "SUN_POSITION"
        photo.sun = obj
        self.report({"INFO"}, f"{photo.name}: sun at {np.round(direction, 4).tolist()}")
        return {"FINISHED"}


class BRDF_OT_up_from_cameras(bpy.types.Operator):
    """Set the scene's up (the sky, for the sun's direction) from the cameras"""

    bl_idname = "brdf.up_from_cameras"
    bl_description = ("Set the scene's up (the sky, for the sun's direction) from the "
                      "cameras: the normal of the plane of their centers, or their mean up "
                      "axis")
    bl_label = "Up from Cameras"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return hasattr(context.scene, "brdf") and not context.scene.brdf.running

    def execute(self, context):
        try:
            up, spread = light_sources.up_from_cameras(context.scene)
        except ValueError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        context.scene.brdf.scene_up = up.tolist()
        self.report({"INFO"}, f"scene up {np.round(up, 4).tolist()} (cameras spread "
                    f"{math.degrees(spread):.1f} deg)")
        return {"FINISHED"}


CLASSES = (BRDF_OT_light_from_sun, BRDF_OT_light_from_probe, BRDF_OT_light_from_time,
           BRDF_OT_up_from_cameras)
