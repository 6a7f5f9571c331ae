"""Per-photo G-buffers of the scan, rendered by Cycles from the photo's camera.

For one lit photo, Cycles renders the scan alone from the photo's camera and
returns, per pixel of the photo: the shading normal and surface point (world
space), the fraction of the distant light reaching the point (cast shadows), and
the region id (the material slot of the face). These are what
``core.method.observations.observe`` consumes.

How it is rendered (nothing of the user's data is modified):

- A temporary scene holds only the scan object, the camera and a temporary Sun;
  the user's objects, materials, world and render settings are never touched.
  Only the scan is in the temporary scene, so only the scan casts shadows (the
  photographed object is the scan; helper objects of the Blender scene are not
  in the photos). The object's own ray-visibility flags, modifiers and the
  scene frame apply, as in any render.
- The view layer's material override is a white Lambertian material, so the
  user's materials (and their displacement) play no part. Its Diffuse Direct
  pass, under a Sun of angle 0 and strength pi W/m^2, is ``vis * max(n.l, 0)``;
  dividing by ``n.l`` gives the visibility. Cycles 5.0 has no shadow pass
  (``ViewLayer.use_pass_shadow`` exists for EEVEE only).
- The same material writes the face attribute ``material_index`` (read by an
  Attribute node) to an AOV, so region ids need no change to the user's
  materials (their ``pass_index`` is not used). With ``uv=True`` it writes the
  mesh's render UV map (a UV Map node; or the one named) to a colour AOV too,
  for textured regions (``core.method.textured``).
- A pixel filter of the smallest width (0.01 px; Blackman-Harris, since Cycles
  ignores the width of its box filter) puts every sample at the pixel centre:
  normals are not blended across silhouettes and shadows are point-sampled, so
  one sample per pixel is enough. Bounces 0, no denoising, no adaptive sampling,
  light threshold 0 (no probabilistic shadow-ray termination).
- The render border is cropped to the object's projected bounding box (the
  image stays full size, background outside), written to a temporary multilayer
  EXR (float32, one part per pass, channels such as ``ViewLayer.Normal.X``) and
  read back with OpenImageIO; the file and its folder are deleted.

Frames: world space for normals, points, the light and the camera centre;
images have row 0 at the top, column 0 at the left (EXR and numpy order).
Known artefact: a pixel centre lying exactly on an edge shared by two coplanar
triangles can get a false shadow (Cycles' shadow ray hits the neighbour at
distance 0); it needs exact alignment, as with a camera on a symmetry axis of
the mesh. Precision: the EXR is float32, so points far from the world origin (geo-referenced
scans) lose precision; keep the scan near the origin.
"""

from __future__ import annotations

import math
import os

import bpy
import numpy as np
from bpy_extras.object_utils import world_to_camera_view
from mathutils import Vector

from ..core.capture.photo_io import read_multilayer_exr
from ..core.method.gbuffers import LAYER, REGION_AOV, UV_AOV, GBuffers, decode, empty
from .scratch_scene import ScratchScene, configure_cycles, float_exr_output

# Sculpt face sets: the integer face attribute Blender keeps them in.
FACE_SET_ATTRIBUTE = ".sculpt_face_set"
# Names of the temporary data-blocks (Blender may add a suffix on a clash).
_NAME = "BRDF_GBuffer"
# Sun strength pi W/m^2 on a white Lambertian surface: radiance = vis * cos(theta_l).
_SUN_STRENGTH = math.pi
# Pixels added around the projected bounding box when cropping.
_CROP_MARGIN_PX = 2
# Orthographic cameras have no centre: a point this many ortho scales behind the
# camera gives view directions parallel to its axis to within ~1e-9 rad.
_ORTHO_DISTANCE = 1e9


