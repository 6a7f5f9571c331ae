"""A Cycles photo of a sphere light probe (chrome or glossy black) under a known Sun,
for the probe tests (tests/blender/test_probe.py) and the probe benchmark
(bench/probe_bench.py).

The sphere (radius 1 m, at the origin) sits right of and below the image centre
of a 35 mm perspective camera 3.7 m away, so it is seen 7 degrees off the
optical axis with a radius of 89 px in the 320 x 240 photo (32 samples, no
denoising, a 0.75 degree Sun, linear EXR). The wall behind it takes the
sphere's shadow, an ellipse of about the sphere's size: a decoy for the circle
search. The truth is the Sun object's world direction (towards the light).
"""

from __future__ import annotations

import math
import pathlib

import bpy
import numpy as np
from mathutils import Vector

from brdf_reconstruct.brdf_addon import light_sources
from brdf_reconstruct.core.capture import photo_io

from . import blender_scene as BS

KINDS = ("chrome", "black")

SIZE = (320, 240)
SAMPLES = 32
SUN_ANGLE_DEG = 0.75
CAMERA_AT = (0.6, -3.6, 0.5)
LOOK_AT = (-0.35, 0.0, 0.25)  # so the sphere (at the origin) is off the image centre


def unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def angle_deg(a, b):
    return math.degrees(math.acos(np.clip(unit(a) @ unit(b), -1.0, 1.0)))


def light_from_view(angle_deg, roll_deg, camera_at=CAMERA_AT):
    """(3,) world direction towards a light `angle_deg` away from the direction from
    the sphere (origin) to the camera, turned by `roll_deg` about it (0: to the right
    of the image, 90: up)."""
    v = unit(camera_at)
    x = unit(np.cross([0.0, 0.0, 1.0], v))
    y = np.cross(v, x)
    t, p = math.radians(angle_deg), math.radians(roll_deg)
    return unit(math.cos(t) * v + math.sin(t) * (math.cos(p) * x + math.sin(p) * y))


def _material(kind):
    mat = bpy.data.materials.new(kind)
    tree = mat.node_tree
    tree.nodes.clear()
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    if kind == "chrome":
        bsdf = tree.nodes.new("ShaderNodeBsdfGlossy")
        bsdf.inputs["Roughness"].default_value = 0.03
    elif kind == "black":  # black base (albedo 0.01) under a clear coat, Fresnel and all
        bsdf = tree.nodes.new("ShaderNodeBsdfPrincipled")
        bsdf.inputs["Base Color"].default_value = (0.01, 0.01, 0.01, 1.0)
        bsdf.inputs["Roughness"].default_value = 0.4
        bsdf.inputs["Coat Weight"].default_value = 1.0
        bsdf.inputs["Coat Roughness"].default_value = 0.03
    elif kind == "wall":
        bsdf = tree.nodes.new("ShaderNodeBsdfDiffuse")
        bsdf.inputs["Color"].default_value = (0.5, 0.5, 0.5, 1.0)
    else:
        raise ValueError(f"unknown material {kind!r}")
    tree.links.new(bsdf.outputs[0], out.inputs["Surface"])
    return mat


def render_probe(path: pathlib.Path, kind: str | None, light_dir, *, size=SIZE,
                 samples=SAMPLES, wall=True, sun_angle_deg=SUN_ANGLE_DEG) -> dict:
    """Reset to an empty scene, build the probe set-up and render it to `path` (EXR).

    kind: "chrome" (Glossy BSDF, roughness 0.03), "black" (Principled, clear coat
    0.03) or None (no sphere: the clean plate). light_dir: (3,) world direction
    towards the Sun. Returns the photo
    ((H, W, 3) linear), the camera (`PerspectiveCamera`), its camera-to-world
    rotation (3, 3), the true light and the true circle of the sphere.
    """
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    if kind is not None:
        bpy.ops.mesh.primitive_uv_sphere_add(segments=128, ring_count=64, radius=1.0)
        bpy.ops.object.shade_smooth()
        bpy.context.active_object.data.materials.append(_material(kind))
    if wall:
        bpy.ops.mesh.primitive_plane_add(size=30.0, location=(0.0, 4.0, 0.0),
                                         rotation=(math.pi / 2, 0.0, 0.0))
        bpy.context.active_object.data.materials.append(_material("wall"))
    world = bpy.data.worlds.new("grey")  # Blender 5 worlds come with their node tree
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.15, 0.15, 0.15, 1)
    scene.world = world
    cam_data = bpy.data.cameras.new("probe camera")
    cam_data.lens = 35.0
    cam = bpy.data.objects.new("probe camera", cam_data)
    scene.collection.objects.link(cam)
    cam.location = CAMERA_AT
    cam.rotation_mode = "QUATERNION"
    cam.rotation_quaternion = (Vector(LOOK_AT) - cam.location).to_track_quat("-Z", "Y")
    scene.camera = cam
    sun_data = bpy.data.lights.new("Sun", "SUN")
    sun_data.energy = 3.0
    sun_data.angle = math.radians(sun_angle_deg)
    sun = bpy.data.objects.new("Sun", sun_data)
    scene.collection.objects.link(sun)
    sun.rotation_mode = "QUATERNION"  # a Sun shines down its -Z: +Z points to it
    sun.rotation_quaternion = Vector((0, 0, 1)).rotation_difference(Vector(tuple(light_dir)))

    # two bounces: the mirror shows the lit wall
    BS.render_photo(scene, path, size, samples=samples, bounces=2, transparent=False)

    image = photo_io.read_photo(str(path))
    h, w = image.shape[:2]
    camera = light_sources.camera_intrinsics(scene, cam, w, h)
    rotation = np.array(cam.matrix_world.to_3x3().normalized())
    centre = rotation.T @ -np.array(cam.matrix_world.translation)  # the sphere, camera space
    return {"image": image, "camera": camera, "rotation": rotation,
            "light": unit(sun.matrix_world.to_3x3().col[2]),
            "circle": true_circle(centre, 1.0, camera)}


def true_circle(centre, radius, camera):
    """The image circle through the two ends of the major axis of a sphere's outline
    (the circle `light_from_highlight` expects): the two tangent rays in the plane
    of the optical axis and the sphere's centre (camera space, looking down -z)."""
    c = np.asarray(centre, dtype=np.float64)
    dist = np.linalg.norm(c)
    alpha = math.asin(radius / dist)
    axis = c / dist
    k = unit(np.cross(axis, [0.0, 0.0, -1.0]))  # the sphere is off the optical axis
    ends = []
    for a in (alpha, -alpha):
        p = axis * math.cos(a) + np.cross(k, axis) * math.sin(a)  # axis turned by a about k
        ends.append([camera.principal_px[0] + camera.focal_px * p[0] / -p[2],
                     camera.principal_px[1] - camera.focal_px * p[1] / -p[2]])
    ends = np.array(ends)
    return tuple(ends.mean(axis=0)), float(np.linalg.norm(ends[0] - ends[1]) / 2.0)


# --- the tests ------------------------------------------------------------------
