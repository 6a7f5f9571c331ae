"""The baked material: a "BRDF Reconstruction" node group from a lobe fit, and its
error measured in Cycles.

:func:`build_material` turns a :class:`core.bake.fitting.LobeFit` into a NEW material
whose tree is one group node (label "BRDF Reconstruction") feeding the Material
Output. The group holds exactly the closures :mod:`core.bake.lobes` models, added
together: a Diffuse BSDF (Lambert), per lobe a Glossy BSDF (GGX or Beckmann) plus
a Metallic BSDF (same distribution, F82, black base, white edge tint: the Schlick
grazing rise) behind a Mix Shader, and a Sheen BSDF (Ashikhmin). The fitted
values are the group node's inputs, so a user can see and tweak them.

:func:`bake_error` renders a unit sphere with the material in Cycles, in a
temporary scene (orthographic camera down -z, one Sun of known irradiance per
light, black world, direct light only) and compares each image with numpy
shading of the table (:func:`core.brdf.render.shade`) on the analytic sphere normals.
"""

from __future__ import annotations

import json
import time

import bpy
import numpy as np
from mathutils import Vector

from ..core.bake import fitting, lobes
from ..core.brdf import metrics, render
from ..core.capture import photo_io
from .scratch_scene import ScratchScene, configure_cycles, float_exr_output

GROUP_NAME = "BRDF Reconstruction"
PRINCIPLED_NAME = "BRDF Principled"
_DISTRIBUTION = {"ggx": "GGX", "beckmann": "BECKMANN"}  # lobes -> node enum


# ------------------------------------------------------------------------- the material
def _params(fit) -> lobes.LobeParams:
    if isinstance(fit, fitting.LobeFit):
        return fit.params
    if isinstance(fit, dict):
        return lobes.LobeParams.from_dict(fit)
    return fit


def _rgba(rgb) -> tuple:
    return (*(float(x) for x in rgb), 1.0)


def _add_input(ng, name, socket_type, value, **limits):
    sock = ng.interface.new_socket(name, in_out="INPUT", socket_type=socket_type)
    for key, limit in limits.items():
        setattr(sock, key, limit)
    sock.default_value = value
    return sock


