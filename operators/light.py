"""The light of each photo: ``brdf.light_from_sun``, ``brdf.light_from_probe``,
``brdf.light_from_time``, and :func:`photo_light`, which every step uses.

Directions are world-space unit vectors *towards* the distant light. A Blender
Sun shines along its local -Z, so the direction towards it is the object's
local +Z axis in world space. Sun position: ``core.sun`` (NOAA) gives
(east, north, up); the scene's north is +Y turned by the photo's north offset
about +Z. The light probe: ``core.light_probe`` on the probe photo, seen by
the photo's camera (perspective intrinsics from the camera and render size).
"""

import datetime as dt
import math

import bpy
import numpy as np
from mathutils import Vector

from ..core import light_probe, photo_io, sun

SUN_NAME = "BRDF Sun"


def sun_object_direction(obj) -> np.ndarray:
    """(3,) world direction towards a Sun object's light (its local +Z)."""
    z = obj.matrix_world.to_3x3() @ Vector((0.0, 0.0, 1.0))
    return np.array(z.normalized(), dtype=np.float64)


def parse_when(text: str, utc_offset_hours: float) -> dt.datetime:
    """Timezone-aware datetime from 'YYYY-MM-DD HH:MM[:SS]' and hours east of UTC."""
    try:
        naive = dt.datetime.fromisoformat(text.strip())
    except ValueError:
        raise ValueError(f"date and time {text!r} is not YYYY-MM-DD HH:MM:SS") from None
    return naive.replace(tzinfo=dt.timezone(dt.timedelta(hours=utc_offset_hours)))


def sun_position_direction(photo) -> np.ndarray:
    """(3,) world direction towards the sun at the photo's date, time and place."""
    when = parse_when(photo.when, photo.utc_offset)
    local = sun.sun_direction(when, photo.latitude, photo.longitude)
    sun.check_above_horizon(local, when, photo.latitude, photo.longitude)
    a = math.radians(photo.north_offset)
    rot = np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0],
                    [0.0, 0.0, 1.0]])
    return rot @ local


def camera_intrinsics(scene, camera_obj, width: int, height: int):
    """A ``light_probe.PerspectiveCamera`` for a Blender camera rendering W x H pixels,
    or "orthographic"."""
    cam = camera_obj.data
    if cam.type == "ORTHO":
        return "orthographic"
    fit = cam.sensor_fit
    if fit == "AUTO":
        fit = "HORIZONTAL" if width >= height else "VERTICAL"
    sensor = cam.sensor_width if fit == "HORIZONTAL" else cam.sensor_height
    size = width if fit == "HORIZONTAL" else height
    focal = cam.lens / sensor * size
    unit = max(width, height) if cam.sensor_fit == "AUTO" else size
    return light_probe.PerspectiveCamera(
        focal_px=focal,
        principal_px=(width / 2 - cam.shift_x * unit - 0.5,
                      height / 2 + cam.shift_y * unit - 0.5))


def probe_direction(scene, photo) -> np.ndarray:
    """(3,) world direction from the probe photo (sphere detected automatically)."""
    if not photo.probe_path:
        raise ValueError(f"photo {photo.name} has no sphere-probe photo")
    if photo.camera is None:
        raise ValueError(f"photo {photo.name} has no camera for its probe")
    image = photo_io.read_photo(bpy.path.abspath(photo.probe_path))
    h, w = image.shape[:2]
    camera = camera_intrinsics(scene, photo.camera, w, h)
    # the sphere's outline: halfway up to the 99th percentile of luminance, so the
    # highlight (a few pixels, far brighter) does not set the threshold
    lum = np.nan_to_num(image @ np.array([0.2126, 0.7152, 0.0722]))
    top = float(np.percentile(lum, 99))
    center, radius = light_probe.detect_sphere(lum > 0.5 * (lum.min() + top), camera=camera)
    rotation = np.array(photo.camera.matrix_world.to_3x3().normalized())
    result = light_probe.light_from_sphere(image, center, radius, camera, rotation)
    return result.direction_world


def photo_light(scene, photo) -> np.ndarray:
    """(3,) world unit direction towards the photo's light; ValueError (one sentence)
    when it cannot be found or is below the horizon of the scene (z <= 0 is
    allowed only for a direction or Sun object: objects can be lit from below)."""
    source = photo.light_source
    if source == "SUN_OBJECT":
        if photo.sun is None:
            raise ValueError(f"photo {photo.name} has no Sun object for its light")
        direction = sun_object_direction(photo.sun)
    elif source == "DIRECTION":
        direction = np.array(photo.direction, dtype=np.float64)
        if not np.linalg.norm(direction) > 0:
            raise ValueError(f"photo {photo.name} has a zero light direction")
    elif source == "PROBE":
        direction = probe_direction(scene, photo)
    elif source == "SUN_POSITION":
        direction = sun_position_direction(photo)
    else:
        raise ValueError(f"photo {photo.name}: unknown light source {source}")
    return direction / np.linalg.norm(direction)


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
            direction = probe_direction(context.scene, photo)
        except ValueError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        photo.direction = direction.tolist()
        photo.light_source = "DIRECTION"
        self.report({"INFO"}, f"{photo.name}: light {np.round(direction, 4).tolist()}")
        return {"FINISHED"}


class BRDF_OT_light_from_time(_PhotoOperator):
    """Set the active photo's light from date, time and place; creates or updates
    the Sun object "BRDF Sun" to show it"""

    bl_idname = "brdf.light_from_time"
    bl_label = "Light from Date, Time, Place"

    def execute(self, context):
        photo = _active_photo(context)
        try:
            direction = sun_position_direction(photo)
        except ValueError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        obj = update_sun_object(context.scene, direction)
        photo.light_source = "SUN_POSITION"
        photo.sun = obj
        self.report({"INFO"}, f"{photo.name}: sun at {np.round(direction, 4).tolist()}")
        return {"FINISHED"}


def update_sun_object(scene, direction) -> bpy.types.Object:
    """Create or re-aim the Sun object named "BRDF Sun" (ours; never a user's light)."""
    obj = bpy.data.objects.get(SUN_NAME)
    if obj is None or obj.type != "LIGHT" or not obj.get("brdf_created"):
        data = bpy.data.lights.new(SUN_NAME, "SUN")
        obj = bpy.data.objects.new(SUN_NAME, data)
        obj["brdf_created"] = True
        scene.collection.objects.link(obj)
    obj.rotation_mode = "QUATERNION"
    obj.rotation_quaternion = Vector((0.0, 0.0, 1.0)).rotation_difference(
        Vector(tuple(direction)))
    return obj


CLASSES = (BRDF_OT_light_from_sun, BRDF_OT_light_from_probe, BRDF_OT_light_from_time)
