"""Peer method for issue 5: Mitsuba 3 inverse rendering of a Principled BSDF.

A user without our extension could fit a Principled-type BSDF to the same photos
with a differentiable renderer. This module does that with Mitsuba 3 (CPU
variant ``llvm_ad_rgb``), from a capture's own files only, and tabulates the
fitted BSDF on the MERL grid so it is scored exactly like our reconstruction
(``core.brdf.metrics.sphere_error`` / ``brdf_log_rmse``).

The peer of ``bench/heldout_bench.py`` (which runs ``python -m testkit.mitsuba_peer``
in a subprocess); its conventions are tested in ``tests/test_mitsuba_peer.py``.

Dev-only: Mitsuba is in ``requirements-bench.txt``, never a dependency of the
extension. Needs the LLVM shared library, version >= 17 (Debian 12:
``apt-get install libllvm19``; with LLVM 14/15 Dr.Jit 1.5 aborts on its first
kernel, "Cannot select: fminimum"); :func:`mitsuba` points ``DRJIT_LIBLLVM_PATH``
at it unless that is set.

Set-up (:func:`fit_principled`):

- Geometry: the capture's ``scan.ply`` (the degraded scan our method also gets),
  loaded as is, so it stays in the COLMAP/Blender world frame, with its vertex
  normals.
- Cameras: ``sparse/0`` through ``core.capture.colmap``. COLMAP's camera frame is x right,
  y down, z forward; Mitsuba's sensor frame is x left, y up, z forward, so the
  sensor's ``to_world`` is COLMAP's camera-to-world times ``diag(-1, -1, 1)``.
  Checked twice (:func:`camera_check`): every camera's Mitsuba rays against
  COLMAP back-projected pixels (angle), and the scan's silhouette traced through
  those rays against the photo's coverage (IoU).
- Light: a ``directional`` emitter travelling along ``-light`` (the job stores the
  direction towards the light), irradiance ``E`` (job default 1) W/m^2 on a
  surface facing it: a white Lambertian plane facing it has radiance
  ``E albedo / pi`` (:func:`check_irradiance`).
- Photos: the linear EXRs named in ``job.toml``. Loss: mean squared error of the
  rendered RGB radiance over the pixels that the scan covers (its silhouette,
  eroded by one pixel so that anti-aliased edges do not count), summed over the
  lit views. No other mask: a user has the photo and the scan, nothing more.
- BSDF: ``principled`` with base_color (RGB), roughness, metallic, specular,
  started at mid values (:data:`INITIAL`), optimised with ``mi.ad.Adam``
  (Mitsuba's documented loop: render, ``dr.backward``, ``opt.step``, clamp to
  the valid range, ``params.update``); 150 steps at learning rate 0.05, decayed
  to 0.005 over the last 40 % (:func:`learning_rate`). Every lit view is
  rendered in every step (a full-batch gradient). The loss curves flatten after
  about 100 steps on the held-out captures (``bench/results/heldout.json``).
  Also fitting clearcoat and clearcoat_gloss (``keys=WITH_CLEARCOAT``) did not
  lower the photo loss beyond its noise on six held-out captures, so the
  default is the four parameters a user fits first.
- Integrator: ``prb`` with ``max_depth=2``: direct illumination only, as in the
  photos (direct light, black world). With a delta light the render noise is
  only the pixel-footprint sampling (box filter, like a sensor pixel), so
  4 spp suffice.

Tabulation (:func:`tabulate`): ``bsdf.eval`` on every MERL cell centre in the
local frame (normal +z). Mitsuba's ``si.wi`` points to the sensor (our view
``wo``) and its ``wo`` argument to the light (our ``wi``); ``eval`` returns
``f * cos(theta)`` of that argument, so the table is ``eval / wi_z`` in 1/sr.
Cells below the horizon are NaN, as in the ground-truth tables.
"""

from __future__ import annotations

import dataclasses
import pathlib
import time
import tomllib

import numpy as np

