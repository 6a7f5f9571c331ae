"""Cameras from a COLMAP model, read through ``pycolmap``.

A COLMAP sparse model is a folder holding ``cameras``, ``images`` and
``points3D`` as ``.bin`` or ``.txt`` (COLMAP >= 3.12 also writes ``rigs`` and
``frames``, which are optional here). It is read through ``pycolmap``.
The model's world frame, its COLMAP camera frame and pixel convention are described
in :mod:`.cameras`, which converts them to Blender's camera conventions.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from .cameras import camera_centre, check_size

_MODEL_FILES = ("cameras", "images", "points3D")


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
        from the model; what ``core.capture.undistort`` needs. Empty if the record
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
    w, h = check_size(width, height)
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
    ``core.capture.undistort`` resamples photos to. COLMAP pixel convention.
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
