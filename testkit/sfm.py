"""Photogrammetry for real (issue 5): pycolmap SfM on ambient renders of the bunny,
for the SfM benchmark (``bench/sfm.py``) and the SfM test (``tests/blender/test_sfm.py``).

The synthetic capture (``testkit/capture.py``) hands the pipeline the true COLMAP
cameras. Here the photogrammetry step is exercised instead: the ground-truth
bunny, with a procedural "baked-in" colour texture, is rendered by Cycles
under ambient light only from the cameras of ``capture.camera_ring``; pycolmap
(SIFT on the CPU, exhaustive matching, incremental mapping) recovers the
cameras from those PNGs alone; and the recovered cameras are compared with
the true ones after a similarity alignment.

- :func:`render_ambient_views`: the PNGs (and the true COLMAP model).
- :func:`run_sfm`: feature extraction, matching, mapping; the largest model.
- :func:`camera_errors`: registered images, rotation and centre errors after a
  Umeyama similarity alignment, reprojection error, points, focal length.
- The command line is the benchmark's: ``python bench/sfm.py [--views N]
  [--width W --height H] [--out bench/results/sfm.json]``.

Frames and units: world = the ground truth's frame (object centred at the
origin, unit radius, z up); COLMAP poses ``(R_cam_from_world (3, 3), t (3,))``
with ``X_cam = R X + t`` (camera x right, y down, z forward); pixels in
COLMAP's convention (image over [0, W] x [0, H]). A recovered model has its
own arbitrary frame and scale until aligned.
"""

from __future__ import annotations

import dataclasses
import pathlib
import shutil
import time

import numpy as np

from . import capture

DEFAULT_VIEWS = 24
DEFAULT_RESOLUTION = (640, 480)
RENDER_SAMPLES = 32
TEXTURE_SCALE = 12.0  # noise features per unit length (the bunny has unit radius)


def view_name(i: int) -> str:
    """Image name of camera ``i`` of the ring, as ``capture.write_colmap`` writes it."""
    return f"view{i:03d}.png"


# --------------------------------------------------------------------------- rendering


def _textured_material(seed: int, scale: float):
    """A diffuse material whose albedo is a procedural colour texture fixed to the
    object (Object coordinates, so a surface point has the same colour in every
    view): the colours of a 3D Noise (``scale`` features per unit length) times
    those of 3D Voronoi cells (twice as fine; sharp corners for SIFT), times a
    brightness ramp of the noise, times 3, clamped to [0, 1]. ``seed`` shifts
    the pattern (3D rather than 4D textures with W = seed: a quarter cheaper)."""
    import bpy

    mat = bpy.data.materials.new("SfM texture")
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    nodes.clear()
    coords = nodes.new("ShaderNodeTexCoord")
    shift = nodes.new("ShaderNodeMapping")
    shift.inputs["Location"].default_value = tuple(
        np.random.default_rng(seed).uniform(-100.0, 100.0, 3)) if seed else (0.0, 0.0, 0.0)
    links.new(coords.outputs["Object"], shift.inputs["Vector"])
    noise = nodes.new("ShaderNodeTexNoise")
    cells = nodes.new("ShaderNodeTexVoronoi")
    noise.noise_dimensions = cells.voronoi_dimensions = "3D"
    for tex, tex_scale in ((noise, scale), (cells, 2.0 * scale)):
        tex.inputs["Scale"].default_value = tex_scale
        links.new(shift.outputs["Vector"], tex.inputs["Vector"])
    noise.inputs["Detail"].default_value = 6.0
    noise.inputs["Roughness"].default_value = 0.6
    noise.inputs["Distortion"].default_value = 0.3
    ramp = nodes.new("ShaderNodeValToRGB")  # stretch the noise's narrow value range
    ramp.color_ramp.elements[0].position = 0.3
    ramp.color_ramp.elements[1].position = 0.7
    links.new(noise.outputs["Color"], ramp.inputs["Fac"])

    def multiply(a, b, clamp=False):
        node = nodes.new("ShaderNodeMix")
        node.data_type = "RGBA"
        node.blend_type = "MULTIPLY"
        node.clamp_result = clamp
        node.inputs["Factor"].default_value = 1.0
        for socket, value in (("A", a), ("B", b)):
            if isinstance(value, tuple):
                node.inputs[socket].default_value = value
            else:
                links.new(value, node.inputs[socket])
        return node.outputs["Result"]

    albedo = multiply(multiply(multiply(noise.outputs["Color"], cells.outputs["Color"]),
                               ramp.outputs["Color"]), (3.0, 3.0, 3.0, 1.0), clamp=True)
    diffuse = nodes.new("ShaderNodeBsdfDiffuse")
    links.new(albedo, diffuse.inputs["Color"])
    out = nodes.new("ShaderNodeOutputMaterial")
    links.new(diffuse.outputs["BSDF"], out.inputs["Surface"])
    return mat