VARIANT = "llvm_ad_rgb"
MIN_LLVM = 17  # oldest LLVM whose x86 back end lowers llvm.minimum / llvm.maximum
# Starting point of the fit: mid values (Mitsuba's defaults are base 0.5,
# roughness 0.5, specular 0.5, metallic 0; metallic starts at 0.5 here so that
# neither the dielectric nor the metal branch is favoured).
INITIAL = {"base_color": (0.5, 0.5, 0.5), "roughness": 0.5, "metallic": 0.5,
           "specular": 0.5, "clearcoat": 0.25, "clearcoat_gloss": 0.5}
# Valid range of each fitted parameter (the plugin's documented [0, 1]);
# roughness is kept >= 0.01, where the plugin's GGX alpha = roughness^2 floors.
BOUNDS = {"base_color": (0.0, 1.0), "roughness": (0.01, 1.0), "metallic": (0.0, 1.0),
          "specular": (0.0, 1.0), "clearcoat": (0.0, 1.0), "clearcoat_gloss": (0.0, 1.0)}
BASIC = ("base_color", "roughness", "metallic", "specular")
WITH_CLEARCOAT = (*BASIC, "clearcoat", "clearcoat_gloss")
# Defaults of fit_principled and of the command line (the benchmark's set-up)
DEFAULT_KEYS = BASIC
DEFAULT_ITERATIONS = 150
DEFAULT_SPP = 4
DEFAULT_LR = 0.05


def _llvm_library() -> str | None:
    """The newest system libLLVM of version >= 17 (Dr.Jit 1.5 emits ``llvm.minimum``,
    which LLVM < 17 cannot compile for x86: 'Cannot select fminimum'), or None."""
    import glob
    import re

    found = []
    for path in glob.glob("/usr/lib/*/libLLVM*.so*") + glob.glob("/usr/lib/libLLVM*.so*"):
        m = re.search(r"libLLVM(?:-(\d+)\.so|\.so\.(\d+))", path)
        if m and int(m.group(1) or m.group(2)) >= MIN_LLVM:
            found.append((int(m.group(1) or m.group(2)), path))
    return max(found)[1] if found else None


def mitsuba():
    """``(mi, dr)`` with the CPU variant set; ImportError naming the install step.

    Dr.Jit's LLVM backend loads the system libLLVM. Unless ``DRJIT_LIBLLVM_PATH``
    is set, it is pointed at the newest libLLVM >= 17 (an older one aborts the
    process on the first kernel), and the absence of one is an ImportError.
    """
    import os

    if "DRJIT_LIBLLVM_PATH" not in os.environ:
        library = _llvm_library()
        if library is None:
            raise ImportError(f"Mitsuba's CPU backend needs libLLVM >= {MIN_LLVM} "
                              "(Debian 12: apt-get install libllvm19)")
        os.environ["DRJIT_LIBLLVM_PATH"] = library
    try:
        import drjit as dr
        import mitsuba as mi
    except ImportError as error:
        raise ImportError("Mitsuba 3 is a dev-only extra: .venv/bin/pip install -r "
                          "requirements-bench.txt") from error
    if mi.variant() != VARIANT:
        mi.set_variant(VARIANT)
    return mi, dr


# ----------------------------------------------------------------------------- capture
@dataclasses.dataclass
class Photo:
    """One lit photo of a capture.

    path: the EXR. rgb: (H, W, 3) float64 linear radiance, row 0 at the top.
    alpha: (H, W) float64 coverage if the file has an alpha channel, else None
    (used only by the silhouette check, never by the fit). camera: the
    ``core.capture.colmap.ColmapImage`` of the view. light: (3,) unit world direction
    towards the light. irradiance: (3,) W/m^2 on a surface facing the light.
    """

    path: pathlib.Path
    rgb: np.ndarray
    alpha: np.ndarray | None
    camera: object
    light: np.ndarray
    irradiance: np.ndarray


@dataclasses.dataclass
class Capture:
    """A capture folder's scan (``mesh``, a .ply path) and lit photos."""

    folder: pathlib.Path
    mesh: pathlib.Path
    photos: list