def render_gbuffers(
    obj,
    camera,
    light_direction,
    *,
    resolution: tuple[int, int] | None = None,
    crop: bool = True,
    render_samples: int = 1,
    tmpdir: str | os.PathLike | None = None,
    device: str = "CPU",
    region_attribute: str = "material_index",
    uv: bool = False,
    uv_map: str = "",
) -> GBuffers:
    """Render the G-buffers of mesh object ``obj`` seen by ``camera`` under a distant light.

    obj: bpy mesh object (the scan), rendered with its modifiers at the current
    frame of the context scene. camera: bpy camera object, perspective or
    orthographic (lens shift and sensor fit apply). light_direction: (3,) world
    direction towards the distant light (normalised here). resolution: (W, H) in
    pixels; default: the camera object's (or its data's) custom properties
    ``brdf_width`` / ``brdf_height`` if set, else the context scene's output size
    (with its percentage). The context scene's pixel aspect ratio is used.
    crop: render only the object's projected bounding box (same result, faster).
    render_samples: Cycles samples per pixel, >= 1. One sample lies at the pixel centre,
    which is what the G-buffers should hold; more are drawn from the 0.01 px
    filter (with rare outliers turning a normal by up to ~1 degree) and only help
    a soft-edged light, which this one is not. tmpdir: folder for the
    temporary EXR (default: the system's). device: Cycles device, 'CPU' or 'GPU'.
    region_attribute: the integer face attribute that gives the region id:
    ``"material_index"`` (the material slot; indices past the last slot count as
    the last, as Blender renders them) or ``FACE_SET_ATTRIBUTE`` (sculpt face
    sets; a mesh without face sets is region 0). uv: also render the UV map
    (``GBuffers.uv``); uv_map: its name ("" for the mesh's active render UV map).

    Returns :class:`GBuffers` of shape (H, W). Raises ValueError for a wrong
    object or camera type, a bad light direction, resolution or sample count, and
    with ``uv`` for a mesh without a UV map (or without the one named).
    """
    if getattr(obj, "type", None) != "MESH":
        raise ValueError(f"obj must be a mesh object, got {obj!r}")
    if getattr(camera, "type", None) != "CAMERA":
        raise ValueError(f"camera must be a camera object, got {camera!r}")
    if camera.data.type not in ("PERSP", "ORTHO"):
        raise ValueError(f"camera {camera.name!r} must be perspective or orthographic, "
                         f"got {camera.data.type}")
    light = np.asarray(light_direction, dtype=np.float64)
    if light.shape != (3,) or not np.all(np.isfinite(light)) or not np.linalg.norm(light) > 0:
        raise ValueError(f"light_direction must be a finite non-zero 3-vector, got {light}")
    light = light / np.linalg.norm(light)
    if int(render_samples) != render_samples or render_samples < 1:
        raise ValueError(f"render_samples must be a positive integer, got {render_samples}")
    if device not in ("CPU", "GPU"):
        raise ValueError(f"device must be 'CPU' or 'GPU', got {device!r}")
    if region_attribute not in ("material_index", FACE_SET_ATTRIBUTE):
        raise ValueError(f"region_attribute must be 'material_index' or "
                         f"{FACE_SET_ATTRIBUTE!r}, got {region_attribute!r}")
    if uv:
        check_uv_map(obj, uv_map)
    user_scene = bpy.context.scene
    width, height = _resolution(camera, user_scene, resolution)

    with ScratchScene(_NAME, remove_new_images=True, tmpdir=tmpdir) as scratch:
        scene = scratch.scene
        _build_scene(scratch, obj, camera, light, user_scene, width, height, region_attribute,
                     uv_map if uv else None)
        configure_cycles(scene, int(render_samples), device=device, point_sampled=True,
                         exact_direct_light=True)
        cam_eval, window = _crop_window(scene, obj, camera, width, height) if crop else (
            _evaluated(scene, camera), None)
        center, ortho = _camera_center(cam_eval)
        if window is not None and (window[0] >= window[1] or window[2] >= window[3]):
            return empty(height, width, center, ortho, window, uv=uv)
        if window is not None:
            _set_border(scene, window, width, height)
        path = scratch.render("gbuffer.exr")
        if not os.path.isfile(path):
            raise RuntimeError(f"Cycles wrote no G-buffer file at {path}")
        channels = read_multilayer_exr(path)
    slots = len(obj.material_slots) if region_attribute == "material_index" else None
    return decode(channels, light=light, slots=slots, center=center, ortho=ortho, window=window,
                  uv=uv)


