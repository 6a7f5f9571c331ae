"""Synthetic photogrammetry capture (issue 5, in progress): the geometry part.

What exists:
- :func:`load_ground_truth`: a mesh file as a new object, centred at the origin
  and scaled to unit radius (the bunny or Spot from ../shared/data).
- :func:`photogrammetry_mesh`: the "photogrammetry" copy of it, degraded as a
  multi-view reconstruction is (the paper's Fig. 3c-d): decimated, smoothed so
  edges and fine detail are blunted, with small seeded vertex noise. A NEW
  object; the ground truth is untouched.
- :func:`camera_ring`: camera poses on rings around the object (COLMAP
  convention), and :func:`write_colmap` the COLMAP model of them, with the
  ground truth's vertices as 3D points, written through pycolmap so that the
  extension's real import path is used.
- :func:`normal_angle_error`: the scan's normals against the ground truth's,
  per pixel of a camera, from Cycles G-buffers of both.

- :func:`render_lit_photos`: the lit photos, shaded by the ground-truth table
  itself (the Cycles table shader, ``brdf_addon.table_shader``).
- :func:`generate`: all of it as files a user would have, with a job file, and
  the ground truth as ``truth.ply`` in the scan's frame (the exact-normal scan:
  a job with ``mesh = "truth.ply"``).

The ambient multi-view images and pycolmap's SfM on them are in ``testkit/sfm.py``
(the benchmark: ``bench/sfm.py``). Used by the demo (``bench/demo.py``), the
benchmarks (``bench/capture_arrays.py``, ``bench/heldout_bench.py``,
``bench/camera_inputs_bench.py``, ``bench/footprint_bench.py``) and the capture
tests (``tests/blender/``); run as a script (:func:`command`) it writes one capture
folder.
"""

from __future__ import annotations

import math
import os
import pathlib
import sys

import bpy
import numpy as np

# the ground-truth meshes: ../shared/data beside the repository, or $BRDF_SHARED_DATA
DATA = pathlib.Path(os.environ.get(
    "BRDF_SHARED_DATA", pathlib.Path(__file__).resolve().parents[2] / "shared" / "data"))


def load_ground_truth(path: str | pathlib.Path, name: str = "GroundTruth"):
    """Import an .obj/.ply as one new mesh object at the origin with unit radius."""
    path = pathlib.Path(path)
    before = set(bpy.data.objects)
    importer = {".obj": bpy.ops.wm.obj_import, ".ply": bpy.ops.wm.ply_import}[path.suffix]
    importer(filepath=str(path))
    new = [o for o in bpy.data.objects if o not in before and o.type == "MESH"]
    if len(new) != 1:
        raise ValueError(f"{path.name} holds {len(new)} meshes, not one")
    obj = new[0]
    obj.name = name
    return _unit_smooth(obj)


def _unit_smooth(obj):
    """Bake ``obj``'s transform into its vertices, centred at the origin with unit
    radius (bounding-box centre, farthest vertex at 1), every face smooth."""
    mesh = obj.data
    co = np.zeros(len(mesh.vertices) * 3)
    mesh.vertices.foreach_get("co", co)
    co = _world(obj, co.reshape(-1, 3))  # the importer may rotate (Y-up files)
    centre = 0.5 * (co.min(axis=0) + co.max(axis=0))
    co = (co - centre) / np.max(np.linalg.norm(co - centre, axis=1))
    obj.matrix_world = _identity()
    mesh.vertices.foreach_set("co", co.ravel())
    mesh.update()
    for polygon in mesh.polygons:
        polygon.use_smooth = True
    return obj


def default_ground_truth(name: str = "GroundTruth"):
    """The Stanford bunny from :data:`DATA` if it is there; otherwise Blender's
    Suzanne, subdivided twice and smoothed (about 8k faces; concave, self-
    shadowing), so that a machine without ../shared/data still runs a capture."""
    bunny = DATA / "stanford-bunny.obj"
    if bunny.is_file():
        return load_ground_truth(bunny, name)
    _say(f"{bunny} not found: using Blender's Suzanne as the ground truth")
    bpy.ops.mesh.primitive_monkey_add()
    obj = bpy.context.active_object
    subsurf = obj.modifiers.new("subdivide", "SUBSURF")
    subsurf.levels = subsurf.render_levels = 2
    depsgraph = bpy.context.evaluated_depsgraph_get()
    baked = bpy.data.meshes.new_from_object(obj.evaluated_get(depsgraph))
    old = obj.data
    obj.modifiers.clear()
    obj.data = baked
    bpy.data.meshes.remove(old)
    obj.name = name
    return _unit_smooth(obj)