def build_node_group(params, name: str = GROUP_NAME) -> bpy.types.ShaderNodeTree:
    """A new shader node group (data-block ``name``, Blender adds a suffix on a clash)
    rendering :class:`core.bake.lobes.LobeParams` ``params``. Inputs: "Diffuse Color",
    per lobe "Lobe i Color" / "Lobe i Roughness" / "Lobe i Grazing", "Sheen Color",
    "Sheen Roughness"; output "Shader"."""
    p = _params(params)
    ng = bpy.data.node_groups.new(name, "ShaderNodeTree")
    ng.interface.new_socket("Shader", in_out="OUTPUT", socket_type="NodeSocketShader")
    _add_input(ng, "Diffuse Color", "NodeSocketColor", _rgba(p.diffuse))
    for i, (color, grazing, rough) in enumerate(
        zip(p.colors, p.grazing, p.roughness, strict=True), start=1
    ):
        _add_input(ng, f"Lobe {i} Color", "NodeSocketColor", _rgba(color))
        _add_input(ng, f"Lobe {i} Roughness", "NodeSocketFloat", float(rough),
                   min_value=0.0, max_value=1.0)
        _add_input(ng, f"Lobe {i} Grazing", "NodeSocketFloat", float(grazing),
                   min_value=0.0, max_value=1.0, subtype="FACTOR")
    has_sheen = bool(np.any(p.sheen != 0.0))
    if has_sheen:
        _add_input(ng, "Sheen Color", "NodeSocketColor", _rgba(p.sheen))
        _add_input(ng, "Sheen Roughness", "NodeSocketFloat", float(p.sheen_sigma),
                   min_value=0.0, max_value=1.0)

    nodes, links = ng.nodes, ng.links
    group_in = nodes.new("NodeGroupInput")
    group_in.location = (-900, 0)
    group_out = nodes.new("NodeGroupOutput")
    group_out.location = (700, 0)

    diffuse = nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.location = (-400, 400)
    diffuse.inputs["Roughness"].default_value = 0.0  # Lambert, not Oren-Nayar
    links.new(group_in.outputs["Diffuse Color"], diffuse.inputs["Color"])
    shaders = [diffuse.outputs["BSDF"]]

    for i, dist in enumerate(p.distributions, start=1):
        y = 400 - 350 * i
        glossy = nodes.new("ShaderNodeBsdfAnisotropic")  # the Glossy BSDF
        glossy.name = glossy.label = f"Lobe {i} Glossy"
        # GGX, not Multiscatter GGX: single scattering, no energy compensation
        glossy.distribution = _DISTRIBUTION[dist]
        glossy.location = (-400, y)
        glossy.inputs["Anisotropy"].default_value = 0.0
        links.new(group_in.outputs[f"Lobe {i} Color"], glossy.inputs["Color"])
        links.new(group_in.outputs[f"Lobe {i} Roughness"], glossy.inputs["Roughness"])
        metallic = nodes.new("ShaderNodeBsdfMetallic")
        metallic.name = metallic.label = f"Lobe {i} Grazing"
        metallic.distribution = _DISTRIBUTION[dist]
        metallic.fresnel_type = "F82"
        metallic.location = (-400, y - 170)
        metallic.inputs["Base Color"].default_value = (0.0, 0.0, 0.0, 1.0)
        metallic.inputs["Edge Tint"].default_value = (1.0, 1.0, 1.0, 1.0)  # pure Schlick
        metallic.inputs["Anisotropy"].default_value = 0.0
        links.new(group_in.outputs[f"Lobe {i} Roughness"], metallic.inputs["Roughness"])
        mix = nodes.new("ShaderNodeMixShader")  # first input empty: scales by Fac
        mix.location = (-150, y - 170)
        links.new(group_in.outputs[f"Lobe {i} Grazing"], mix.inputs["Fac"])
        links.new(metallic.outputs["BSDF"], mix.inputs[2])
        shaders += [glossy.outputs["BSDF"], mix.outputs["Shader"]]

    if has_sheen:
        sheen = nodes.new("ShaderNodeBsdfSheen")
        sheen.distribution = "ASHIKHMIN"
        sheen.location = (-400, -400 - 350 * len(p.alphas))
        links.new(group_in.outputs["Sheen Color"], sheen.inputs["Color"])
        links.new(group_in.outputs["Sheen Roughness"], sheen.inputs["Roughness"])
        shaders.append(sheen.outputs["BSDF"])

    total = shaders[0]
    for j, shader in enumerate(shaders[1:]):
        add = nodes.new("ShaderNodeAddShader")
        add.location = (150 + 120 * j, 200 - 60 * j)
        links.new(total, add.inputs[0])
        links.new(shader, add.inputs[1])
        total = add.outputs["Shader"]
    links.new(total, group_out.inputs["Shader"])
    return ng


def build_material(name: str, fit, provenance: dict) -> bpy.types.Material:
    """A NEW material ``name`` (Blender suffixes it if taken; no existing material is
    touched) holding one "BRDF Reconstruction" group node -> Material Output.

    fit: a :class:`core.bake.fitting.LobeFit` (or its params, or their dict).
    provenance: JSON-able facts about where the BRDF came from; each key is stored
    as the custom property ``"brdf_" + key`` (strings as they are, anything else as
    a JSON string), e.g. ``{"table_path": ..., "settings": {...}}`` gives
    ``mat["brdf_table_path"]`` and ``mat["brdf_settings"]``. Also stored:
    ``mat["brdf_fit"]`` (parameters JSON), ``mat["brdf_errors"]`` and
    ``mat["brdf_fit_info"]`` (JSON, when ``fit`` is a LobeFit).
    """
    params = _params(fit)
    mat = bpy.data.materials.new(name)
    if mat.node_tree is None:  # before Blender 5.0 a material starts without nodes
        mat.use_nodes = True
    tree = mat.node_tree
    tree.nodes.clear()
    ng = build_node_group(params, GROUP_NAME)
    group = tree.nodes.new("ShaderNodeGroup")
    group.node_tree = ng
    group.label = GROUP_NAME
    group.name = GROUP_NAME
    group.location = (0, 0)
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    out.location = (300, 0)
    tree.links.new(group.outputs["Shader"], out.inputs["Surface"])

    for key, value in provenance.items():
        mat[f"brdf_{key}"] = (value if isinstance(value, str)
                              else json.dumps(value, sort_keys=True, default=str))
    mat["brdf_fit"] = json.dumps(params.to_dict(), sort_keys=True)
    if isinstance(fit, fitting.LobeFit):
        mat["brdf_errors"] = json.dumps(fit.errors, sort_keys=True)
        mat["brdf_fit_info"] = json.dumps(fit.info, sort_keys=True)
    return mat


