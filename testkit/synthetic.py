"""Synthetic scenes in numpy for tests and benchmarks: exact G-buffers, and a
"photogrammetry" version of them that is blunted and noisy, like the paper's
Fig. 3(c-d).

The object is a height field ``z = f(x, y)`` over ``[-1, 1]^2`` seen by an
orthographic camera looking down -z (image row 0 at +y): a dome with sharp
ridges and cones on it, so that a smoothed reconstruction has wrong normals
exactly where the curvature is high. Self-shadowing is ignored (visibility 1).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.ndimage import gaussian_filter

from brdf_reconstruct.core.brdf import render
from brdf_reconstruct.core.capture.cameras import check_pose

CAMERA_DISTANCE = 1e6  # orthographic camera emulated by a far camera centre on +z


@dataclasses.dataclass(frozen=True)
class GBuffer:
    """normal, position: (H, W, 3) world space; mask: (H, W) bool;
    camera_center: (3,) world space."""

    normal: np.ndarray
    position: np.ndarray
    mask: np.ndarray
    camera_center: np.ndarray


def height_field(resolution: int = 256) -> np.ndarray:
    """(H, W) heights of the test object on a grid over [-1, 1]^2 (row 0 at y = +1)."""
    c = (np.arange(resolution) + 0.5) / resolution * 2.0 - 1.0
    x, y = np.meshgrid(c, -c)
    r2 = x**2 + y**2
    z = 0.6 * np.sqrt(np.clip(1.2 - r2, 0.0, None))  # dome
    z += 0.12 * np.clip(1.0 - np.abs(x - 0.25) / 0.08, 0.0, None)  # sharp ridge
    z += 0.10 * np.clip(1.0 - np.abs(y + 0.35) / 0.06, 0.0, None)  # sharp ridge
    for cx, cy, h, w in ((-0.45, 0.4, 0.15, 0.15), (0.5, 0.5, 0.12, 0.12), (-0.2, -0.6, 0.1, 0.1)):
        z += h * np.clip(1.0 - np.hypot(x - cx, y - cy) / w, 0.0, None)  # cones
    return z


def gbuffer_from_heights(z: np.ndarray) -> GBuffer:
    """G-buffer of a height field on [-1, 1]^2 under the orthographic camera."""
    res = z.shape[0]
    step = 2.0 / res
    c = (np.arange(res) + 0.5) * step - 1.0
    x, y = np.meshgrid(c, -c)
    dz_dy_rows, dz_dx = np.gradient(z, step)
    dz_dy = -dz_dy_rows  # rows run towards -y
    normal = np.stack([-dz_dx, -dz_dy, np.ones_like(z)], axis=-1)
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    position = np.stack([x, y, z], axis=-1)
    mask = np.ones(z.shape, dtype=bool)
    return GBuffer(normal, position, mask, np.array([0.0, 0.0, CAMERA_DISTANCE]))


def blunted(z: np.ndarray, sigma_px: float = 3.0, noise: float = 0.0002,
            rng: np.random.Generator | int | None = 0) -> np.ndarray:
    """The "photogrammetry" heights: Gaussian-smoothed (edges blunted) plus noise."""
    rng = np.random.default_rng(rng)
    return gaussian_filter(z, sigma_px, mode="nearest") + rng.normal(0.0, noise, z.shape)


def photo(table: np.ndarray, truth: GBuffer, light: np.ndarray, irradiance=1.0,
          noise: float = 0.0, rng: np.random.Generator | int | None = 0) -> np.ndarray:
    """(H, W, 3) linear photo of the true geometry shaded by ``table`` under a distant
    light, with optional multiplicative Gaussian noise of relative level ``noise``."""
    light = np.asarray(light, dtype=np.float64) / np.linalg.norm(light)
    view = render.view_directions(truth.camera_center, truth.position[truth.mask])
    image = np.zeros(truth.mask.shape + (3,))
    image[truth.mask] = render.shade(table, truth.normal[truth.mask], light, view, irradiance)
    if noise:
        image *= 1.0 + np.random.default_rng(rng).normal(0.0, noise, image.shape)
    return np.clip(image, 0.0, None)


def normal_angle_error(a: GBuffer, b: GBuffer) -> np.ndarray:
    """(H, W) angle in radians between the normals of two G-buffers."""
    return np.arccos(np.clip(np.sum(a.normal * b.normal, axis=-1), -1.0, 1.0))


def height_field_uv(g: GBuffer) -> np.ndarray:
    """(H, W, 2) the height field's UV map at each pixel of a G-buffer: (x, y) over
    [-1, 1]^2 mapped to [0, 1]^2 (u right, v up, as Blender's)."""
    return np.stack([(g.position[..., 0] + 1.0) / 2.0, (g.position[..., 1] + 1.0) / 2.0],
                    axis=-1)


def patch_texture(shape=(24, 24), patch: int = 4, seed: int = 0) -> np.ndarray:
    """(height * width, 3) a relative albedo texture (mean 1 per channel): square
    patches of ``patch`` texels of random colour, times a 1-texel checker of 1 and
    0.6; at least 10:1 between its darkest and brightest texel (issue 16)."""
    height, width = shape
    rng = np.random.default_rng(seed)
    colours = rng.uniform(0.15, 1.6, size=(-(-height // patch), -(-width // patch), 3))
    tex = np.repeat(np.repeat(colours, patch, axis=0), patch, axis=1)[:height, :width]
    row, col = np.indices(shape)
    tex = tex * np.where((row + col) % 2 == 0, 1.0, 0.6)[..., None]
    tex = tex.reshape(-1, 3)
    return tex / tex.mean(axis=0)


def colour_tables(spec: dict) -> tuple[np.ndarray, np.ndarray]:
    """(colour part, rest), each (3, 90, 90, 180): an analytic material's table split
    into the part its texture scales (its Lambert or Oren-Nayar lobes, under its coat
    when it has one: the models are linear in that albedo) and the part it does not
    (its specular lobes and coat). The truth of the textured scenes: a texel of
    relative albedo a has the table ``rest + a * colour``."""
    import copy

    from brdf_reconstruct.core.brdf import database

    full = database.make_table(spec)
    plain = copy.deepcopy(spec)
    plain["lobes"] = [lobe for lobe in spec["lobes"] if lobe["type"] not in ("lambert",
                                                                                 "oren_nayar")]
    rest = (database.make_table(plain) if plain["lobes"] or "coat" in plain
            else np.zeros_like(full))
    return full - rest, rest


def textured_photo(colour: np.ndarray, rest: np.ndarray, texture: np.ndarray, shape,
                   truth: GBuffer, light: np.ndarray, irradiance=1.0, noise: float = 0.0,
                   rng: np.random.Generator | int | None = 0) -> np.ndarray:
    """(H, W, 3) linear photo of the true height field with the texture (relative
    albedo per texel, (height * width, 3), on :func:`height_field_uv`) scaling the
    colour part of the table (:func:`colour_tables`); otherwise as :func:`photo`."""
    from brdf_reconstruct.core.method import albedo

    light = np.asarray(light, dtype=np.float64) / np.linalg.norm(light)
    texel = albedo.texel_index(height_field_uv(truth)[truth.mask], shape)
    view = render.view_directions(truth.camera_center, truth.position[truth.mask])
    n = truth.normal[truth.mask]
    image = np.zeros(truth.mask.shape + (3,))
    image[truth.mask] = (render.shade(rest, n, light, view, irradiance)
                         + texture[texel] * render.shade(colour, n, light, view, irradiance))
    if noise:
        image *= 1.0 + np.random.default_rng(rng).normal(0.0, noise, image.shape)
    return np.clip(image, 0.0, None)


def textured_inputs(colour: np.ndarray, rest: np.ndarray, texture: np.ndarray, shape,
                    truth: GBuffer, scan: GBuffer, *, noise: float = 0.01, rng_base: int = 0,
                    with_uv: bool = True) -> list:
    """Three ``pipeline.PhotoInput``s of the textured height field: photos of the
    truth (:func:`textured_photo`, lights ``LIGHTS[0:3]``, photo i's noise seeded
    ``rng_base + i``) with the scan's G-buffers and UV map (None if not ``with_uv``)."""
    from brdf_reconstruct.core.method import pipeline

    uv = height_field_uv(scan) if with_uv else None
    region = np.zeros(truth.mask.shape, dtype=np.int64)
    inputs = []
    for i in (0, 1, 2):
        light = LIGHTS[i]
        photo = textured_photo(colour, rest, texture, shape, truth, light, noise=noise,
                               rng=rng_base + i)
        inputs.append(pipeline.PhotoInput(
            photo=photo, normal=scan.normal, position=scan.position,
            visibility=np.ones(truth.mask.shape), region=region,
            camera_center=scan.camera_center, light=light, name=f"photo{i}", uv=uv))
    return inputs


LIGHTS = np.array([[0.5, 0.3, 0.81], [-0.6, 0.2, 0.77], [0.1, -0.7, 0.71], [0.0, 0.0, 1.0]])


def synthetic_reconstruction(views, xyz, rgb=None):
    """A pycolmap.Reconstruction with the given cameras and points (for tests and demos).

    views: iterable of (name, camera_model, params, width, height,
        R_cam_from_world, t), one camera and one image per view; params in
        the model's COLMAP order (e.g. PINHOLE: fx, fy, cx, cy).
    xyz: (N, 3) world points. Each point is observed by every view that sees
        it in front of the camera and inside the image; the 2D observation is
        COLMAP's own projection (``Camera.img_from_cam``). Points seen by no
        view are kept without a track.
    rgb: optional (N, 3) uint8 point colours (default black).
    Write the result with ``.write(dir)`` (binary) or ``.write_text(dir)``.
    """
    import pycolmap

    pts = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    colours = np.zeros((len(pts), 3), np.uint8) if rgb is None else np.asarray(rgb, np.uint8)
    rec = pycolmap.Reconstruction()
    tracks = [[] for _ in range(len(pts))]
    for k, (name, model, params, width, height, R, t) in enumerate(views, start=1):
        camera = pycolmap.Camera.create_from_model_name(k, model, 1.0, int(width), int(height))
        camera.params = np.asarray(params, dtype=np.float64)
        rec.add_camera_with_trivial_rig(camera)
        R, t = check_pose(R, t)
        cam_pts = pts @ R.T + t
        uv = camera.img_from_cam(cam_pts, check_cheirality=False)
        seen = np.flatnonzero(
            (cam_pts[:, 2] > 0)
            & (uv[:, 0] >= 0)
            & (uv[:, 0] <= width)
            & (uv[:, 1] >= 0)
            & (uv[:, 1] <= height)
        )
        image = pycolmap.Image(
            name=name, keypoints=uv[seen].reshape(-1, 2), camera_id=k, image_id=k
        )
        pose = pycolmap.Rigid3d(pycolmap.Rotation3d(R), t)
        rec.add_image_with_trivial_frame(image, pose)
        for idx2d, j in enumerate(seen):
            tracks[j].append((k, idx2d))
    for j, track in enumerate(tracks):
        elements = [pycolmap.TrackElement(image_id, idx2d) for image_id, idx2d in track]
        # add_point3D also links each image's 2D point to the new 3D point
        rec.add_point3D(pts[j], pycolmap.Track(elements), colours[j])
    return rec