def _read_exr(path) -> tuple[np.ndarray, np.ndarray | None]:
    """(H, W, 3) float64 colour and the (H, W) alpha (None without an A channel) of
    a photo, through the product's EXR reader (channels in the file's order)."""
    from brdf_reconstruct.core.capture import photo_io

    channels = photo_io.read_multilayer_exr(path)
    planes = list(channels.values())
    colour = planes[:3] if len(planes) >= 3 else planes[:1] * 3
    rgb = np.stack(colour, axis=-1).astype(np.float64)
    alpha = channels["A"].astype(np.float64) if "A" in channels else None
    return rgb, alpha


def read_capture(folder) -> Capture:
    """Read ``job.toml`` of a capture folder: the mesh, the COLMAP cameras and the
    photos with their light (``light = [x, y, z]`` entries only)."""
    from brdf_reconstruct.core.capture import colmap

    folder = pathlib.Path(folder).resolve()
    job = tomllib.loads((folder / "job.toml").read_text())
    model = colmap.read_model(folder / job.get("colmap", "sparse/0"))
    by_name = {im.name: im for im in model.images}
    by_stem = {pathlib.Path(im.name).stem: im for im in model.images}
    photos = []
    for entry in job["photo"]:
        camera = by_name.get(entry["camera"]) or by_stem.get(pathlib.Path(entry["camera"]).stem)
        if camera is None:
            raise ValueError(f"no COLMAP image named {entry['camera']}")
        light = entry.get("light")
        if not (isinstance(light, list) and len(light) == 3):
            raise ValueError("the Mitsuba peer supports only `light = [x, y, z]` photos")
        light = np.asarray(light, dtype=np.float64)
        irradiance = np.broadcast_to(np.asarray(entry.get("irradiance", 1.0), float), (3,))
        rgb, alpha = _read_exr(folder / entry["image"])
        if rgb.shape[:2] != (camera.height, camera.width):
            raise ValueError(f"{entry['image']} is not {camera.width}x{camera.height} pixels")
        photos.append(Photo(folder / entry["image"], rgb, alpha, camera,
                            light / np.linalg.norm(light), irradiance.copy()))
    return Capture(folder, (folder / job["mesh"]).resolve(), photos)


# ----------------------------------------------------------------------------- scene
def sensor_to_world(camera) -> np.ndarray:
    """(4, 4) Mitsuba sensor ``to_world`` (sensor x left, y up, z forward) of a
    COLMAP camera (x right, y down, z forward; ``X_cam = R X + t``)."""
    R, t = camera.R_cam_from_world, camera.t_cam_from_world
    M = np.eye(4)
    M[:3, :3] = R.T @ np.diag([-1.0, -1.0, 1.0])
    M[:3, 3] = -R.T @ t
    return M


def sensor_dict(camera, spp: int) -> dict:
    """Mitsuba ``perspective`` sensor of a PINHOLE/SIMPLE_PINHOLE COLMAP camera.

    fov along x from fx; principal point offset as a fraction of the image size
    (checked against COLMAP rays by :func:`camera_check`); a box pixel filter,
    so a pixel averages radiance over its own footprint as a camera sensor does. fx != fy or lens
    distortion cannot be represented: ValueError.
    """
    mi, _ = mitsuba()
    if camera.distorted or abs(camera.fx - camera.fy) > 1e-6 * camera.fx:
        raise ValueError(f"{camera.name}: the Mitsuba sensor needs an undistorted pinhole "
                         "camera with square pixels")
    w, h = camera.width, camera.height
    return {
        "type": "perspective", "fov_axis": "x",
        "fov": float(np.degrees(2.0 * np.arctan(0.5 * w / camera.fx))),
        # Mitsuba's offsets move the image window: a principal point right of /
        # below the centre (cx > W/2, cy > H/2) is a negative offset
        # (tests/test_mitsuba_peer.py checks it with an off-centre camera)
        "principal_point_offset_x": float((0.5 * w - camera.cx) / w),
        "principal_point_offset_y": float((0.5 * h - camera.cy) / h),
        "to_world": mi.ScalarTransform4f(sensor_to_world(camera)),
        "film": {"type": "hdrfilm", "width": w, "height": h, "pixel_format": "rgb",
                 "rfilter": {"type": "box"}},
        "sampler": {"type": "independent", "sample_count": spp},
    }