def render_ambient_views(folder, n_views: int = DEFAULT_VIEWS,
                         resolution: tuple[int, int] = DEFAULT_RESOLUTION,
                         focal_px: float | None = None, seed: int = 0, mesh=None, *,
                         samples: int = RENDER_SAMPLES, denoise: bool = False,
                         texture_scale: float = TEXTURE_SCALE, ambient: float = 1.0) -> dict:
    """Render the textured ground truth under ambient light from ``camera_ring(n_views)``.

    Resets Blender to an empty factory scene, loads ``mesh`` (an .obj/.ply
    path; default the bunny, ``capture.DATA / "stanford-bunny.obj"``) centred
    with unit radius, gives it :func:`_textured_material` (``texture_scale``:
    noise features per unit length; ``seed``: shifts the texture, and is
    Cycles' seed), and lights it by
    a uniform world of colour ``ambient`` (strength 1, no sun). The true
    cameras are written as a COLMAP model (PINHOLE, fx = fy = ``focal_px``,
    default 1.25 x width, principal point at the image centre) into
    ``folder / "truth_sparse"`` with ``capture.write_colmap`` and imported
    with the product's ``brdf_addon.colmap_import.import_cameras``. Each is rendered by
    Cycles on the CPU (``samples`` per pixel, one bounce, Standard view
    transform; ``denoise``: OpenImageDenoise, off by default as it costs about
    1.5 s per view to start and SIFT does as well without it) to an 8-bit RGB
    PNG ``folder / view000.png`` ... (``resolution`` = (W, H) pixels). The
    background is the uniform world colour.

    Returns {"images": [PNG paths, camera order], "poses": [(R (3, 3), t (3,))
    true COLMAP poses, world units], "focal_px": float, "resolution": (W, H),
    "truth_model": path, "seconds": render wall time}.
    """
    import bpy

    from brdf_reconstruct.brdf_addon import colmap_import
    from brdf_reconstruct.brdf_addon.scratch_scene import configure_cycles

    t0 = time.perf_counter()
    folder = pathlib.Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    width, height = (int(v) for v in resolution)
    focal_px = 1.25 * width if focal_px is None else float(focal_px)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    truth = capture.load_ground_truth(mesh or capture.DATA / "stanford-bunny.obj")
    truth.data.materials.append(_textured_material(seed, texture_scale))

    world = bpy.data.worlds.new("ambient")  # a new world has a Background node
    background = next(n for n in world.node_tree.nodes if n.type == "BACKGROUND")
    background.inputs["Color"].default_value = (ambient, ambient, ambient, 1.0)
    background.inputs["Strength"].default_value = 1.0
    scene.world = world

    poses = capture.camera_ring(n_views)
    co = np.zeros(len(truth.data.vertices) * 3)
    truth.data.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    model = capture.write_colmap(folder / "truth_sparse", poses, width, height, focal_px,
                                 co[:: max(1, len(co) // 2000)])
    cameras = colmap_import.import_cameras(scene, model)

    configure_cycles(scene, samples, bounces=1, denoise=denoise, seed=seed)
    scene.cycles.denoiser = "OPENIMAGEDENOISE"
    r = scene.render
    r.use_persistent_data = True  # one BVH for all views
    r.film_transparent = False
    scene.view_settings.view_transform = "Standard"
    r.image_settings.file_format = "PNG"
    r.image_settings.color_mode = "RGB"
    r.image_settings.color_depth = "8"
    images = []
    for cam in cameras:
        scene.camera = cam
        colmap_import.set_render_to_camera(scene, cam)
        path = folder / cam["brdf_image_name"]
        r.filepath = str(path)
        bpy.ops.render.render(write_still=True)
        images.append(path)
    return {"images": images, "poses": poses, "focal_px": focal_px,
            "resolution": (width, height), "truth_model": model,
            "seconds": time.perf_counter() - t0}


# --------------------------------------------------------------------------- SfM


@dataclasses.dataclass
class SfmRun:
    """One pycolmap reconstruction of a folder of images.

    reconstruction: the largest model (most registered images), a
        ``pycolmap.Reconstruction`` in its own arbitrary frame and scale, or
        None if mapping found none.
    intrinsics: "known" (one fixed PINHOLE camera given to SfM) or
        "estimated" (one shared SIMPLE_RADIAL camera, f and k refined by SfM
        from COLMAP's default guess f = 1.2 x max(W, H)).
    n_images: images given to SfM. n_models: models mapping produced.
    seconds: wall time per stage, {"extract", "match", "map"} (those run).
    database, model_dir: the COLMAP database and the folder the model is in.
    """

    reconstruction: object
    intrinsics: str
    n_images: int
    n_models: int
    seconds: dict
    database: pathlib.Path
    model_dir: pathlib.Path


def extract_and_match(image_folder, database, image_names=None, *, seed: int = 0,
                      num_threads: int = -1) -> dict:
    """SIFT features (CPU) of ``image_names`` (default every *.png directly in
    ``image_folder``) into a NEW COLMAP ``database`` (an existing file is
    replaced), all images sharing one camera; then exhaustive matching with
    geometric verification. Returns {"extract": s, "match": s} wall times."""
    import pycolmap

    image_folder, database = pathlib.Path(image_folder), pathlib.Path(database)
    if image_names is None:
        image_names = sorted(p.name for p in image_folder.glob("*.png"))
    database.parent.mkdir(parents=True, exist_ok=True)
    database.unlink(missing_ok=True)
    pycolmap.set_random_seed(seed)
    seconds = {}
    t0 = time.perf_counter()
    extraction = pycolmap.FeatureExtractionOptions()
    extraction.num_threads = num_threads
    pycolmap.extract_features(database, image_folder, image_names=list(image_names),
                              camera_mode=pycolmap.CameraMode.SINGLE,
                              extraction_options=extraction, device=pycolmap.Device.cpu)
    seconds["extract"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    matching = pycolmap.FeatureMatchingOptions()
    matching.num_threads = num_threads
    verification = pycolmap.TwoViewGeometryOptions()
    verification.ransac.random_seed = seed
    pycolmap.match_exhaustive(database, matching_options=matching,
                              verification_options=verification, device=pycolmap.Device.cpu)
    seconds["match"] = time.perf_counter() - t0
    return seconds


def map_database(database, image_folder, model_dir, focal_px: float | None = None, *,
                 seed: int = 0, min_model_size: int = 3) -> tuple[object, int, float]:
    """Incremental mapping of a matched ``database`` into ``model_dir`` (replaced).

    focal_px: the true focal length in pixels: the database's one camera
    becomes PINHOLE (f, f, W / 2, H / 2), held fixed in every bundle
    adjustment ("known" intrinsics). None: SIMPLE_RADIAL (f = 1.2 x max(W, H),
    W / 2, H / 2, k = 0) without a focal prior, f and k refined ("estimated",
    COLMAP's default for images without EXIF). The principal point is never
    refined (COLMAP's default). The database's camera is rewritten either way.

    Returns (largest reconstruction or None, number of models, wall seconds);
    the largest model is written (binary) to ``model_dir``.
    """
    import pycolmap

    t0 = time.perf_counter()
    database, model_dir = pathlib.Path(database), pathlib.Path(model_dir)
    db = pycolmap.Database.open(database)
    try:
        for camera in db.read_all_cameras():
            w, h = camera.width, camera.height
            model, params = (("PINHOLE", [focal_px, focal_px, w / 2, h / 2]) if focal_px
                             else ("SIMPLE_RADIAL", [1.2 * max(w, h), w / 2, h / 2, 0.0]))
            new = pycolmap.Camera.create_from_model_name(camera.camera_id, model, 1.0, w, h)
            new.params = np.asarray(params, dtype=np.float64)
            new.has_prior_focal_length = focal_px is not None
            db.update_camera(new)
    finally:
        db.close()
    options = pycolmap.IncrementalPipelineOptions()
    options.random_seed = seed
    options.min_model_size = min_model_size
    if focal_px:
        options.ba_refine_focal_length = False
        options.ba_refine_extra_params = False
        options.mapper.abs_pose_refine_focal_length = False
        options.mapper.abs_pose_refine_extra_params = False
    if model_dir.exists():
        shutil.rmtree(model_dir)
    scratch = model_dir.parent / (model_dir.name + "_all")
    if scratch.exists():
        shutil.rmtree(scratch)
    scratch.mkdir(parents=True)
    pycolmap.set_random_seed(seed)
    models = pycolmap.incremental_mapping(database, image_folder, scratch, options=options)
    shutil.rmtree(scratch)
    best = max(models.values(), key=lambda r: r.num_reg_images(), default=None)
    if best is not None:
        model_dir.mkdir(parents=True)
        best.write(model_dir)
    return best, len(models), time.perf_counter() - t0


def run_sfm(image_folder, work_folder, focal_px: float | None = None, *, image_names=None,
            seed: int = 0, num_threads: int = -1) -> SfmRun:
    """pycolmap sparse reconstruction of the PNGs in ``image_folder``.

    Feature extraction (SIFT, CPU, one camera for all images), exhaustive
    matching and incremental mapping (:func:`extract_and_match`,
    :func:`map_database`), with ``work_folder / "database.db"`` and the
    largest model written to ``work_folder / "sparse"``. ``focal_px``: known
    focal length in pixels (fixed PINHOLE camera), or None to let SfM
    estimate a SIMPLE_RADIAL camera. Seeded, but multi-threaded RANSAC and
    bundle adjustment need not repeat to the last digit.
    """
    work_folder = pathlib.Path(work_folder)
    database = work_folder / "database.db"
    seconds = extract_and_match(image_folder, database, image_names, seed=seed,
                                num_threads=num_threads)
    image_count = len(image_names) if image_names is not None else len(
        list(pathlib.Path(image_folder).glob("*.png")))
    rec, n_models, seconds["map"] = map_database(database, image_folder,
                                                 work_folder / "sparse", focal_px, seed=seed)
    return SfmRun(rec, "known" if focal_px else "estimated", image_count, n_models, seconds,
                  database, work_folder / "sparse")


# --------------------------------------------------------------------------- errors


def umeyama(src, dst) -> tuple[float, np.ndarray, np.ndarray]:
    """Similarity (s, Q (3, 3) rotation, d (3,)) minimising sum |s Q src_i + d - dst_i|^2.

    src, dst: (N, 3) corresponding points, N >= 3 not all on a line
    (Umeyama 1991, with the reflection guard)."""
    src = np.asarray(src, dtype=np.float64)
    dst = np.asarray(dst, dtype=np.float64)
    mu_s, mu_d = src.mean(axis=0), dst.mean(axis=0)
    a, b = src - mu_s, dst - mu_d
    U, S, Vt = np.linalg.svd(b.T @ a / len(src))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U) * np.linalg.det(Vt)) or 1.0])
    Q = U @ D @ Vt
    s = float(np.trace(np.diag(S) @ D) / np.mean(np.sum(a * a, axis=1)))
    return s, Q, mu_d - s * Q @ mu_s