def check_uv_map(obj, uv_map: str = "") -> None:
    """ValueError (one sentence) when the mesh object has no UV map, or none named
    ``uv_map`` ("": any)."""
    layers = obj.data.uv_layers
    if not len(layers):
        raise ValueError(f"the scan {obj.name!r} has no UV map, so its texture cannot be "
                         "reconstructed (add one, use Make UV Map on a Copy or a job's "
                         "uv_on_copy = true, or reconstruct it untextured)")
    if uv_map and uv_map not in layers:
        raise ValueError(f"the scan {obj.name!r} has no UV map named {uv_map!r} "
                         f"(it has {', '.join(repr(layer.name) for layer in layers)})")


def camera_resolution(camera, scene) -> tuple[tuple[int, int], str]:
    """The (width, height) in pixels a camera's images have, and where that came
    from: "camera" for the object's (or its data's) ``brdf_width`` /
    ``brdf_height`` (the COLMAP import sets them), else "scene render size" (the
    scene's output size with its percentage, as other importers set it)."""
    for holder in (camera, camera.data):
        if "brdf_width" in holder and "brdf_height" in holder:
            return (holder["brdf_width"], holder["brdf_height"]), "camera"
    scale = scene.render.resolution_percentage / 100.0
    return ((int(scene.render.resolution_x * scale), int(scene.render.resolution_y * scale)),
            "scene render size")


def _resolution(camera, scene, resolution) -> tuple[int, int]:
    if resolution is None:
        resolution = camera_resolution(camera, scene)[0]
    try:
        width, height = (int(r) for r in resolution)
    except (TypeError, ValueError):
        raise ValueError(f"resolution must be (width, height), got {resolution!r}") from None
    if width < 1 or height < 1 or (width, height) != tuple(resolution):
        raise ValueError(f"resolution must be two positive integers, got {resolution!r}")
    return width, height


def _build_scene(scratch, obj, camera, light, user_scene, width, height, region_attribute,
                 uv_map=None):
    """The scratch scene: the scan, the camera and a Sun, the white Lambertian
    override writing the region AOV (and the UV AOV unless ``uv_map`` is None), the
    passes, multilayer EXR output."""
    scene = scratch.scene
    scene.frame_current = user_scene.frame_current
    render = scene.render
    render.resolution_x, render.resolution_y = width, height
    render.resolution_percentage = 100
    render.pixel_aspect_x = user_scene.render.pixel_aspect_x
    render.pixel_aspect_y = user_scene.render.pixel_aspect_y
    render.film_transparent = True  # alpha = coverage of the object
    render.use_compositing = False
    render.use_sequencer = False
    render.use_motion_blur = False
    render.use_border = False
    render.use_crop_to_border = False  # keep the full frame when cropping
    render.use_file_extension = False
    float_exr_output(scene, multilayer=True)

    layer = scene.view_layers[0]
    layer.name = LAYER
    layer.use_pass_combined = True
    layer.use_pass_z = False
    layer.use_pass_normal = True
    layer.use_pass_position = True
    layer.use_pass_diffuse_direct = True
    aov = layer.aovs.add()
    aov.name, aov.type = REGION_AOV, "VALUE"
    if uv_map is not None:
        uv_aov = layer.aovs.add()
        uv_aov.name, uv_aov.type = UV_AOV, "COLOR"
    layer.material_override = _override_material(scratch, region_attribute, uv_map)

    scene.collection.objects.link(obj)
    scene.collection.objects.link(camera)
    scene.camera = camera
    sun_data = scratch.new(bpy.data.lights, _NAME, "SUN")
    sun_data.energy = _SUN_STRENGTH
    sun_data.angle = 0.0  # a distant point light: hard, point-sampled shadows
    sun = scratch.new(bpy.data.objects, _NAME, sun_data)
    sun.rotation_mode = "QUATERNION"
    # A Sun shines along its local -Z, so its +Z points towards the light.
    sun.rotation_quaternion = Vector(light.tolist()).to_track_quat("Z", "Y")
    scene.collection.objects.link(sun)