def _identity():
    from mathutils import Matrix

    return Matrix.Identity(4)


def _world(obj, co):
    """(N, 3) object-space points -> world space."""
    m = np.array(obj.matrix_world)
    return co @ m[:3, :3].T + m[:3, 3]


def photogrammetry_mesh(truth, *, decimate_ratio: float = 0.2, smooth_iterations: int = 8,
                        smooth_factor: float = 0.5, noise: float = 0.002, seed: int = 0,
                        name: str = "Scan"):
    """A degraded copy of ``truth`` (a new object with a new mesh).

    decimate_ratio: share of faces kept (collapse). smooth_iterations,
    smooth_factor: Laplacian-like vertex smoothing that blunts edges and fine
    detail. noise: standard deviation of the vertex displacement along the
    normal, in units of the object's radius (1). Seeded.
    """
    obj = truth.copy()
    obj.data = truth.data.copy()
    obj.name = obj.data.name = name
    bpy.context.scene.collection.objects.link(obj)
    decimate = obj.modifiers.new("decimate", "DECIMATE")
    decimate.ratio = decimate_ratio
    smooth = obj.modifiers.new("smooth", "SMOOTH")
    smooth.iterations = smooth_iterations
    smooth.factor = smooth_factor
    depsgraph = bpy.context.evaluated_depsgraph_get()
    evaluated = obj.evaluated_get(depsgraph)
    baked = bpy.data.meshes.new_from_object(evaluated)
    old = obj.data
    obj.modifiers.clear()
    obj.data = baked
    bpy.data.meshes.remove(old)
    baked.name = name
    n = len(baked.vertices)
    co = np.zeros(n * 3)
    normal = np.zeros(n * 3)
    baked.vertices.foreach_get("co", co)
    baked.vertices.foreach_get("normal", normal)
    shift = np.random.default_rng(seed).normal(0.0, noise, n)[:, None]
    baked.vertices.foreach_set("co", (co.reshape(-1, 3) + shift * normal.reshape(-1, 3)).ravel())
    baked.update()
    for polygon in baked.polygons:
        polygon.use_smooth = True
    return obj


def camera_ring(n_views: int, distance: float = 3.5,
                elevations_deg=(-10.0, 20.0, 50.0)) -> list[tuple[np.ndarray, np.ndarray]]:
    """COLMAP poses (R_cam_from_world, t) of ``n_views`` cameras spread over rings at
    the given elevations, all looking at the origin from ``distance``."""
    from brdf_reconstruct.core.capture import cameras

    poses = []
    rings = len(elevations_deg)
    for i in range(n_views):
        ring = i % rings
        k = i // rings
        per_ring = math.ceil(n_views / rings)
        azimuth = 2 * math.pi * (k + 0.5 * ring) / per_ring
        el = math.radians(elevations_deg[ring])
        centre = distance * np.array([math.cos(el) * math.cos(azimuth),
                                      math.cos(el) * math.sin(azimuth), math.sin(el)])
        poses.append(cameras.look_at(centre, [0.0, 0.0, 0.0]))
    return poses


def write_colmap(folder: str | pathlib.Path, poses, width: int, height: int,
                 focal_px: float, points) -> pathlib.Path:
    """Write a binary COLMAP model (PINHOLE cameras, images view000.png ...) of the
    poses, with ``points`` (N, 3) as the sparse 3D points; returns the folder."""
    from testkit import synthetic

    folder = pathlib.Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    views = [(f"view{i:03d}.png", "PINHOLE", [focal_px, focal_px, width / 2, height / 2],
              width, height, R, t) for i, (R, t) in enumerate(poses)]
    synthetic.synthetic_reconstruction(views, points).write(str(folder))
    return folder


