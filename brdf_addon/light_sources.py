"""The light of each photo as a world direction: :func:`photo_light`, which every step
uses, and the Sun object the light operators aim (``operators/light.py``, the panel's buttons).

Directions are world-space unit vectors *towards* the distant light. A Blender
Sun shines along its local -Z, so the direction towards it is the object's
local +Z axis in world space. Sun position: ``core.capture.sun`` (NOAA) gives
(east, north, up); ``core.capture.scene_frame`` maps it into the scene, whose up is
``scene.brdf.scene_up`` (set by hand or from the cameras, ``brdf.up_from_cameras``)
and whose north is +Y (projected off that up) turned by the photo's north
offset. Date, time and place may come from the photo's EXIF and GPS
(``core.capture.exif``). The light probe: ``core.capture.light_probe`` on the probe photo, seen
by the photo's camera (perspective intrinsics from the camera and render size);
the sphere is found automatically or given as a centre and radius in pixels.
"""

import datetime as dt
import math

import bpy
import numpy as np
from mathutils import Vector

from ..core.capture import exif, light_probe, photo_io, scene_frame, sun

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


def when_and_where(photo) -> tuple[dt.datetime, float, float, list[str]]:
    """The photo's (aware datetime, latitude, longitude) and where each came from:
    typed, or the lit photo's EXIF date/time (with its UTC offset where the camera
    wrote one, else the typed offset) and GPS position."""
    notes = []
    metadata = {}
    if photo.time_from_exif or photo.place_from_exif:
        metadata = photo_io.read_metadata(bpy.path.abspath(photo.filepath))
    if photo.time_from_exif:
        found = exif.capture_time(metadata)
        if found is None:
            raise ValueError(f"photo {photo.name} has no EXIF date and time; type them")
        when, has_offset = found
        if not has_offset:
            when = when.replace(tzinfo=dt.timezone(dt.timedelta(hours=photo.utc_offset)))
        notes.append(f"time {when.isoformat()} from EXIF"
                     + ("" if has_offset else " (UTC offset typed)"))
    else:
        when = parse_when(photo.when, photo.utc_offset)
    if photo.place_from_exif:
        place = exif.gps_position(metadata)
        if place is None:
            raise ValueError(f"photo {photo.name} has no GPS position in its EXIF; type "
                             "latitude and longitude")
        latitude, longitude = place
        notes.append(f"place {latitude:.5f}, {longitude:.5f} from GPS EXIF")
    else:
        latitude, longitude = photo.latitude, photo.longitude
    return when, latitude, longitude, notes


def sun_position_direction(photo, scene=None, details: dict | None = None) -> np.ndarray:
    """(3,) world direction towards the sun at the photo's date, time and place, in
    the scene's frame (``scene.brdf.scene_up``, +Z without a scene)."""
    when, latitude, longitude, notes = when_and_where(photo)
    local = sun.sun_direction(when, latitude, longitude)
    try:
        sun.check_above_horizon(local, when, latitude, longitude)
    except ValueError as error:
        raise ValueError(f"photo {photo.name}: {error}; check its date, time (and UTC "
                         "offset) and place") from None
    up = (0.0, 0.0, 1.0) if scene is None else tuple(scene.brdf.scene_up)
    world = scene_frame.world_from_enu(up, photo.north_offset) @ local
    if details is not None:
        details.update(notes=notes, when=when.isoformat(), latitude=latitude,
                       longitude=longitude, up=list(up))
    return world


def up_from_cameras(scene) -> tuple[np.ndarray, float]:
    """The scene's up from its cameras (``core.capture.scene_frame.up_from_cameras``) and
    their spread (radians); ValueError with fewer than two cameras."""
    cameras = [o for o in scene.objects if o.type == "CAMERA"]
    if len(cameras) < 2:
        raise ValueError(f"finding up from the cameras needs at least 2, the scene has "
                         f"{len(cameras)}")
    rotations = np.array([np.array(c.matrix_world.to_3x3().normalized()) for c in cameras])
    centres = np.array([np.array(c.matrix_world.translation) for c in cameras])
    return scene_frame.up_from_cameras(rotations, centres)


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


def probe_result(scene, photo) -> light_probe.LightProbeResult:
    """The probe photo's light (world direction, uncertainty, highlight): the sphere
    is the user's circle (``probe_center``, ``probe_radius`` > 0, refined onto the
    outline by ``core.capture.light_probe.refine_sphere``: 1 px off costs about 2 d / r
    radians) or found automatically (``core.capture.light_probe.locate_sphere``)."""
    if not photo.probe_path:
        raise ValueError(f"photo {photo.name} has no sphere-probe photo")
    if photo.camera is None:
        raise ValueError(f"photo {photo.name} has no camera for its probe")
    image = photo_io.read_photo_file(bpy.path.abspath(photo.probe_path)).radiance
    h, w = image.shape[:2]
    camera = camera_intrinsics(scene, photo.camera, w, h)
    if photo.probe_radius > 0:  # the user's circle, snapped to the sphere's outline
        center, radius = light_probe.refine_sphere(image, tuple(photo.probe_center),
                                                   photo.probe_radius, camera=camera)
    else:
        center, radius = light_probe.locate_sphere(image, camera=camera)
    rotation = np.array(photo.camera.matrix_world.to_3x3().normalized())
    return light_probe.light_from_sphere(image, center, radius, camera, rotation)


def probe_direction(scene, photo, details: dict | None = None) -> np.ndarray:
    """(3,) world direction from the probe photo (see :func:`probe_result`)."""
    result = probe_result(scene, photo)
    if details is not None:
        details.update(uncertainty_deg=math.degrees(result.uncertainty_rad),
                       highlight_px=list(result.highlight_px),
                       sphere="given" if photo.probe_radius > 0 else "found")
    return result.direction_world


def photo_light(scene, photo, details: dict | None = None) -> np.ndarray:
    """(3,) world unit direction towards the photo's light; ValueError (one sentence)
    when it cannot be found or is below the horizon of the scene (z <= 0 is
    allowed only for a direction or Sun object: objects can be lit from below).
    details: a dict to fill with how it was found (for the report)."""
    source = photo.light_source
    if details is not None:
        details["source"] = source.lower()
    if source == "SUN_OBJECT":
        if photo.sun is None:
            raise ValueError(f"photo {photo.name} has no Sun object for its light")
        direction = sun_object_direction(photo.sun)
    elif source == "DIRECTION":
        direction = np.array(photo.direction, dtype=np.float64)
        # Blender stores an infinite component as the float32 maximum: not finite either
        shown = np.where(np.abs(direction) >= np.finfo(np.float32).max,
                         np.copysign(np.inf, direction), direction)
        if not np.all(np.isfinite(shown)):
            raise ValueError(f"photo {photo.name} has a light direction that is not finite "
                             f"({', '.join(f'{x:g}' for x in shown)}): type three numbers")
        if not np.linalg.norm(direction) > 0:
            raise ValueError(f"photo {photo.name} has a zero light direction")
    elif source == "PROBE":
        direction = probe_direction(scene, photo, details)
    elif source == "SUN_POSITION":
        direction = sun_position_direction(photo, scene, details)
    else:
        raise ValueError(f"photo {photo.name}: unknown light source {source}")
    return direction / np.linalg.norm(direction)


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