def bsdf_dict(values: dict) -> dict:
    """Mitsuba ``principled`` BSDF of parameter ``values`` (names of :data:`INITIAL`)."""
    d = {"type": "principled",
         "base_color": {"type": "rgb", "value": [float(x) for x in values["base_color"]]}}
    for key in ("roughness", "metallic", "specular", "clearcoat", "clearcoat_gloss"):
        if key in values:
            d[key] = float(values[key])
    return d


def scene_dict(capture: Capture, values: dict, spp: int) -> dict:
    """The fitting scene: the scan with a principled BSDF of ``values``, one
    directional light, one sensor per photo (``sensor_0`` ...), ``prb`` direct only."""
    lights = {tuple(p.light) for p in capture.photos}
    irradiances = {tuple(p.irradiance) for p in capture.photos}
    if len(lights) != 1 or len(irradiances) != 1:
        raise ValueError("the Mitsuba peer supports photos under one common light")
    photo = capture.photos[0]
    scene = {
        "type": "scene",
        "integrator": {"type": "prb", "max_depth": 2},
        "light": {"type": "directional", "direction": [float(x) for x in -photo.light],
                  "irradiance": {"type": "rgb", "value": [float(x) for x in photo.irradiance]}},
        "scan": {"type": "ply", "filename": str(capture.mesh), "bsdf": bsdf_dict(values)},
    }
    for i, p in enumerate(capture.photos):
        scene[f"sensor_{i}"] = sensor_dict(p.camera, spp)
    return scene


# ----------------------------------------------------------------------------- checks
def _pixel_rays(sensor, px: np.ndarray, width: int, height: int):
    """Mitsuba rays of ``sensor`` through pixel positions ``px`` (N, 2) (continuous,
    COLMAP convention: x right, y down, [0, W] x [0, H])."""
    mi, _ = mitsuba()
    n = len(px)
    pos = mi.Point2f((px[:, 0] / width).astype(np.float32), (px[:, 1] / height).astype(np.float32))
    ray, _ = sensor.sample_ray(time=0.0, sample1=mi.Float(np.zeros(n, np.float32)),
                               sample2=pos, sample3=mi.Point2f(0.5, 0.5))
    return ray


def silhouette(scene, sensor, camera) -> np.ndarray:
    """(H, W) bool: pixels whose centre ray through ``sensor`` hits the scene."""
    h, w = camera.height, camera.width
    ys, xs = np.mgrid[0:h, 0:w]
    px = np.stack([xs.ravel() + 0.5, ys.ravel() + 0.5], axis=1)
    hit = scene.ray_intersect(_pixel_rays(sensor, px, w, h)).is_valid()
    return np.asarray(hit, dtype=bool).reshape(h, w)


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sum(a & b) / max(1, np.sum(a | b)))