def build_principled_material(name: str, fit, provenance: dict) -> bpy.types.Material:
    """A NEW material ``name`` whose tree is one Principled BSDF (single-scattering
    GGX) -> Material Output, its inputs :func:`core.bake.principled.from_lobes` of
    the lobe fit: what Eevee and the glTF exporter read. provenance as in
    :func:`build_material`; also stored: ``mat["brdf_principled"]`` (its
    parameters, JSON) and ``mat["brdf_fit"]`` (the lobe fit it came from)."""
    from ..core.bake import principled

    params = _params(fit)
    values = principled.from_lobes(params)
    mat = bpy.data.materials.new(name)
    if mat.node_tree is None:
        mat.use_nodes = True
    tree = mat.node_tree
    tree.nodes.clear()
    bsdf = tree.nodes.new("ShaderNodeBsdfPrincipled")
    bsdf.name = bsdf.label = PRINCIPLED_NAME
    bsdf.distribution = "GGX"  # single scattering, as the bake's lobes
    for key, value in values.to_inputs().items():
        bsdf.inputs[key].default_value = value
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    out.location = (300, 0)
    tree.links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    for key, value in provenance.items():
        mat[f"brdf_{key}"] = (value if isinstance(value, str)
                              else json.dumps(value, sort_keys=True, default=str))
    mat["brdf_principled"] = json.dumps(values.to_dict(), sort_keys=True)
    mat["brdf_fit_source"] = json.dumps(params.to_dict(), sort_keys=True)
    return mat


METAL_TEXTURE_NOTE = ("the Principled version is a metal, and the texture holds the "
                      "diffuse color: not linked")


def takes_texture(mat, model: str) -> bool:
    """Whether :func:`add_texture` should link a texture of ``model`` into ``mat``:
    every pair but a metallic Principled version (Metallic above 0.5) and a
    "diffuse" texture, whose file holds a diffuse colour a metal has not
    (:data:`METAL_TEXTURE_NOTE` says so in the report)."""
    bsdf = mat.node_tree.nodes.get(PRINCIPLED_NAME)
    metal = bsdf is not None and bsdf.inputs["Metallic"].default_value > 0.5
    return not (metal and model == "diffuse")


def add_texture(mat, image, uv_map: str = "", model: str = "diffuse") -> None:
    """Put a textured region's albedo image into a material :func:`build_material`
    or :func:`build_principled_material` made: an Image Texture on the mesh's UV map
    (``uv_map``; "" the render map). model "diffuse": the image is the diffuse
    colour (linked to the group's "Diffuse Color", or the Principled BSDF's "Base
    Color"); "whole": it multiplies every colour input of the group (the base
    color of the Principled one), each input's value times the texel's, by a
    Vector Math node. ValueError for a material without either node or another
    model."""
    if model not in ("diffuse", "whole"):
        raise ValueError(f"texture model must be 'diffuse' or 'whole', got {model!r}")
    tree = mat.node_tree
    group = tree.nodes.get(GROUP_NAME)
    bsdf = tree.nodes.get(PRINCIPLED_NAME)
    if (group is None or group.type != "GROUP") and bsdf is None:
        raise ValueError(f"material {mat.name!r} has no {GROUP_NAME!r} group node "
                         f"and no {PRINCIPLED_NAME!r} node")
    uv = tree.nodes.new("ShaderNodeUVMap")
    uv.uv_map = uv_map
    uv.location = (-700, 0)
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.name = tex.label = "BRDF Albedo"
    tex.image = image
    tex.location = (-500, 0)
    tree.links.new(uv.outputs["UV"], tex.inputs["Vector"])
    if group is None:  # the Principled version: the texture is its base color
        if model == "diffuse":
            tree.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
            return
        colours = [bsdf.inputs["Base Color"]]
    elif model == "diffuse":
        tree.links.new(tex.outputs["Color"], group.inputs["Diffuse Color"])
        return
    else:
        colours = [sock for sock in group.inputs if sock.type == "RGBA"]
    for k, sock in enumerate(colours):
        times = tree.nodes.new("ShaderNodeVectorMath")
        times.operation = "MULTIPLY"
        times.name = times.label = f"{sock.name} x Albedo"
        times.location = (-250, 200 - 150 * k)
        times.inputs[1].default_value = tuple(sock.default_value)[:3]
        tree.links.new(tex.outputs["Color"], times.inputs[0])
        tree.links.new(times.outputs["Vector"], sock)