def normal_angle_error(truth, scan, camera, resolution) -> np.ndarray:
    """Angles (radians) between the scan's and the ground truth's rendered normals,
    at the pixels both cover, seen by ``camera`` (Cycles G-buffers)."""
    from brdf_reconstruct.brdf_addon import gbuffer

    light = np.array([0.0, 0.0, 1.0])
    a = gbuffer.render_gbuffers(truth, camera, light, resolution=resolution)
    b = gbuffer.render_gbuffers(scan, camera, light, resolution=resolution)
    both = a.mask & b.mask
    cos = np.clip(np.sum(a.normal[both] * b.normal[both], axis=-1), -1.0, 1.0)
    return np.arccos(cos)


def _textured(material, texture_path) -> None:
    """Multiply the table material's shading by an Image Texture (linear, on the
    mesh's active UV map): the whole table scales with the texel's value."""
    tree = material.node_tree
    diffuse = next(n for n in tree.nodes if n.type == "BSDF_DIFFUSE")
    link = diffuse.inputs["Color"].links[0]
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image = bpy.data.images.load(str(texture_path), check_existing=False)
    tex.image.colorspace_settings.name = "Non-Color"
    tex.interpolation = "Closest"
    times = tree.nodes.new("ShaderNodeMix")
    times.data_type, times.blend_type = "RGBA", "MULTIPLY"
    times.inputs["Factor"].default_value = 1.0
    tree.links.new(link.from_socket, times.inputs["A"])
    tree.links.new(tex.outputs["Color"], times.inputs["B"])
    tree.links.new(times.outputs["Result"], diffuse.inputs["Color"])


def render_lit_photos(truth, cameras, table, light, folder, resolution, irradiance=1.0,
                      samples: int = 16, texture_path=None) -> list[pathlib.Path]:
    """Linear EXR photos of ``truth`` shaded by the ground-truth ``table`` (not an
    approximation: ``brdf_addon.table_shader``) under one distant light, one per
    camera, direct light only; ``texture_path``: a linear EXR on the truth's UV map
    that multiplies the whole table per texel. A temporary scene; the user's scene
    is unchanged."""
    from brdf_reconstruct.brdf_addon import cycles_select, table_shader

    folder = pathlib.Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    light = np.asarray(light, dtype=np.float64) / np.linalg.norm(light)
    images_before = set(bpy.data.images)
    material = table_shader.table_material("ground truth", table, light)
    if texture_path is not None:
        _textured(material, texture_path)
    try:
        paths = [folder / (pathlib.Path(cam["brdf_image_name"]).stem + ".exr")
                 for cam in cameras]
        for i, (cam, path) in enumerate(zip(cameras, paths, strict=True)):
            _say(f"photo {i + 1}/{len(paths)}: {path.name}")
            cycles_select.render_candidate(truth, material, cam, light, irradiance,
                                           resolution, samples, path=path)
        return paths
    finally:
        bpy.data.materials.remove(material)
        for image in set(bpy.data.images) - images_before:
            bpy.data.images.remove(image)