def _poses(model) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """{image name: (R_cam_from_world (3, 3), t (3,))} of a pycolmap Reconstruction,
    a COLMAP model folder, a {name: pose} mapping or a list of poses (the ring's
    order, named view000.png ...)."""
    if isinstance(model, dict):
        return {k: (np.asarray(R, float), np.asarray(t, float)) for k, (R, t) in model.items()}
    if isinstance(model, list | tuple):
        return {view_name(i): (np.asarray(R, float), np.asarray(t, float))
                for i, (R, t) in enumerate(model)}
    if isinstance(model, str | pathlib.Path):
        import pycolmap

        model = pycolmap.Reconstruction(str(model))
    if model is None:  # mapping found no model
        return {}
    out = {}
    for image in model.images.values():
        if image.has_pose:
            m = np.asarray(image.cam_from_world().matrix(), dtype=np.float64)
            out[image.name] = (m[:, :3], m[:, 3])
    return out


def camera_errors(recovered, truth_poses, *, target=(0.0, 0.0, 0.0),
                  true_focal_px: float | None = None, n_images: int | None = None) -> dict:
    """Recovered cameras against the true ones, after a similarity alignment.

    recovered: a pycolmap Reconstruction (or a model folder, or None: nothing
        registered), or poses as for truth_poses, in SfM's own
        frame. truth_poses: the true COLMAP poses, a list of (R_cam_from_world
        (3, 3), t (3,)) named view000.png ... in order (``camera_ring``), or a
        {name: (R, t)} mapping; world units.
    target: (3,) the point the cameras look at (the object's centre); a
        camera's distance is its true centre's distance to it (world units).
    true_focal_px: the true focal length, pixels, to compare with the
        recovered one(s). n_images: images given to SfM (default: all true).

    The recovered camera centres are mapped onto the true ones, matched by
    image name, with the Umeyama similarity (s, Q, d): X_true = s Q X_rec + d.
    A recovered camera's rotation in the true frame is then R_rec Q^T.

    Returns a JSON-ready dict: "registered", "total"; "rotation_error_deg"
    and "centre_error_rel" (each {"median", "max", "per_image": {name: v}};
    the centre error is |aligned centre - true centre| / camera distance);
    "scale" (s); "mean_reprojection_error_px", "num_points3D",
    "mean_track_length"; "focal_px" (recovered, per camera) and
    "focal_rel_error" when ``true_focal_px`` is given; "camera_models".
    """
    truth = _poses(truth_poses)
    rec = _poses(recovered)
    names = sorted(set(rec) & set(truth))
    total = len(truth) if n_images is None else int(n_images)
    out = {"registered": len(names), "total": total}
    if isinstance(recovered, str | pathlib.Path):
        import pycolmap

        recovered = pycolmap.Reconstruction(str(recovered))
    if recovered is not None and not isinstance(recovered, dict | list | tuple):
        out["mean_reprojection_error_px"] = float(recovered.compute_mean_reprojection_error())
        out["num_points3D"] = int(recovered.num_points3D())
        out["mean_track_length"] = float(recovered.compute_mean_track_length())
        cams = list(recovered.cameras.values())
        out["camera_models"] = sorted({c.model.name for c in cams})
        focal = [float(np.mean(c.params[list(c.focal_length_idxs())])) for c in cams]
        out["focal_px"] = focal
        extra = {c.model.name: c.params[list(c.extra_params_idxs())].tolist() for c in cams
                 if len(c.extra_params_idxs())}
        if extra:
            out["distortion_params"] = extra
        if true_focal_px:
            out["true_focal_px"] = float(true_focal_px)
            out["focal_rel_error"] = [f / true_focal_px - 1.0 for f in focal]
    if len(names) < 3:
        out["error"] = "fewer than 3 registered images: no alignment"
        return out

    def centre(R, t):
        return -R.T @ t

    c_rec = np.array([centre(*rec[n]) for n in names])
    c_true = np.array([centre(*truth[n]) for n in names])
    s, Q, d = umeyama(c_rec, c_true)
    aligned = s * c_rec @ Q.T + d
    distance = np.linalg.norm(c_true - np.asarray(target, dtype=np.float64), axis=1)
    centre_err = np.linalg.norm(aligned - c_true, axis=1) / distance
    rel = np.array([truth[n][0] @ (rec[n][0] @ Q.T).T for n in names])  # (K, 3, 3)
    # |R - I|_F = 2 sqrt(2) sin(angle / 2): exact to small angles, unlike arccos of the trace
    chord = np.linalg.norm(rel - np.eye(3), axis=(1, 2)) / (2.0 * np.sqrt(2.0))
    rot_err = np.degrees(2.0 * np.arcsin(np.clip(chord, 0.0, 1.0)))

    def summary(values):
        return {"median": float(np.median(values)), "max": float(np.max(values)),
                "per_image": {n: float(v) for n, v in zip(names, values, strict=True)}}

    out["rotation_error_deg"] = summary(rot_err)
    out["centre_error_rel"] = summary(centre_err)
    out["scale"] = s
    return out


# --------------------------------------------------------------------------- CLI