# ------------------------------------------------------------------------- bake error
class _SphereScene:
    """A :class:`ScratchScene` with a unit sphere wearing ``material``, an
    orthographic camera looking down -z that frames [-1, 1]^2, a Sun, and a black
    world; Cycles on the CPU, direct light only, point-sampled pixels, linear float
    EXR output. Everything it creates is removed on exit, also after an error; the
    user's scenes and the context scene are not touched."""

    def __init__(self, material, resolution: int, render_samples: int):
        self.material = material
        self.resolution = resolution
        self.render_samples = render_samples
        self.scratch = ScratchScene("BRDF bake check", remove_new_images=True)

    def __enter__(self):
        self.scratch.__enter__()
        try:
            self._build()
        except BaseException:
            self.scratch.__exit__(None, None, None)
            raise
        return self

    def _build(self):
        scratch = self.scratch
        scene = scratch.scene
        # Point-sample each pixel centre, like the numpy sphere.
        configure_cycles(scene, self.render_samples, point_sampled=True)
        r = scene.render
        r.resolution_x = r.resolution_y = self.resolution
        r.resolution_percentage = 100
        r.pixel_aspect_x = r.pixel_aspect_y = 1.0
        r.film_transparent = False
        r.use_compositing = False
        r.use_sequencer = False
        float_exr_output(scene, color_mode="RGB")

        world = scratch.new(bpy.data.worlds, "BRDF bake check")
        if world.node_tree is None:  # before Blender 5.0
            world.use_nodes = True
        bg = next(n for n in world.node_tree.nodes if n.type == "BACKGROUND")
        bg.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
        bg.inputs["Strength"].default_value = 0.0
        scene.world = world

        # The sphere is one point of radius 1: Cycles intersects points as true
        # spheres with exact normals (a UV sphere's interpolated normals are off by
        # ~1e-4 rad, enough to move a roughness-0.1 highlight's peak by 2 %).
        nodes_tree = scratch.new(bpy.data.node_groups, "BRDF bake check sphere",
                                 "GeometryNodeTree")
        nodes_tree.interface.new_socket("Geometry", in_out="OUTPUT",
                                        socket_type="NodeSocketGeometry")
        points = nodes_tree.nodes.new("GeometryNodePoints")
        points.inputs["Count"].default_value = 1
        points.inputs["Position"].default_value = (0.0, 0.0, 0.0)
        points.inputs["Radius"].default_value = 1.0
        set_material = nodes_tree.nodes.new("GeometryNodeSetMaterial")
        set_material.inputs["Material"].default_value = self.material
        output = nodes_tree.nodes.new("NodeGroupOutput")
        nodes_tree.links.new(points.outputs["Points"], set_material.inputs["Geometry"])
        nodes_tree.links.new(set_material.outputs["Geometry"], output.inputs["Geometry"])
        mesh = scratch.new(bpy.data.meshes, "BRDF bake check sphere")
        sphere = scratch.new(bpy.data.objects, "BRDF bake check sphere", mesh)
        modifier = sphere.modifiers.new("sphere", "NODES")
        modifier.node_group = nodes_tree
        scene.collection.objects.link(sphere)

        cam_data = scratch.new(bpy.data.cameras, "BRDF bake check camera")
        cam_data.type = "ORTHO"
        cam_data.ortho_scale = 2.0
        cam_data.clip_start = 0.1
        cam_data.clip_end = 100.0
        camera = scratch.new(bpy.data.objects, "BRDF bake check camera", cam_data)
        camera.location = (0.0, 0.0, 10.0)  # identity rotation: looks down -z, +y up
        scene.collection.objects.link(camera)
        scene.camera = camera

        sun_data = scratch.new(bpy.data.lights, "BRDF bake check sun", "SUN")
        sun_data.angle = 0.0  # a delta light: no penumbra, no blur of sharp lobes
        self.sun = scratch.new(bpy.data.objects, "BRDF bake check sun", sun_data)
        scene.collection.objects.link(self.sun)

    def render(self, light, irradiance: float) -> np.ndarray:
        """Linear radiance image (H, W, 3), row 0 at +y, under a Sun from ``light``
        (unit (3,), towards the light) of ``irradiance`` W/m^2."""
        # A Sun shines along its local -Z: point local +Z at the light.
        self.sun.rotation_mode = "QUATERNION"
        self.sun.rotation_quaternion = Vector(light).normalized().to_track_quat("Z", "Y")
        self.sun.data.energy = irradiance  # Sun strength is irradiance in W/m^2
        return photo_io.read_photo(self.scratch.render("render.exr"))

    def __exit__(self, *exc):
        return self.scratch.__exit__(*exc)


