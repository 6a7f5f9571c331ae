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
  materials (their ``pass_index`` is not used).
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

import dataclasses
import math
import os
import tempfile

import bpy
import numpy as np
import OpenImageIO as oiio
from bpy_extras.object_utils import world_to_camera_view
from mathutils import Vector

# Sculpt face sets: the integer face attribute Blender keeps them in.
FACE_SET_ATTRIBUTE = ".sculpt_face_set"
# Names of the temporary data-blocks (Blender may add a suffix on a clash).
_NAME = "BRDF_GBuffer"
_REGION_AOV = "brdf_region"
_LAYER = "ViewLayer"
# Sun strength pi W/m^2 on a white Lambertian surface: radiance = vis * cos(theta_l).
_SUN_STRENGTH = math.pi
# Pixels added around the projected bounding box when cropping.
_CROP_MARGIN_PX = 2
# Below this n.l the visibility ratio is ill-conditioned; such points count as unlit.
_MIN_COSINE = 1e-6
# Orthographic cameras have no centre: a point this many ortho scales behind the
# camera gives view directions parallel to its axis to within ~1e-9 rad.
_ORTHO_DISTANCE = 1e9


@dataclasses.dataclass(frozen=True)
class GBuffers:
    """Per-pixel geometry of one photo, full photo size (H, W).

    normal: (H, W, 3) float64, world space, unit: the shading normal as rendered
        (interpolated on smooth faces, towards the camera on back faces); 0 on
        background.
    position: (H, W, 3) float64, world space, scene units; 0 on background.
    visibility: (H, W) float64 in [0, 1]: fraction of the distant light reaching
        the point, from cast shadows by the scan itself (1 = lit); 0 where the
        shading normal faces away from the light (n.l <= 0) and on background.
    region: (H, W) int32: material slot index of the visible face (0 for an object
        without slots; indices past the last slot clamp to it, as Blender's
        renderers do); -1 on background.
    mask: (H, W) bool: pixels covered by the object (coverage >= 1/2) with finite
        geometry. ``region >= 0`` exactly where ``mask``.
    camera_center: (3,) float64, world space. For an orthographic camera, a point
        very far behind the camera on its axis, so that ``normalize(C - P)`` is the
        (parallel) view direction; see ``orthographic``.
    orthographic: True for an orthographic camera.
    window: (row_start, row_stop, col_start, col_stop), half-open, of the rendered
        crop; None when the full frame was rendered; an empty window when the
        object projects outside the frame (nothing rendered). Outside it is
        background.
    """

    normal: np.ndarray
    position: np.ndarray
    visibility: np.ndarray
    region: np.ndarray
    mask: np.ndarray
    camera_center: np.ndarray
    orthographic: bool = False
    window: tuple[int, int, int, int] | None = None

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) of the images."""
        return self.mask.shape


def render_gbuffers(
    obj,
    camera,
    light_direction,
    *,
    resolution: tuple[int, int] | None = None,
    crop: bool = True,
    samples: int = 1,
    tmpdir: str | os.PathLike | None = None,
    device: str = "CPU",
    region_attribute: str = "material_index",
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
    samples: Cycles samples per pixel, >= 1. One sample lies at the pixel centre,
    which is what the G-buffers should hold; more are drawn from the 0.01 px
    filter (with rare outliers turning a normal by up to ~1 degree) and only help
    a soft-edged light, which this one is not. tmpdir: folder for the
    temporary EXR (default: the system's). device: Cycles device, 'CPU' or 'GPU'.
    region_attribute: the integer face attribute that gives the region id:
    ``"material_index"`` (the material slot; indices past the last slot count as
    the last, as Blender renders them) or ``FACE_SET_ATTRIBUTE`` (sculpt face
    sets; a mesh without face sets is region 0).

    Returns :class:`GBuffers` of shape (H, W). Raises ValueError for a wrong
    object or camera type, a bad light direction, resolution or sample count.
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
    if int(samples) != samples or samples < 1:
        raise ValueError(f"samples must be a positive integer, got {samples}")
    if device not in ("CPU", "GPU"):
        raise ValueError(f"device must be 'CPU' or 'GPU', got {device!r}")
    if region_attribute not in ("material_index", FACE_SET_ATTRIBUTE):
        raise ValueError(f"region_attribute must be 'material_index' or "
                         f"{FACE_SET_ATTRIBUTE!r}, got {region_attribute!r}")
    user_scene = bpy.context.scene
    width, height = _resolution(camera, user_scene, resolution)

    images_before = set(bpy.data.images)
    try:
        with _TemporaryScene(obj, camera, light, user_scene, width, height,
                             region_attribute) as scene:
            _configure_cycles(scene, int(samples), device)
            cam_eval, window = _crop_window(scene, obj, camera, width, height) if crop else (
                _evaluated(scene, camera), None)
            center, ortho = _camera_center(cam_eval)
            if window is not None and (window[0] >= window[1] or window[2] >= window[3]):
                return _empty(height, width, center, ortho, window)
            if window is not None:
                _set_border(scene, window, width, height)
            with tempfile.TemporaryDirectory(prefix="brdf_gbuffer_", dir=tmpdir) as folder:
                path = os.path.join(folder, "gbuffer.exr")
                scene.render.filepath = path
                bpy.ops.render.render(write_still=True, scene=scene.name)
                if not os.path.isfile(path):
                    raise RuntimeError(f"Cycles wrote no G-buffer file at {path}")
                channels = read_multilayer_exr(path)
    finally:
        # Rendering creates the "Render Result" image if there was none; drop it again.
        for image in set(bpy.data.images) - images_before:
            bpy.data.images.remove(image)
    slots = len(obj.material_slots) if region_attribute == "material_index" else None
    return _assemble(channels, light=light, slots=slots, center=center,
                     ortho=ortho, window=window)


def read_multilayer_exr(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """All channels of a (multi-part or single-part) multilayer EXR, by full name.

    Returns {"ViewLayer.Normal.X": (H, W) float32, ...} on the display window
    (row 0 at the top); pixels outside a part's data window are 0.
    """
    image = oiio.ImageInput.open(os.fspath(path))
    if image is None:
        raise RuntimeError(f"cannot open {path}: {oiio.geterror()}")
    channels = {}
    try:
        part = 0
        while image.seek_subimage(part, 0):
            spec = image.spec()
            data = image.read_image(part, 0, 0, spec.nchannels, oiio.FLOAT)
            if data is None:
                raise RuntimeError(f"cannot read {path}: {image.geterror()}")
            data = np.asarray(data, dtype=np.float32).reshape(
                spec.height, spec.width, spec.nchannels)
            full = np.zeros((spec.full_height, spec.full_width, spec.nchannels), np.float32)
            # Place the data window into the display window (they differ for crops).
            y0, x0 = spec.y - spec.full_y, spec.x - spec.full_x
            ys = slice(max(y0, 0), min(y0 + spec.height, spec.full_height))
            xs = slice(max(x0, 0), min(x0 + spec.width, spec.full_width))
            full[ys, xs] = data[ys.start - y0:ys.stop - y0, xs.start - x0:xs.stop - x0]
            for k, name in enumerate(spec.channelnames):
                channels[name] = full[..., k]
            part += 1
    finally:
        image.close()
    return channels


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


class _TemporaryScene:
    """A scene with the scan, the camera and a Sun; removed with all it created."""

    def __init__(self, obj, camera, light, user_scene, width, height,
                 region_attribute="material_index"):
        self.obj, self.camera, self.light = obj, camera, light
        self.region_attribute = region_attribute
        self.user_scene, self.width, self.height = user_scene, width, height
        self.created = []  # (collection, data-block), removed in reverse order

    def _new(self, collection, *args):
        block = collection.new(*args)
        self.created.append((collection, block))
        return block

    def __enter__(self):
        try:
            return self._build()
        except BaseException:
            self._remove()
            raise

    def __exit__(self, *exc):
        self._remove()
        return False

    def _build(self):
        scene = self._new(bpy.data.scenes, _NAME)
        scene.world = None  # black, so only the Sun lights the scan
        scene.frame_current = self.user_scene.frame_current
        render = scene.render
        render.engine = "CYCLES"
        render.resolution_x, render.resolution_y = self.width, self.height
        render.resolution_percentage = 100
        render.pixel_aspect_x = self.user_scene.render.pixel_aspect_x
        render.pixel_aspect_y = self.user_scene.render.pixel_aspect_y
        render.film_transparent = True  # alpha = coverage of the object
        render.use_compositing = False
        render.use_sequencer = False
        render.use_motion_blur = False
        render.use_border = False
        render.use_crop_to_border = False  # keep the full frame when cropping
        render.use_file_extension = False
        image = render.image_settings
        image.media_type = "MULTI_LAYER_IMAGE"
        image.file_format = "OPEN_EXR_MULTILAYER"
        image.color_depth = "32"
        image.exr_codec = "ZIP"

        layer = scene.view_layers[0]
        layer.name = _LAYER
        layer.use_pass_combined = True
        layer.use_pass_z = False
        layer.use_pass_normal = True
        layer.use_pass_position = True
        layer.use_pass_diffuse_direct = True
        aov = layer.aovs.add()
        aov.name, aov.type = _REGION_AOV, "VALUE"
        layer.material_override = self._override_material()

        scene.collection.objects.link(self.obj)
        scene.collection.objects.link(self.camera)
        scene.camera = self.camera
        sun_data = self._new(bpy.data.lights, _NAME, "SUN")
        sun_data.energy = _SUN_STRENGTH
        sun_data.angle = 0.0  # a distant point light: hard, point-sampled shadows
        sun = self._new(bpy.data.objects, _NAME, sun_data)
        sun.rotation_mode = "QUATERNION"
        # A Sun shines along its local -Z, so its +Z points towards the light.
        sun.rotation_quaternion = Vector(self.light.tolist()).to_track_quat("Z", "Y")
        scene.collection.objects.link(sun)
        return scene

    def _override_material(self):
        material = self._new(bpy.data.materials, _NAME)
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
        attribute.attribute_name = self.region_attribute
        aov = nodes.new("ShaderNodeOutputAOV")
        aov.aov_name = _REGION_AOV
        links.new(attribute.outputs["Fac"], aov.inputs["Value"])
        return material

    def _remove(self):
        for collection, block in reversed(self.created):
            try:
                collection.remove(block)
            except ReferenceError:  # already gone with its owner
                pass
        self.created.clear()


def _configure_cycles(scene, samples: int, device: str) -> None:
    cycles = scene.cycles
    cycles.device = device
    cycles.samples = samples
    cycles.use_adaptive_sampling = False
    cycles.use_denoising = False
    cycles.seed = 0
    cycles.use_animated_seed = False
    cycles.max_bounces = 0  # direct light only
    for bounces in ("diffuse_bounces", "glossy_bounces", "transmission_bounces",
                    "volume_bounces", "transparent_max_bounces"):
        setattr(cycles, bounces, 0)
    cycles.light_sampling_threshold = 0.0  # no random termination of dim shadow rays
    cycles.sample_clamp_direct = 0.0
    # The narrowest filter keeps every sample within 0.005 px of the pixel centre,
    # so nothing blends across silhouettes. Not 'BOX': Cycles ignores the width of
    # a box filter and jitters over the whole pixel.
    cycles.pixel_filter_type = "BLACKMAN_HARRIS"
    cycles.filter_width = cycles.bl_rna.properties["filter_width"].hard_min
    cycles.use_camera_cull = False
    cycles.use_distance_cull = False


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


def _empty(height, width, center, ortho, window) -> GBuffers:
    return GBuffers(
        normal=np.zeros((height, width, 3)), position=np.zeros((height, width, 3)),
        visibility=np.zeros((height, width)),
        region=np.full((height, width), -1, dtype=np.int32),
        mask=np.zeros((height, width), dtype=bool), camera_center=center,
        orthographic=ortho, window=window)


def _assemble(channels, *, light, slots, center, ortho, window) -> GBuffers:
    def read(pass_name, components):
        try:
            planes = [channels[f"{_LAYER}.{pass_name}.{c}"] for c in components]
        except KeyError as missing:
            raise RuntimeError(f"the G-buffer EXR has no channel {missing}; "
                               f"it has {sorted(channels)}") from None
        return np.stack(planes, axis=-1).astype(np.float64)

    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        coverage = read("Combined", "A")[..., 0]
        # Passes average over all samples of a pixel, background ones giving 0:
        # divide by the coverage to get the value on the object.
        scale = np.where(coverage > 0.0, 1.0 / coverage, 0.0)[..., None]
        normal = read("Normal", "XYZ") * scale
        position = read("Position", "XYZ") * scale
        direct = read("Diffuse Direct", "RGB").mean(axis=-1) * scale[..., 0]
        region_value = read(_REGION_AOV, "X")[..., 0] * scale[..., 0]
        length = np.linalg.norm(normal, axis=-1)
        mask = ((coverage >= 0.5) & np.isfinite(coverage) & np.isfinite(length)
                & (length > 0.5) & np.all(np.isfinite(position), axis=-1)
                & np.isfinite(direct) & np.isfinite(region_value))
        normal = np.where(mask[..., None], normal / np.where(mask, length, 1.0)[..., None], 0.0)
        position = np.where(mask[..., None], position, 0.0)
        cosine = normal @ light
        lit = mask & (cosine > _MIN_COSINE)
        visibility = np.where(lit, np.clip(direct / np.where(lit, cosine, 1.0), 0.0, 1.0), 0.0)
        region_value = np.rint(np.where(mask, region_value, 0.0))
        if slots is not None:  # a face whose index is past the last slot renders with it
            region_value = np.clip(region_value, 0, max(slots - 1, 0))
        region = np.where(mask, region_value, -1)
    return GBuffers(normal=normal, position=position, visibility=visibility,
                    region=region.astype(np.int32), mask=mask, camera_center=center,
                    orthographic=ortho, window=window)