def camera_check(scene, capture: Capture) -> dict:
    """Frame and intrinsics check of every sensor.

    max_ray_angle_deg: largest angle between Mitsuba's ray through a pixel and
    COLMAP's back-projection ``R^T K^-1 (x, y, 1)`` of it, over a 9 x 7 grid of
    pixel positions of every camera; max_ray_centre_distance: the largest
    distance of the COLMAP camera centre from those rays' lines (world units).
    iou_alpha: per photo, IoU of the scan's traced silhouette (pixel centres)
    with the photo's coverage (alpha > 0.5); iou_nonblack: the same with the
    photo's non-black pixels (lower by construction: shadowed and unlit parts
    of the object are black too); iou_mirrored: the alpha IoU with the
    silhouette mirrored left-right, what a wrong x axis would give.
    """
    sensors = scene.sensors()
    angles, offsets, iou_a, iou_nb, iou_m = [], [], [], [], []
    for sensor, photo in zip(sensors, capture.photos, strict=True):
        cam = photo.camera
        gx, gy = np.meshgrid(np.linspace(0.0, cam.width, 9), np.linspace(0.0, cam.height, 7))
        px = np.stack([gx.ravel(), gy.ravel()], axis=1)
        ray = _pixel_rays(sensor, px, cam.width, cam.height)
        d_mi = np.asarray(ray.d, dtype=np.float64).reshape(3, -1).T
        d_mi /= np.linalg.norm(d_mi, axis=1, keepdims=True)
        o_mi = np.asarray(ray.o, dtype=np.float64).reshape(3, -1).T
        k_inv = np.stack([(px[:, 0] - cam.cx) / cam.fx, (px[:, 1] - cam.cy) / cam.fy,
                          np.ones(len(px))], axis=1)
        d_cm = k_inv @ cam.R_cam_from_world  # rows: R^T k
        d_cm /= np.linalg.norm(d_cm, axis=1, keepdims=True)
        cos = np.clip(np.sum(d_mi * d_cm, axis=1), -1.0, 1.0)
        angles.append(float(np.degrees(np.arccos(cos)).max()))
        # distance of the camera centre from each ray's line (Mitsuba starts the
        # rays on the near plane, so the origins themselves are not the centre)
        offsets.append(float(np.linalg.norm(np.cross(cam.centre[None, :] - o_mi, d_mi),
                                            axis=1).max()))
        mask = silhouette(scene, sensor, cam)
        nonblack = photo.rgb.max(axis=-1) > 0.0
        iou_nb.append(_iou(mask, nonblack))
        if photo.alpha is not None:
            covered = photo.alpha > 0.5
            iou_a.append(_iou(mask, covered))
            iou_m.append(_iou(mask[:, ::-1], covered))
    return {"max_ray_angle_deg": max(angles), "max_ray_centre_distance": max(offsets),
            "iou_alpha": iou_a, "iou_nonblack": iou_nb, "iou_mirrored": iou_m}


def check_irradiance(albedo: float = 0.5, incidence_deg: float = 60.0, spp: int = 4) -> dict:
    """Radiance of a Lambertian plane (``diffuse``, reflectance ``albedo``) under a
    ``directional`` emitter of irradiance 1 at ``incidence_deg`` from its normal,
    rendered with the fit's integrator, against ``albedo cos(incidence) / pi``."""
    mi, _ = mitsuba()
    a = np.radians(incidence_deg)
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "prb", "max_depth": 2},
        "light": {"type": "directional", "direction": [-np.sin(a), 0.0, -np.cos(a)],
                  "irradiance": {"type": "rgb", "value": 1.0}},
        "plane": {"type": "rectangle", "bsdf": {"type": "diffuse", "reflectance":
                                                {"type": "rgb", "value": albedo}}},
        "sensor": {"type": "perspective", "fov": 20.0,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0.3, 0.2, 3.0],
                                                              target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 16, "height": 16,
                            "pixel_format": "rgb"}},
    })
    image = np.asarray(mi.render(scene, spp=spp), dtype=np.float64)
    expected = albedo * np.cos(a) / np.pi
    return {"expected": expected, "mean": float(image.mean()),
            "max_rel_error": float(np.abs(image / expected - 1.0).max())}


# ----------------------------------------------------------------------------- tabulation
def eval_local(bsdf, light: np.ndarray, view: np.ndarray) -> np.ndarray:
    """BRDF values rho (N, 3) in 1/sr of a Mitsuba BSDF at local-frame (normal +z)
    light and view directions (N, 3) (both above the horizon), float64 from
    Mitsuba's float32 evaluation."""
    mi, dr = mitsuba()
    n = len(light)
    with dr.suspend_grad():
        si = dr.zeros(mi.SurfaceInteraction3f, n)
        si.sh_frame = mi.Frame3f(mi.Vector3f(0.0, 0.0, 1.0))
        si.n = mi.Normal3f(0.0, 0.0, 1.0)
        si.wi = mi.Vector3f(*(view.T.astype(np.float32)))  # Mitsuba's wi: towards the sensor
        wo = mi.Vector3f(*(light.T.astype(np.float32)))  # ... its wo: towards the light
        value = bsdf.eval(mi.BSDFContext(), si, wo)  # f(wi, wo) * cos(theta_wo)
        out = np.asarray(value, dtype=np.float64).reshape(3, -1).T
    return out / light[:, 2:3]


