"""A tiny test scene in pip bpy: a sphere scan, one camera, one Sun, and a lit photo
rendered by Cycles with a known material (Lambert, albedo ALBEDO).

Used by the Blender workflow, panel and batch tests.
"""

import math
import pathlib

import bpy
import numpy as np
from mathutils import Vector

from brdf_reconstruct.brdf_addon.scratch_scene import configure_cycles, float_exr_output

ALBEDO = 0.5
SIZE = 48  # photo pixels (square)
LIGHT = np.array([0.35, -0.55, 0.76]) / np.linalg.norm([0.35, -0.55, 0.76])
IMAGE_NAME = "view0.jpg"  # the camera's COLMAP-style image name


def build(tmp: pathlib.Path, photo: bool = True) -> dict:
    """Reset to an empty scene and build it; returns names and paths."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=4, radius=1.0)
    scan = bpy.context.active_object
    scan.name = "Scan"
    bpy.ops.object.shade_smooth()
    mat = bpy.data.materials.new("Known Lambert")
    scan.data.materials.append(mat)
    tree = mat.node_tree
    tree.nodes.clear()
    bsdf = tree.nodes.new("ShaderNodeBsdfDiffuse")
    bsdf.inputs["Color"].default_value = (ALBEDO, ALBEDO, ALBEDO, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.0
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    tree.links.new(bsdf.outputs[0], out.inputs["Surface"])

    cam_data = bpy.data.cameras.new("view0")
    cam_data.lens = 50.0
    camera = bpy.data.objects.new("view0", cam_data)
    scene.collection.objects.link(camera)
    camera.location = (0.3, -4.5, 0.8)
    camera.rotation_mode = "QUATERNION"
    camera.rotation_quaternion = (Vector((0, 0, 0)) - camera.location).to_track_quat("-Z", "Y")
    camera["brdf_image_name"] = IMAGE_NAME
    camera["brdf_width"] = SIZE
    camera["brdf_height"] = SIZE
    scene.camera = camera

    sun_data = bpy.data.lights.new("Sun", "SUN")
    sun_data.energy = math.pi  # W/m^2 irradiance
    sun_data.angle = 0.0
    sun = bpy.data.objects.new("Sun", sun_data)
    scene.collection.objects.link(sun)
    sun.rotation_mode = "QUATERNION"
    sun.rotation_quaternion = Vector((0, 0, 1)).rotation_difference(Vector(tuple(LIGHT)))

    paths = {"dir": tmp, "photo": tmp / "view0.exr"}
    if photo:
        render_photo(scene, paths["photo"])
    return {"scene": scene, "scan": scan, "camera": camera, "sun": sun, **paths}


def render_photo(scene, path: pathlib.Path, size: int | tuple[int, int] = SIZE, *,
                 samples: int = 32, bounces: int = 0, transparent: bool = True) -> None:
    """Linear float EXR, no view transform, no denoising, CPU; ``size`` x ``size``
    pixels (or (width, height)). Direct light only by default; ``bounces`` > 0
    lets a mirror show what the light lights."""
    # Cycles' adaptive sampling stays on here, as these photos were always rendered
    configure_cycles(scene, samples, bounces=bounces, adaptive=True)
    r = scene.render
    r.resolution_x, r.resolution_y = (size, size) if isinstance(size, int) else size
    r.resolution_percentage = 100
    r.film_transparent = transparent
    float_exr_output(scene)
    r.filepath = str(path)
    bpy.ops.render.render(write_still=True)


def settings_for_tiny_runs(built: dict, out: pathlib.Path) -> None:
    """Point ``scene.brdf`` at the scan, with settings for a 48-pixel photo: the
    sphere's normals turn ~0.06 rad per pixel there, so the paper's 0.2 per 10
    pixels (meant for multi-megapixel photos) would drop every pixel."""
    s = built["scene"].brdf
    s.target = built["scan"]
    s.output_dir = str(out)
    s.curvature_threshold = 1.5
    s.samples, s.trials = 12, 2


def lit_irradiance() -> float:
    return math.pi
