"""Cameras from a COLMAP model, and their conversion to Blender's camera conventions.

A COLMAP sparse model is a folder holding ``cameras``, ``images`` and
``points3D`` as ``.bin`` or ``.txt`` (COLMAP >= 3.12 also writes ``rigs`` and
``frames``, which are optional here). It is read through ``pycolmap``.

Frames and units:
- World: the model's own frame and (arbitrary) length unit; kept as is, so a
  Blender import shares it (Blender is z-up, COLMAP worlds usually are not).
- COLMAP camera: x right, y down, z forward (the viewing direction).
  ``R_cam_from_world`` (3, 3) and ``t`` (3,) map a world point X to
  ``X_cam = R X + t``; the camera centre is ``C = -R^T t``.
- Blender camera: x right, y up, looking down -z. Its ``matrix_world`` is the
  COLMAP world-from-camera with the y and z axes negated.
- Pixels (COLMAP): continuous (x, y), x to the right, y down, the image
  covering [0, W] x [0, H], so pixel (0, 0) has its centre at (0.5, 0.5).
  Blender's camera frame covers the same [0, W] x [0, H] (``u * W``,
  ``(1 - v) * H`` for ``world_to_camera_view``'s (u, v)), so the principal
  point needs no half-pixel shift.

Blender's projection (BKE_camera_params_compute_viewplane, Blender 4.2-5.0),
for render size W x H pixels, pixel aspect (ax, ay), ycor = ay / ax:
- The sensor dimension in use is ``sensor_height`` if ``sensor_fit`` is
  VERTICAL, else ``sensor_width``. It spans the image width for a horizontal
  fit and the image height for a vertical one (AUTO picks horizontal when
  ``W * ax >= H * ay``).
- Horizontal fit: fx = lens * W / sensor_width; vertical fit:
  fy = lens * H / sensor_height. Always fx / fy = ycor = ay / ax: a pixel is
  ycor times as tall as it is wide, which is how fx != fy is represented.
- Lens shift is in units of the fitted image dimension measured in
  width-pixels (W for a horizontal fit, ycor * H for a vertical one). A
  positive shift_x moves the view right (the optical axis lands left of the
  centre); a positive shift_y moves it up.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

SENSOR_SIZE_MM = 36.0
"""Width of the fitted (larger) sensor dimension given to imported cameras, mm."""

_MODEL_FILES = ("cameras", "images", "points3D")
_MAX_PIXEL_ASPECT = 200.0  # Blender's hard limit on pixel_aspect_x / _y


@dataclass(frozen=True)
class ColmapImage:
    """One registered image of a COLMAP model.

    name: the image's path relative to the COLMAP image folder, exactly as in
        the model (may contain '/').
    width, height: image size in pixels.
    fx, fy, cx, cy: focal lengths and principal point, pixels (COLMAP pixel
        convention, see the module docstring).
    camera_model: COLMAP model name, e.g. "PINHOLE", "OPENCV".
    distorted: True if the model is not a plain pinhole projection (fisheye
        models, or non-zero distortion parameters). Blender cameras are
        pinholes, so such images need undistorting before use.
    R_cam_from_world: (3, 3) float64 rotation, world to COLMAP camera.
    t_cam_from_world: (3,) float64 translation, world units.
    point3D_ids: (M,) int64 ids of the 3D points this image observes, or
        None if observations were not read.
    points2D: (M, 2) float64 pixel positions of those observations, or None.
    params: the camera model's parameters in COLMAP's order (e.g. OPENCV: fx,
        fy, cx, cy, k1, k2, p1, p2; pixels for focal lengths and principal
        point, distortion coefficients on normalized coordinates), as read
        from the model; what ``core.undistort`` needs. Empty if the record
        was made by hand without them.
    """

    image_id: int
    name: str
    camera_id: int
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    camera_model: str
    distorted: bool
    R_cam_from_world: np.ndarray
    t_cam_from_world: np.ndarray
    point3D_ids: np.ndarray | None = None
    points2D: np.ndarray | None = None
    params: tuple[float, ...] = ()

    @property
    def centre(self) -> np.ndarray:
        """(3,) camera centre in world coordinates."""
        return camera_centre(self.R_cam_from_world, self.t_cam_from_world)


@dataclass(frozen=True)
class ColmapModel:
    """A COLMAP model: registered images (sorted by name) and the sparse points.

    point_ids: (N,) int64; xyz: (N, 3) float64 world positions; rgb: (N, 3)
    uint8 colours as stored by COLMAP (sRGB).
    """

    path: str
    images: tuple[ColmapImage, ...]
    point_ids: np.ndarray
    xyz: np.ndarray
    rgb: np.ndarray


@dataclass(frozen=True)
class BlenderIntrinsics:
    """Blender camera data and render settings reproducing a pinhole camera.

    lens, sensor_width, sensor_height: mm. sensor_fit: 'HORIZONTAL' or
    'VERTICAL'. shift_x, shift_y: Blender lens shift (fractions of the fitted
    dimension). pixel_aspect_x, pixel_aspect_y: scene render pixel aspect,
    each >= 1 (the smaller is 1). resolution_x, resolution_y: render size in
    pixels at 100 %.
    """

    lens: float
    sensor_width: float
    sensor_height: float
    sensor_fit: str
    shift_x: float
    shift_y: float
    pixel_aspect_x: float
    pixel_aspect_y: float
    resolution_x: int
    resolution_y: int


# --------------------------------------------------------------------------- reading


def find_model_files(model_dir) -> str | None:
    """The extension ('.bin' or '.txt') of the complete model in `model_dir`, or None.

    Binary wins when both are complete, as in COLMAP itself.
    """
    for ext in (".bin", ".txt"):
        if all(os.path.isfile(os.path.join(model_dir, f + ext)) for f in _MODEL_FILES):
            return ext
    return None


def read_model(model_dir, *, observations: bool = False) -> ColmapModel:
    """Read a COLMAP sparse model folder (binary or text) through pycolmap.

    model_dir: the folder holding cameras/images/points3D (.bin or .txt), e.g.
        ``sparse/0``. A path to a file inside it is accepted too.
    observations: also read each image's 2D observations of 3D points
        (``ColmapImage.point3D_ids`` and ``points2D``); slower on big models.

    Only registered images (with a pose) are returned, sorted by name.
    Raises ValueError with one sentence for a missing folder, a folder with no
    model, an unreadable model, a model with no registered image, or a camera
    model that is not perspective (e.g. EQUIRECTANGULAR).
    """
    import pycolmap  # bundled wheel; imported here so the conversions need only numpy

    model_dir = os.path.abspath(os.path.expanduser(os.fspath(model_dir)))
    if os.path.isfile(model_dir):
        model_dir = os.path.dirname(model_dir)
    if not os.path.isdir(model_dir):
        raise ValueError(f"COLMAP model folder not found: {model_dir}")
    if find_model_files(model_dir) is None:
        hint = ""
        sub = os.path.join(model_dir, "0")
        if os.path.isdir(sub) and find_model_files(sub) is not None:
            hint = f" (did you mean {sub}?)"
        raise ValueError(
            f"No COLMAP model (cameras, images and points3D as .bin or .txt) in {model_dir}{hint}"
        )
    try:
        rec = pycolmap.Reconstruction(model_dir)
    except Exception as exc:  # pycolmap raises ValueError/RuntimeError with a C++ location
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ValueError(f"Could not read the COLMAP model in {model_dir}: {reason}") from exc

    images = []
    for image_id in rec.reg_image_ids():
        image = rec.image(image_id)
        if not image.has_pose:
            continue
        images.append(_image_record(rec, image, observations))
    if not images:
        raise ValueError(f"The COLMAP model in {model_dir} has no registered images")
    images.sort(key=lambda im: (im.name, im.image_id))

    points = rec.points3D
    n = len(points)
    point_ids = np.empty(n, dtype=np.int64)
    xyz = np.empty((n, 3), dtype=np.float64)
    rgb = np.empty((n, 3), dtype=np.uint8)
    for i, (point_id, point) in enumerate(points.items()):
        point_ids[i] = point_id
        xyz[i] = point.xyz
        rgb[i] = point.color
    return ColmapModel(model_dir, tuple(images), point_ids, xyz, rgb)


def _image_record(rec, image, observations: bool) -> ColmapImage:
    camera = rec.camera(image.camera_id)
    model = camera.model.name
    if not camera.is_perspective():
        raise ValueError(
            f"Image {image.name!r} uses the {model} camera model, which is not a "
            "perspective camera and cannot become a Blender camera"
        )
    params = tuple(float(p) for p in camera.params)
    fx, fy, cx, cy = _pinhole_of(camera)
    distorted = _distorted(camera)

    pose = np.asarray(image.cam_from_world().matrix(), dtype=np.float64)  # (3, 4) [R | t]
    ids = xy = None
    if observations:
        obs = image.get_observation_points2D()
        ids = np.fromiter((p.point3D_id for p in obs), dtype=np.int64, count=len(obs))
        xy = np.array([p.xy for p in obs], dtype=np.float64).reshape(-1, 2)
    return ColmapImage(
        image_id=int(image.image_id),
        name=str(image.name),
        camera_id=int(image.camera_id),
        width=int(camera.width),
        height=int(camera.height),
        fx=float(fx),
        fy=float(fy),
        cx=float(cx),
        cy=float(cy),
        camera_model=model,
        distorted=bool(distorted),
        R_cam_from_world=pose[:, :3].copy(),
        t_cam_from_world=pose[:, 3].copy(),
        point3D_ids=ids,
        points2D=xy,
        params=params,
    )


# --------------------------------------------------------------------------- camera models


def pycolmap_camera(model: str, params, width: int = 1, height: int = 1):
    """A ``pycolmap.Camera`` of a COLMAP model name, its parameters and image size.

    model: COLMAP model name, e.g. "OPENCV". params: the model's parameters in
    COLMAP's order (sequence of floats). width, height: image size, pixels.
    Raises ValueError (one sentence) for an unknown model or a parameter
    count that does not fit it.
    """
    import pycolmap

    name = str(model)
    if name not in pycolmap.CameraModelId.__members__ or name == "INVALID":
        raise ValueError(f"Unknown COLMAP camera model {name!r}")
    w, h = _check_size(width, height)
    values = np.asarray(params, dtype=np.float64).reshape(-1)
    camera = pycolmap.Camera.create_from_model_name(0, name, 1.0, w, h)
    if values.size != len(camera.params):
        raise ValueError(
            f"The {name} camera model takes {len(camera.params)} parameters "
            f"({camera.params_info}), got {values.size}"
        )
    if not np.isfinite(values).all():
        raise ValueError(f"The {name} camera parameters must be finite, got {values.tolist()}")
    camera.params = values
    return camera


def pinhole_params(model: str, params) -> tuple[float, float, float, float]:
    """(fx, fy, cx, cy) in pixels of any COLMAP camera model's parameters.

    The focal lengths and principal point the model's params hold (one
    shared focal length gives fx = fy), i.e. the pinhole that
    ``blender_intrinsics`` turns into a Blender camera and that
    ``core.undistort`` resamples photos to. COLMAP pixel convention.
    """
    return _pinhole_of(pycolmap_camera(model, params))


def is_distorted(model: str, params) -> bool:
    """True if a COLMAP camera is not a plain pinhole projection.

    The rule ``ColmapImage.distorted`` uses: fisheye (and other non-pinhole)
    models always, pinhole-type models when a distortion parameter is
    non-zero (beyond pycolmap's 1e-8 tolerance).
    """
    return _distorted(pycolmap_camera(model, params))


def _pinhole_of(camera) -> tuple[float, float, float, float]:
    params = np.asarray(camera.params, dtype=np.float64)
    focal = params[list(camera.focal_length_idxs())]
    cx, cy = params[list(camera.principal_point_idxs())]
    fx, fy = (focal[0], focal[0]) if focal.size == 1 else (focal[0], focal[1])
    return float(fx), float(fy), float(cx), float(cy)


def _distorted(camera) -> bool:
    # Fisheye models are not pinholes even with zero coefficients.
    return bool(not camera.is_perspective_pinhole() or not camera.is_undistorted())


# --------------------------------------------------------------------------- conversions


def blender_intrinsics(
    fx, fy, cx, cy, width, height, *, sensor_size: float = SENSOR_SIZE_MM
) -> BlenderIntrinsics:
    """Blender camera settings reproducing a pinhole camera's intrinsics exactly.

    fx, fy: focal lengths, pixels (> 0). cx, cy: principal point, pixels, in
    COLMAP's convention (image spans [0, width] x [0, height], y down).
    width, height: image size, pixels. sensor_size: mm given to the fitted
    sensor dimension.

    The fit follows the displayed aspect (width * pixel_aspect_x against
    height * pixel_aspect_y): the larger side gets `sensor_size` mm and lens
    is derived from it; the other sensor dimension is set so that switching
    the fit would give the same projection. fx != fy becomes a non-square
    pixel aspect (a scene render setting in Blender, so every render from this
    camera must use it). Conventions: see the module docstring.
    """
    fx, fy, cx, cy = (float(v) for v in (fx, fy, cx, cy))
    for name, value in (("fx", fx), ("fy", fy)):
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a positive focal length in pixels, got {value}")
    for name, value in (("cx", cx), ("cy", cy)):
        if not np.isfinite(value):
            raise ValueError(f"{name} must be finite, got {value}")
    w, h = _check_size(width, height)
    if not sensor_size > 0:
        raise ValueError(f"sensor_size must be positive (mm), got {sensor_size}")
    if max(fx, fy) / min(fx, fy) > _MAX_PIXEL_ASPECT:
        raise ValueError(
            f"fx / fy = {fx / fy:.6g} is beyond Blender's pixel aspect range "
            f"(1 / {_MAX_PIXEL_ASPECT:g} to {_MAX_PIXEL_ASPECT:g})"
        )

    # fx / fy = ay / ax (module docstring); the smaller aspect is 1.
    ax, ay = (1.0, fx / fy) if fx >= fy else (fy / fx, 1.0)
    ycor = ay / ax
    if w * ax >= h * ay:
        fit = "HORIZONTAL"
        sensor_w = sensor_size
        sensor_h = sensor_size * (h * ay) / (w * ax)
        lens = fx * sensor_w / w
        viewfac = w
    else:
        fit = "VERTICAL"
        sensor_h = sensor_size
        sensor_w = sensor_size * (w * ax) / (h * ay)
        lens = fy * sensor_h / h
        viewfac = ycor * h
    shift_x = (0.5 * w - cx) / viewfac
    shift_y = ycor * (cy - 0.5 * h) / viewfac
    return BlenderIntrinsics(
        lens=lens,
        sensor_width=sensor_w,
        sensor_height=sensor_h,
        sensor_fit=fit,
        shift_x=shift_x,
        shift_y=shift_y,
        pixel_aspect_x=ax,
        pixel_aspect_y=ay,
        resolution_x=w,
        resolution_y=h,
    )


def pinhole_from_blender(intr: BlenderIntrinsics) -> tuple[float, float, float, float]:
    """Inverse of `blender_intrinsics`: (fx, fy, cx, cy) in pixels, COLMAP convention.

    Implements Blender's own viewplane rule (module docstring) for an
    explicit 'HORIZONTAL' or 'VERTICAL' fit, so it is also a reference model
    of what Blender will render.
    """
    w, h = _check_size(intr.resolution_x, intr.resolution_y)
    ax, ay = float(intr.pixel_aspect_x), float(intr.pixel_aspect_y)
    ycor = ay / ax
    if intr.sensor_fit == "HORIZONTAL":
        fx = intr.lens * w / intr.sensor_width
        viewfac = w
    elif intr.sensor_fit == "VERTICAL":
        fx = intr.lens * ycor * h / intr.sensor_height
        viewfac = ycor * h
    else:
        raise ValueError(f"sensor_fit must be 'HORIZONTAL' or 'VERTICAL', got {intr.sensor_fit!r}")
    fy = fx / ycor
    cx = 0.5 * w - intr.shift_x * viewfac
    cy = 0.5 * h + intr.shift_y * viewfac / ycor
    return fx, fy, cx, cy


def camera_centre(R_cam_from_world, t) -> np.ndarray:
    """(3,) camera centre in world coordinates, C = -R^T t.

    R_cam_from_world: (3, 3) rotation; t: (3,) translation (X_cam = R X + t).
    """
    R, t = _check_pose(R_cam_from_world, t)
    return -R.T @ t


def camera_to_world(R_cam_from_world, t) -> np.ndarray:
    """(4, 4) float64 Blender ``matrix_world`` of a camera with a COLMAP pose.

    R_cam_from_world: (3, 3) rotation, t: (3,) translation, with
    X_cam = R X + t in COLMAP's camera frame (x right, y down, z forward).
    The result maps Blender camera coordinates (x right, y up, looking down
    -z) to world coordinates: rotation R^T diag(1, -1, -1), translation the
    camera centre -R^T t. No scale.
    """
    R, t = _check_pose(R_cam_from_world, t)
    M = np.eye(4)
    M[:3, :3] = R.T @ np.diag([1.0, -1.0, -1.0])
    M[:3, 3] = -R.T @ t
    return M


def project_blender(matrix_world, intr: BlenderIntrinsics, xyz) -> np.ndarray:
    """Pixel positions of world points seen by a Blender camera (reference model).

    matrix_world: (4, 4) rigid Blender camera matrix; intr: its intrinsics;
    xyz: (N, 3) world points. Returns (N, 2) float64 pixels in COLMAP's
    convention (x right, y down, image over [0, W] x [0, H]), i.e. the same
    as ``u * W, (1 - v) * H`` from Blender's ``world_to_camera_view``.
    Points behind the camera get NaN.
    """
    M = np.asarray(matrix_world, dtype=np.float64)
    if M.shape != (4, 4):
        raise ValueError(f"matrix_world must be (4, 4), got {M.shape}")
    pts = np.asarray(xyz, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"xyz must be (N, 3), got {pts.shape}")
    fx, fy, cx, cy = pinhole_from_blender(intr)
    local = (pts - M[:3, 3]) @ M[:3, :3]  # rows: R^T (p - C) for orthonormal R
    depth = -local[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = cx + fx * local[:, 0] / depth
        v = cy - fy * local[:, 1] / depth
    out = np.stack([u, v], axis=1)
    out[~(depth > 0)] = np.nan
    return out


def view_scale(centres, xyz=None) -> float:
    """A characteristic length of the scene in world units (for clip and display sizes).

    centres: (K, 3) camera centres; xyz: optional (N, 3) sparse points.
    The median distance from the cameras to the median point (to the median
    camera centre without points). Falls back to 1.0 when degenerate.
    """
    c = np.asarray(centres, dtype=np.float64).reshape(-1, 3)
    pts = None if xyz is None else np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    if not len(c):
        return 1.0
    target = np.median(pts, axis=0) if pts is not None and len(pts) else np.median(c, axis=0)
    scale = float(np.median(np.linalg.norm(c - target, axis=1)))
    return scale if np.isfinite(scale) and scale > 0 else 1.0


def _check_size(width, height) -> tuple[int, int]:
    w, h = int(width), int(height)
    if w != width or w <= 0:
        raise ValueError(f"width must be a positive whole number of pixels, got {width}")
    if h != height or h <= 0:
        raise ValueError(f"height must be a positive whole number of pixels, got {height}")
    return w, h


def _check_pose(R, t) -> tuple[np.ndarray, np.ndarray]:
    R = np.asarray(R, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    if R.shape != (3, 3):
        raise ValueError(f"R_cam_from_world must be (3, 3), got {R.shape}")
    if t.shape != (3,):
        raise ValueError(f"t must have 3 elements, got {t.shape}")
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise ValueError("R_cam_from_world must be a rotation (orthonormal, det +1)")
    return R, t


# --------------------------------------------------------------------------- synthetic models


def look_at(centre, target, up=(0.0, 0.0, 1.0)) -> tuple[np.ndarray, np.ndarray]:
    """COLMAP pose (R_cam_from_world (3, 3), t (3,)) of a camera at `centre` facing `target`.

    centre, target: (3,) world points; up: (3,) world direction that appears
    up in the image (must not be parallel to the viewing direction).
    """
    c = np.asarray(centre, dtype=np.float64)
    z = np.asarray(target, dtype=np.float64) - c
    if not np.linalg.norm(z) > 0:
        raise ValueError("target must differ from centre")
    z /= np.linalg.norm(z)
    x = np.cross(z, np.asarray(up, dtype=np.float64))  # right = forward x up
    if not np.linalg.norm(x) > 1e-9:
        raise ValueError("up must not be parallel to the viewing direction")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    return R, -R @ c


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
        R, t = _check_pose(R, t)
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