def tabulate(bsdf, chunk: int = 1 << 19) -> np.ndarray:
    """(3, 90, 90, 180) float64 table in 1/sr of a Mitsuba BSDF at the MERL cell
    centres (``merl.cell_directions``), NaN below the horizon."""
    from brdf_reconstruct.core.brdf import merl

    wi, wo = merl.cell_directions()
    valid = np.flatnonzero(merl.valid_cells())
    flat = np.full((merl.N_CELLS, 3), np.nan)
    for start in range(0, len(valid), chunk):  # chunks of ~0.5 M cells bound the memory
        idx = valid[start:start + chunk]
        flat[idx] = eval_local(bsdf, wi[idx], wo[idx])
    return np.ascontiguousarray(flat.T).reshape(3, *merl.SHAPE)


def check_tabulation(values: dict | None = None) -> dict:
    """Two checks of :func:`tabulate`.

    diffuse_max_rel_error: Mitsuba's ``diffuse`` BSDF (reflectance 0.2, 0.5, 0.8)
    tabulated against ``reflectance / pi`` over all valid cells (checks the
    wi/wo roles and the cosine division). sphere_rel_rmse: a principled BSDF of
    ``values`` (default a glossy part-metal) rendered on the metric's test
    spheres (``render.render_sphere``, the three ``metrics.SPHERE_LIGHTS``) from
    its table, against the same spheres shaded by ``bsdf.eval`` at each pixel's
    exact directions: the table's own quantisation error, with the metric's
    nearest-cell lookup and with trilinear interpolation between cell centres.
    """
    from brdf_reconstruct.core.brdf import merl, metrics, render

    mi, _ = mitsuba()
    albedo = np.array([0.2, 0.5, 0.8])
    diffuse = mi.load_dict({"type": "diffuse",
                            "reflectance": {"type": "rgb", "value": albedo.tolist()}})
    table = tabulate(diffuse)
    valid = merl.valid_cells()
    rho = table.reshape(3, -1)[:, valid]
    diffuse_err = float(np.abs(rho / (albedo[:, None] / np.pi) - 1.0).max())
    values = values or {"base_color": (0.8, 0.5, 0.2), "roughness": 0.3, "metallic": 0.5,
                        "specular": 0.5}
    principled = mi.load_dict(bsdf_dict(values))
    table = tabulate(principled)
    normals, mask = render.sphere_normals(96)
    n = normals[mask]
    view = np.array([0.0, 0.0, 1.0])
    from_table = {"nearest": [], "trilinear": []}
    direct = []
    for light in metrics.SPHERE_LIGHTS:
        for interpolation, images in from_table.items():
            images.append(render.render_sphere(table, light, interpolation=interpolation)[mask])
        lit = (n @ light > 0.0) & (n[:, 2] > 0.0)
        shaded = np.zeros((len(n), 3))
        wl = merl.to_local(n[lit], np.broadcast_to(light, n[lit].shape))
        wv = merl.to_local(n[lit], np.broadcast_to(view, n[lit].shape))
        shaded[lit] = eval_local(principled, wl, wv) * (n[lit] @ light)[:, None]
        direct.append(shaded)
    return {"diffuse_max_rel_error": diffuse_err,
            "sphere_rel_rmse": {k: metrics.relative_rmse(np.stack(v), np.stack(direct))
                                for k, v in from_table.items()},
            "principled": {k: (list(v) if isinstance(v, tuple) else v)
                           for k, v in values.items()}}


# ----------------------------------------------------------------------------- fit
def _erode(mask: np.ndarray) -> np.ndarray:
    from scipy import ndimage

    return ndimage.binary_erosion(mask, iterations=1)