def render_sphere_cycles(material, lights, resolution: int = 64, render_samples: int = 16,
                         irradiance: float = 1.0) -> list[np.ndarray]:
    """Cycles images (H, W, 3) of a unit sphere with ``material``, one per light.

    lights: (L, 3) directions towards the light, camera space (+z towards the
    viewer, +y up), as in :func:`core.brdf.render.render_sphere`. Pixels outside the
    sphere are black. Uses and then removes a temporary scene.
    """
    lights = np.atleast_2d(np.asarray(lights, dtype=np.float64))
    with _SphereScene(material, resolution, render_samples) as tmp:
        return [tmp.render(light, irradiance) for light in lights]


def bake_error(material, table, lights, resolution: int = 64, render_samples: int = 16,
               irradiance: float = 1.0, interpolation: str = "trilinear") -> dict:
    """Relative RMSE of Cycles renders of ``material`` against numpy shading of
    ``table``, one per light.

    table: (3, 90, 90, 180) BRDF in 1/sr (NaN = unmeasured). lights: (L, 3)
    directions towards the light in camera space (+z to the viewer), as in
    :func:`core.brdf.render.render_sphere`; the fit used the whole table, so any lights
    are "held out" in the sense that none was singled out by the fit, but pick
    ones other than the fit's own ``fitting.ERROR_LIGHTS`` to check the bake
    independently. The Sun's strength is ``irradiance`` (W/m^2 on a surface facing
    it), the numpy side uses the same value. render_samples: Cycles samples per pixel;
    with a delta Sun, direct light only and point-sampled pixels the render is
    nearly noise-free, but Cycles' narrow pixel filter still throws the odd sample
    into a neighbouring pixel, which 16 samples average away. interpolation: how
    the table is read between bin centres ("trilinear", or "nearest" for the
    reference reader's bins, which alone is ~20 % off a 0.013-wide mirror lobe on
    a 64-pixel sphere, and would be charged to the bake).

    Returns ``{"rel_rmse": [per light], "mean": float, "max": float,
    "lights": [[x, y, z], ...], "resolution", "samples", "time_s"}``, and
    ``"model_rel_rmse"`` (numpy evaluation of the material's stored ``brdf_fit``
    against the table, per light) when the material has one: the difference
    between the two is Cycles' share of the error.
    """
    t0 = time.perf_counter()
    lights = np.atleast_2d(np.asarray(lights, dtype=np.float64))
    lights = lights / np.linalg.norm(lights, axis=1, keepdims=True)
    table = fitting.clean_table(table, copy=False)  # only read here
    normals, mask = render.sphere_normals(resolution)
    images = render_sphere_cycles(material, lights, resolution, render_samples, irradiance)
    stored = material.get("brdf_fit")
    params = lobes.LobeParams.from_dict(json.loads(stored)) if stored else None
    rel, model_rel = [], []
    for light, image in zip(lights, images, strict=True):
        ref = np.zeros((resolution, resolution, 3))
        ref[mask] = render.shade(table, normals[mask], light, (0.0, 0.0, 1.0), irradiance,
                                 interpolation)
        rel.append(metrics.relative_rmse(np.where(mask[..., None], image, 0.0), ref))
        if params is not None:
            model = np.zeros_like(ref)
            model[mask] = shade_params(params, normals[mask], light, irradiance)
            model_rel.append(metrics.relative_rmse(model, ref))
    out = {"rel_rmse": [float(e) for e in rel], "mean": float(np.mean(rel)),
           "max": float(np.max(rel)), "lights": lights.tolist(), "resolution": resolution,
           "samples": render_samples, "time_s": time.perf_counter() - t0}
    if params is not None:
        out["model_rel_rmse"] = [float(e) for e in model_rel]
    return out


def shade_params(params, n: np.ndarray, light, irradiance: float = 1.0) -> np.ndarray:
    """Radiance (N, 3) of the lobe model at normals ``n`` (N, 3), camera space,
    seen from +z, lit from ``light`` (3,): what Cycles should render."""
    from ..core.brdf import merl

    n = np.asarray(n, dtype=np.float64).reshape(-1, 3)
    light = np.asarray(light, dtype=np.float64)
    light = np.broadcast_to(light / np.linalg.norm(light), n.shape)
    view = np.broadcast_to(np.array([0.0, 0.0, 1.0]), n.shape)
    rho = lobes.evaluate(params, merl.to_local(n, light), merl.to_local(n, view))
    cos = np.clip(np.sum(n * light, axis=1), 0.0, None)
    return rho * cos[:, None] * irradiance