def _override_material(scratch, region_attribute, uv_map=None):
    material = scratch.new(bpy.data.materials, _NAME)
    if material.node_tree is None:  # Blender < 5.0 creates it on demand
        material.use_nodes = True
    nodes, links = material.node_tree.nodes, material.node_tree.links
    nodes.clear()
    output = nodes.new("ShaderNodeOutputMaterial")
    output.target = "CYCLES"
    diffuse = nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    diffuse.inputs["Roughness"].default_value = 0.0  # Lambertian
    links.new(diffuse.outputs["BSDF"], output.inputs["Surface"])
    # Cycles exposes the face attributes material_index and .sculpt_face_set to
    # shaders (checked in tests); a missing attribute reads 0.
    attribute = nodes.new("ShaderNodeAttribute")
    attribute.attribute_type = "GEOMETRY"
    attribute.attribute_name = region_attribute
    aov = nodes.new("ShaderNodeOutputAOV")
    aov.aov_name = REGION_AOV
    links.new(attribute.outputs["Fac"], aov.inputs["Value"])
    if uv_map is not None:
        uv_node = nodes.new("ShaderNodeUVMap")
        uv_node.uv_map = uv_map  # "": the render UV map
        uv_out = nodes.new("ShaderNodeOutputAOV")
        uv_out.aov_name = UV_AOV
        links.new(uv_node.outputs["UV"], uv_out.inputs["Color"])
    return material


def _evaluated(scene, block):
    with bpy.context.temp_override(scene=scene, view_layer=scene.view_layers[0]):
        depsgraph = bpy.context.evaluated_depsgraph_get()
    return block.evaluated_get(depsgraph)


def _crop_window(scene, obj, camera, width, height):
    """The evaluated camera and the pixel window (rows, cols half-open) holding the
    object's projected bounding box plus a margin, or None when it cannot be
    bounded (a corner behind a perspective camera)."""
    obj_eval, cam_eval = _evaluated(scene, obj), _evaluated(scene, camera)
    world = obj_eval.matrix_world
    corners = [world_to_camera_view(scene, cam_eval, world @ Vector(c))
               for c in obj_eval.bound_box]
    if camera.data.type == "PERSP" and min(c.z for c in corners) <= 0.0:
        return cam_eval, None
    xs = [c.x * width for c in corners]
    ys = [(1.0 - c.y) * height for c in corners]  # rows from the top
    col0 = max(math.floor(min(xs)) - _CROP_MARGIN_PX, 0)
    col1 = min(math.ceil(max(xs)) + _CROP_MARGIN_PX, width)
    row0 = max(math.floor(min(ys)) - _CROP_MARGIN_PX, 0)
    row1 = min(math.ceil(max(ys)) + _CROP_MARGIN_PX, height)
    return cam_eval, (row0, max(row1, row0), col0, max(col1, col0))


def _set_border(scene, window, width, height) -> None:
    row0, row1, col0, col1 = window
    render = scene.render
    render.use_border = True
    # Blender truncates border * size to whole pixels; a quarter pixel in keeps
    # the truncation on the intended pixel. Border y runs from the bottom.
    render.border_min_x = min((col0 + 0.25) / width, 1.0)
    render.border_max_x = min((col1 + 0.25) / width, 1.0)
    render.border_min_y = min((height - row1 + 0.25) / height, 1.0)
    render.border_max_y = min((height - row0 + 0.25) / height, 1.0)


def _camera_center(cam_eval) -> tuple[np.ndarray, bool]:
    matrix = cam_eval.matrix_world
    center = np.array(matrix.translation, dtype=np.float64)
    if cam_eval.data.type != "ORTHO":
        return center, False
    backwards = np.array(matrix.to_3x3().normalized().col[2], dtype=np.float64)
    return center + backwards * _ORTHO_DISTANCE * cam_eval.data.ortho_scale, True