def photo_loss(capture_folder, values: dict, spp: int = 16, seed: int = 1) -> float:
    """The fit's loss (mean squared radiance error over the eroded scan
    silhouettes of all lit photos, (W/(m^2 sr))^2) of a principled BSDF of
    ``values``, rendered without derivatives: to probe the loss landscape, e.g.
    whether the optimiser stopped short of a better point."""
    mi, _ = mitsuba()
    capture = read_capture(capture_folder)
    scene = mi.load_dict(scene_dict(capture, values, spp))
    total, count = 0.0, 0
    for sensor, photo in zip(scene.sensors(), capture.photos, strict=True):
        mask = _erode(silhouette(scene, sensor, photo.camera))
        image = np.asarray(mi.render(scene, sensor=sensor, spp=spp, seed=seed), np.float64)
        total += float(np.sum((image - photo.rgb)[mask] ** 2))
        count += 3 * int(mask.sum())
    return total / count


def learning_rate(step: int, iterations: int, lr: float) -> float:
    """Adam's step size at ``step``: ``lr`` for the first 60 % of the steps, then
    decaying exponentially to ``lr / 10`` at the last one, so that the parameters
    settle instead of jittering at the noise level of the gradients."""
    start = 0.6 * iterations
    return lr * 0.1 ** (max(0.0, step - start) / max(1.0, iterations - start))


def fit_principled(capture_folder, iterations: int = DEFAULT_ITERATIONS,
                   spp: int = DEFAULT_SPP, seed: int = 0, lr: float = DEFAULT_LR,
                   keys=DEFAULT_KEYS, log_every: int = 10, progress=None) -> dict:
    """Fit a Principled BSDF to a capture's lit photos by inverse rendering.

    capture_folder: a folder holding ``job.toml``, ``scan.ply``, ``sparse/0`` and
    the photos (``testkit/capture.py``). iterations: Adam steps, each rendering
    every lit view at ``spp`` samples per pixel (a new sampler seed for every
    render, derived from ``seed``).
    lr: Adam's learning rate (parameters live in [0, 1]). keys: the fitted
    parameters (:data:`BASIC` or :data:`WITH_CLEARCOAT`). log_every: the loss is
    recorded every that many steps. progress: optional callable(step, loss).

    Returns a dict: ``params`` (fitted values), ``table`` ((3, 90, 90, 180) 1/sr,
    NaN below the horizon), ``seconds`` (``scene`` build incl. the checks,
    ``optimise``, ``tabulate``, ``total``), ``loss`` (final mean squared error
    of the radiance over the masked pixels, (W/(m^2 sr))^2), ``rel_rmse`` (its
    root over the photos' RMS there), ``loss_curve`` (``[step, loss]`` every
    ``log_every`` steps), ``camera_check`` (:func:`camera_check`), ``settings``.
    """
    mi, dr = mitsuba()
    t0 = time.perf_counter()
    capture = read_capture(capture_folder)
    values = {k: INITIAL[k] for k in keys}
    scene = mi.load_dict(scene_dict(capture, values, spp))
    check = camera_check(scene, capture)
    sensors = scene.sensors()
    masks, targets, weights = [], [], []
    for sensor, photo in zip(sensors, capture.photos, strict=True):
        mask = _erode(silhouette(scene, sensor, photo.camera))
        masks.append(mi.TensorXf(np.repeat(mask[..., None], 3, axis=-1).astype(np.float32)))
        targets.append(mi.TensorXf(photo.rgb.astype(np.float32)))
        weights.append(mask)
    n_values = 3.0 * sum(float(m.sum()) for m in weights)
    target_ms = sum(float(np.sum(p.rgb[m] ** 2)) for p, m in
                    zip(capture.photos, weights, strict=True)) / n_values
    params = mi.traverse(scene)
    names = {k: (f"scan.bsdf.{k}" if k == "specular" else f"scan.bsdf.{k}.value") for k in keys}
    opt = mi.ad.Adam(lr=lr)
    for name in names.values():
        opt[name] = params[name]
    params.update(opt)
    t1 = time.perf_counter()
    curve = []
    loss_value = float("nan")
    for step in range(iterations + 1):
        total = 0.0
        for i, sensor in enumerate(sensors):
            image = mi.render(scene, params, sensor=sensor, spp=spp,
                              seed=seed * 100003 + step * len(sensors) + i)
            residual = (image - targets[i]) * masks[i]
            loss = dr.sum(dr.square(residual), axis=None) / n_values
            if step < iterations:
                dr.backward(loss)
            total += float(loss.array[0])
        loss_value = total
        if step % log_every == 0 or step == iterations:
            curve.append([step, loss_value])
            if progress is not None:
                progress(step, loss_value)
        if step == iterations:  # the last pass only measures the final loss
            break
        opt.set_learning_rate(learning_rate(step + 1, iterations, lr))
        opt.step()
        for k, name in names.items():
            lo, hi = BOUNDS[k]
            opt[name] = dr.clip(opt[name], lo, hi)
        params.update(opt)
    t2 = time.perf_counter()
    fitted = {}
    for k, name in names.items():
        v = np.asarray(params[name], dtype=np.float64).ravel()
        fitted[k] = v.tolist() if k == "base_color" else float(v[0])
    table = tabulate(mi.load_dict(bsdf_dict(fitted)))
    t3 = time.perf_counter()
    return {
        "params": fitted, "table": table,
        "seconds": {"scene": t1 - t0, "optimise": t2 - t1, "tabulate": t3 - t2,
                    "total": t3 - t0},
        "loss": loss_value, "rel_rmse": float(np.sqrt(loss_value / target_ms)),
        "loss_curve": curve, "camera_check": check,
        "settings": {"variant": VARIANT, "mitsuba": mi.__version__, "integrator": "prb",
                     "max_depth": 2, "iterations": iterations, "spp": spp, "lr": lr,
                     "seed": seed, "optimizer": "mi.ad.Adam", "keys": list(keys),
                     "initial": {k: INITIAL[k] for k in keys},
                     "masked_pixels": [int(m.sum()) for m in weights]},
    }