def build_scene(sparse_folder, resolution=(240, 180), n_views: int = 6, seed: int = 0,
                scan_options: dict | None = None, mesh=None, focal_px: float | None = None,
                points=None):
    """The capture's Blender objects in a new empty scene: ``(truth, scan, cameras)``.

    truth: the ground truth (``mesh``, default :func:`default_ground_truth`);
    scan: its degraded copy (:func:`photogrammetry_mesh`, seeded); cameras: one per
    view of :func:`camera_ring`, from the COLMAP model written to ``sparse_folder``
    (PINHOLE, ``focal_px`` default 1.25 x the width; ``points`` (N, 3), default up
    to 2000 of the truth's vertices) and imported by the extension's own COLMAP
    importer. The points set the scene scale the importer derives the cameras'
    clip range from, so they change the G-buffers in the last float digits.
    """
    from brdf_reconstruct.brdf_addon import colmap_import

    bpy.ops.wm.read_factory_settings(use_empty=True)
    _say("loading the ground-truth mesh and degrading it into the scan")
    truth = load_ground_truth(mesh) if mesh else default_ground_truth()
    scan = photogrammetry_mesh(truth, seed=seed, **(scan_options or {}))
    if points is None:
        co = np.zeros(len(truth.data.vertices) * 3)
        truth.data.vertices.foreach_get("co", co)
        points = co.reshape(-1, 3)[:: max(1, len(co) // 3 // 2000)]
    focal_px = 1.25 * resolution[0] if focal_px is None else focal_px
    sparse = write_colmap(sparse_folder, camera_ring(n_views), *resolution, focal_px, points)
    return truth, scan, colmap_import.import_cameras(bpy.context.scene, sparse)


def generate(folder, table, *, mesh=None, n_views: int = 6, lit_views=(0, 2, 4),
             light=(0.35, -0.45, 0.82), resolution=(160, 120), focal_px: float | None = None,
             seed: int = 0, scan_options: dict | None = None,
             texture: np.ndarray | None = None) -> pathlib.Path:
    """A whole synthetic capture in ``folder``: ``scan.ply`` (the degraded mesh),
    ``sparse/0`` (COLMAP model of every camera), ``lit/*.exr`` (photos of the
    ground truth shaded by ``table`` from the ``lit_views`` cameras under one
    distant light), ``truth.binary`` and ``job.toml`` for the batch entry.
    focal_px: default 1.25 x the width, so the object fills the frame alike at
    any resolution. texture: (H, W, 3) linear multiplier on the truth's UV map (row 0
    at the top; the mesh needs a UV map, as Spot has), written as
    ``truth_texture.exr``; the photos' whole table scales with it, the scan keeps the
    UV map (``scan.ply`` with UVs) and the job turns ``texture`` on. Resets Blender
    to an empty scene. Returns the job file's path."""
    from brdf_reconstruct.core.brdf import merl
    from brdf_reconstruct.core.method import texture_io

    folder = pathlib.Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    truth, scan, cameras = build_scene(folder / "sparse" / "0", resolution, n_views, seed,
                                       scan_options, mesh, focal_px)
    _say(f"rendering {len(lit_views)} lit photos with the true table (Cycles)")
    texture_path = None
    if texture is not None:
        if not len(truth.data.uv_layers):
            raise ValueError("a textured capture needs a ground truth with a UV map")
        texture_path = folder / "truth_texture.exr"
        texture_io.write_albedo(texture_path, np.asarray(texture, dtype=np.float64), "EXR")
    photos = render_lit_photos(truth, [cameras[i] for i in lit_views], table, light,
                               folder / "lit", resolution, texture_path=texture_path)
    export_ply(scan, folder / "scan.ply")
    export_ply(truth, folder / "truth.ply")
    merl.write(folder / "truth.binary", table)
    lines = ['mesh = "scan.ply"', 'colmap = "sparse/0"', 'out = "out"', "",
             "[settings]", f"seed = {seed}"]
    if texture is not None:
        lines += ["texture = true", f"texture_size = {np.shape(texture)[0]}"]
    lines += [""]
    for path in photos:
        lines += ["[[photo]]", f'image = "lit/{path.name}"',
                  f'camera = "{path.stem}.png"', f"light = {list(map(float, light))}", ""]
    job = folder / "job.toml"
    job.write_text("\n".join(lines))
    return job


def export_ply(obj, path) -> pathlib.Path:
    """Write ``obj`` alone as a PLY file (world coordinates, normals and UVs, Blender's
    default axes, which the job file's ``mesh`` import keeps): ``scan.ply`` and
    ``truth.ply`` of :func:`generate` alike, so both share the cameras' frame."""
    bpy.ops.object.select_all(action="DESELECT")
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    bpy.ops.wm.ply_export(filepath=str(path), export_selected_objects=True,
                          export_normals=True, export_uv=True, apply_modifiers=True)
    return pathlib.Path(path)


def default_subject() -> str:
    """"bunny" when :data:`DATA` holds the Stanford bunny, else "suzanne" (the
    fallback of :func:`default_ground_truth`)."""
    return "bunny" if (DATA / "stanford-bunny.obj").is_file() else "suzanne"


def cache_folder(material: str, views: int, lit: int, resolution, seed: int,
                 mesh=None) -> pathlib.Path:
    """Where the benchmarks and the demo keep the capture of these settings
    (``<cache>/captures/<subject>_<material>_...``); see :func:`command`. subject:
    :func:`default_subject`, or the stem of ``mesh`` (a ground-truth mesh file, e.g.
    ``spot`` for ``spot.obj``) when one is given."""
    from brdf_reconstruct.core.brdf import basis

    w, h = resolution
    subject = pathlib.Path(mesh).stem if mesh else default_subject()
    return (basis.default_cache_dir() / "captures"
            / f"{subject}_{material}_{views}v{lit}l_{w}x{h}_s{seed}")


def command(folder, material: str, views: int, lit: int, resolution, seed: int,
            mesh=None) -> list:
    """The command line that writes that capture to ``folder`` (a fresh process, so
    that the caller's Blender scene is untouched); ``mesh``: the ground truth's mesh
    file (``--mesh``), default :func:`default_ground_truth`'s."""
    w, h = resolution
    line = [sys.executable, str(pathlib.Path(__file__).resolve()), str(folder),
            "--material", material, "--views", str(views), "--lit", str(lit),
            "--width", str(w), "--height", str(h), "--seed", str(seed)]
    return line + (["--mesh", str(pathlib.Path(mesh).resolve())] if mesh else [])


def preset_job(folder, preset: str, out=None) -> pathlib.Path:
    """A copy of ``folder/job.toml`` with ``preset`` in its ``[settings]`` (and ``out``
    if given), as ``folder/job_<preset>.toml``: same folder, so the job's relative
    paths still hold. Returns its path."""
    folder = pathlib.Path(folder)
    text = (folder / "job.toml").read_text()
    text = text.replace("[settings]\n", f'[settings]\npreset = "{preset}"\n', 1)
    if out is not None:
        text = text.replace('out = "out"', f'out = "{pathlib.Path(out).as_posix()}"', 1)
    job = folder / f"job_{preset.lower()}.toml"
    job.write_text(text)
    return job


def _say(message: str) -> None:
    """A progress line (``capture: ...``) that callers such as ``make demo`` show."""
    print(f"capture: {message}", flush=True)


def main(argv=None) -> int:
    """``python testkit/capture.py OUT --material NAME [--mesh PATH] ...``: write a
    capture to OUT. NAME: an analytic held-out material (``database.heldout_specs``)
    or a measured one of the pack (``testkit.measured.PACK``); PATH: the ground
    truth's .obj/.ply (default: the bunny of ../shared/data, else Suzanne)."""
    import argparse

    from brdf_reconstruct.core.brdf import database

    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument("out")
    parser.add_argument("--material", default="heldout_gold_medium")
    parser.add_argument("--views", type=int, default=6)
    parser.add_argument("--lit", type=int, default=3)
    parser.add_argument("--width", type=int, default=240)
    parser.add_argument("--height", type=int, default=180)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--mesh", default=None,
                        help="the ground truth's .obj/.ply (default: the bunny)")
    args = parser.parse_args(argv)
    if args.mesh and not pathlib.Path(args.mesh).is_file():
        print(f"error: mesh not found: {args.mesh}", file=sys.stderr)
        return 2
    specs = {s["name"]: s for s in database.heldout_specs()}
    if args.material in specs:
        table = database.make_table(specs[args.material])
    else:  # a measured material of the pack (testkit.measured.PACK)
        from brdf_reconstruct.core.brdf import nbrdf
        from testkit import measured

        pack = nbrdf.load(measured.PACK) if measured.PACK.is_file() else None
        if pack is None or args.material not in pack.names:
            print(f"error: unknown material {args.material!r} (neither an analytic "
                  "held-out material nor one of the measured pack's)", file=sys.stderr)
            return 2
        table = nbrdf.tabulate(pack, pack.index(args.material))
    step = max(1, args.views // args.lit)
    job = generate(args.out, table, mesh=args.mesh, n_views=args.views,
                   lit_views=tuple(range(0, args.views, step))[: args.lit],
                   resolution=(args.width, args.height), seed=args.seed)
    print(f"wrote {job}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