def main(argv=None) -> int:
    """``python -m testkit.mitsuba_peer CAPTURE``: fit a capture, score it against its
    ``truth.binary`` if there is one, print the summary; ``--out`` writes the
    table (MERL .binary), ``--json`` the summary."""
    import argparse
    import json

    from brdf_reconstruct.core.brdf import merl, metrics

    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument("capture", help="folder with job.toml, scan.ply, sparse/0, photos")
    parser.add_argument("--iterations", type=int, default=DEFAULT_ITERATIONS)
    parser.add_argument("--spp", type=int, default=DEFAULT_SPP)
    parser.add_argument("--lr", type=float, default=DEFAULT_LR)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--keys", choices=("basic", "clearcoat"),
                        default="clearcoat" if DEFAULT_KEYS == WITH_CLEARCOAT else "basic",
                        help="fitted parameters: basic = base_color, roughness, metallic, "
                             "specular; clearcoat = also clearcoat and clearcoat_gloss")
    parser.add_argument("--out", help="write the fitted table here (.binary)")
    parser.add_argument("--json", help="write the summary here")
    parser.add_argument("--checks", action="store_true", help="also run the convention checks")
    parser.add_argument("--quiet", action="store_true")
    args = parser.parse_args(argv)
    summary = {}
    if args.checks:
        summary["checks"] = {"irradiance": check_irradiance(), "tabulation": check_tabulation()}
    progress = None if args.quiet else (
        lambda s, v: print(f"  step {s:4d} loss {v:.6g}", flush=True))
    result = fit_principled(args.capture, iterations=args.iterations, spp=args.spp,
                            lr=args.lr, seed=args.seed,
                            keys=WITH_CLEARCOAT if args.keys == "clearcoat" else BASIC,
                            progress=progress)
    table = result.pop("table")
    summary.update(result)
    truth_path = pathlib.Path(args.capture) / "truth.binary"
    if truth_path.is_file():
        truth = merl.read(truth_path)
        summary["sphere_error"] = metrics.sphere_error(table, truth)
        summary["brdf_log_rmse"] = metrics.brdf_log_rmse(table, truth)
    if args.out:
        merl.write(args.out, table)
    text = json.dumps(summary, indent=1)
    if args.json:
        pathlib.Path(args.json).write_text(text)
    if not args.quiet:
        print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
