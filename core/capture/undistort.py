"""Lens distortion: resampling photos of a distorted COLMAP camera to its pinhole.

``brdf_addon/colmap_import.py`` turns every COLMAP camera into a Blender
pinhole with the model's own fx, fy, cx, cy and image size, whatever the
model (SIMPLE_RADIAL, OPENCV, OPENCV_FISHEYE, ...). A lit photo taken through
a distorted lens only lines up with that pinhole after resampling: each
output pixel takes the photo's value where its pinhole ray lands in the
distorted image.

Conventions (as in ``core.capture.colmap``):
- Pixels: COLMAP's continuous (x, y), x right, y down, the image covering
  [0, W] x [0, H]; pixel (0, 0) has its centre at (0.5, 0.5), so array
  index (row, col) = (y - 0.5, x - 0.5).
- Output pixel centre (x, y) has the pinhole ray ((x - cx) / fx,
  (y - cy) / fy, 1) in the COLMAP camera frame (x right, y down, z forward);
  pycolmap's ``Camera.img_from_cam`` maps it to the distorted photo.
- Outside: an output pixel whose ray lands outside the photo's [0, W] x
  [0, H], behind a fisheye's field of view, or beyond the point where the
  distortion polynomial folds back (checked by undistorting the landing
  point again with ``cam_from_img``: a folded ray does not come back) is NaN
  in images and False in masks. Within the photo's outer half pixel the edge
  pixels are extended (interpolation clamps to them).
- Photo size: a photo may be the camera's size times a common factor s
  (e.g. 2 for photos at twice COLMAP's resolution); the intrinsics are
  scaled by s (fx, fy, cx, cy -> s fx, ..., s cy), the distortion
  coefficients (on normalized coordinates) are unchanged, and the output
  has the photo's size.

`is_distorted` and `pinhole_params` are ``core.capture.colmap``'s, re-exported.
pycolmap is imported on first use, through ``core.capture.colmap``.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from .colmap import is_distorted, pinhole_params, pycolmap_camera

__all__ = [
    "distorted_positions",
    "is_distorted",
    "pinhole_params",
    "undistort_image",
    "undistort_mask",
]

_BLOCK_PIXELS = 1 << 20  # output pixels mapped at once (bounds the temporary arrays)
_ROUND_TRIP_PX = 1e-2  # a ray that does not come back this close has folded


def distorted_positions(model: str, params, width: int, height: int, image_shape=None):
    """(H, W, 2) float64: where each output pixel centre lands in the distorted photo.

    model, params: the COLMAP camera model name and its parameters in
        COLMAP's order. width, height: the camera's image size, pixels.
    image_shape: the photo's (H, W) (a trailing channel count is ignored);
        default (height, width). It must be the camera size times a common
        factor, which scales the intrinsics.
    Returns COLMAP pixel positions (x, y) in the photo (see the module
    docstring), NaN where the pixel is outside (module docstring).
    """
    camera, (h, w) = _photo_camera(model, params, width, height, image_shape)
    out = np.empty((h, w, 2), dtype=np.float64)
    for rows, xy in _blocks(camera, h, w):
        out[rows] = xy.reshape(-1, w, 2)
    return out


def undistort_image(image, model: str, params, width: int, height: int, *, order: int = 1):
    """A photo of a distorted COLMAP camera resampled to the camera's pinhole.

    image: (H, W) or (H, W, C) array (any real dtype, taken as float64;
        row 0 = top), the photo as taken through the distorted lens.
    model, params: the COLMAP camera model name and its parameters in
        COLMAP's order (``ColmapImage.camera_model`` / ``.params``).
    width, height: the camera's image size, pixels. (H, W) must equal
        (height, width) times a common factor (module docstring).
    order: spline order of the interpolation, 0 (nearest) to 5; 1 is
        bilinear. Above 1 a NaN in the photo spreads along its rows and
        columns (spline prefilter).
    Returns a float64 array of the photo's shape: the view of the pinhole
    with the model's fx, fy, cx, cy (scaled with the photo), NaN outside
    (module docstring). An undistorted camera returns the photo unchanged
    (as float64). Raises ValueError (one sentence) for a bad shape, size,
    order or camera.
    """
    img = _as_image(image)
    order = _check_order(order)
    camera, (h, w) = _photo_camera(model, params, width, height, img.shape)
    if not is_distorted(model, params):
        return img.copy()  # the pinhole is the camera itself: identity resampling
    planes = img.reshape(h, w, -1)
    if order > 1:
        sources = [
            ndimage.spline_filter(planes[..., c], order, output=np.float64, mode="nearest")
            for c in range(planes.shape[2])
        ]
    else:
        sources = [planes[..., c] for c in range(planes.shape[2])]
    out = np.empty(planes.shape, dtype=np.float64)
    for rows, xy in _blocks(camera, h, w):
        out[rows] = _sample(sources, xy, order).reshape(-1, w, len(sources))
    return out.reshape(img.shape)


def undistort_mask(mask, model: str, params, width: int, height: int) -> np.ndarray:
    """(H, W) bool mask of a distorted photo resampled to the camera's pinhole.

    mask: (H, W) bool (or real: > 0.5 is True) mask in the distorted photo's
        pixels. model, params, width, height: as for `undistort_image`.
    An output pixel is True where the bilinear interpolation of the mask
    (True = 1) exceeds 0.5, False outside (module docstring).
    """
    m = np.asarray(mask)
    if m.ndim != 2:
        raise ValueError(f"The mask must be a 2-D (H, W) array, got shape {m.shape}")
    values = (m > 0.5) if m.dtype != np.bool_ else m
    out = undistort_image(values.astype(np.float64), model, params, width, height, order=1)
    with np.errstate(invalid="ignore"):
        return out > 0.5


# --------------------------------------------------------------------------- internals


def _as_image(image) -> np.ndarray:
    arr = np.asarray(image)
    if arr.ndim not in (2, 3) or min(arr.shape[:2], default=0) < 1:
        raise ValueError(f"The image must be an (H, W) or (H, W, C) array, got shape {arr.shape}")
    if arr.dtype.kind not in "biuf":
        raise ValueError(f"The image must hold real numbers, got dtype {arr.dtype}")
    return arr.astype(np.float64, copy=False)


def _check_order(order) -> int:
    if isinstance(order, bool) or int(order) != order or not 0 <= int(order) <= 5:
        raise ValueError(f"order must be a whole number from 0 to 5, got {order!r}")
    return int(order)


def _photo_camera(model, params, width, height, image_shape):
    """The pycolmap camera at the photo's size and the photo's (h, w)."""
    camera = pycolmap_camera(model, params, width, height)
    if not camera.is_perspective():
        raise ValueError(
            f"The {model} camera model is not a perspective camera and has no pinhole to "
            "undistort to"
        )
    w0, h0 = int(camera.width), int(camera.height)
    h, w = (h0, w0) if image_shape is None else (int(image_shape[0]), int(image_shape[1]))
    if (h, w) != (h0, w0):
        if w * h0 != h * w0:
            raise ValueError(
                f"The photo is {w} x {h} pixels but its COLMAP camera is {w0} x {h0}, "
                "which is neither the same size nor the same size scaled"
            )
        camera.rescale(w, h)  # fx, fy, cx, cy times w / w0 = h / h0; coefficients kept
    return camera, (h, w)


def _blocks(camera, h, w):
    """Yield (row slice, (rows * w, 2) distorted positions, NaN outside) over the output."""
    fx, fy, cx, cy = (float(v) for v in (camera.focal_length_x, camera.focal_length_y,
                                         camera.principal_point_x, camera.principal_point_y))
    step = max(1, _BLOCK_PIXELS // w)
    x = np.arange(w, dtype=np.float64) + 0.5
    for r0 in range(0, h, step):
        r1 = min(h, r0 + step)
        y = np.arange(r0, r1, dtype=np.float64) + 0.5
        rays = np.empty((r1 - r0, w, 3), dtype=np.float64)
        rays[..., 0] = ((x - cx) / fx)[None, :]
        rays[..., 1] = ((y - cy) / fy)[:, None]
        rays[..., 2] = 1.0
        rays = rays.reshape(-1, 3)
        xy = np.asarray(camera.img_from_cam(rays), dtype=np.float64)  # NaN behind the lens
        back = np.asarray(camera.cam_from_img(np.nan_to_num(xy)), dtype=np.float64)
        with np.errstate(invalid="ignore"):
            folded = np.maximum(
                np.abs(back[:, 0] - rays[:, 0]) * fx, np.abs(back[:, 1] - rays[:, 1]) * fy
            )
            ok = (
                (xy[:, 0] >= 0.0)
                & (xy[:, 0] <= camera.width)
                & (xy[:, 1] >= 0.0)
                & (xy[:, 1] <= camera.height)
                & (folded < _ROUND_TRIP_PX)
            )
        xy[~ok] = np.nan
        yield slice(r0, r1), xy


def _sample(sources, xy, order) -> np.ndarray:
    """(N, C) values of the (H, W) planes at COLMAP positions xy (N, 2); NaN rows stay NaN."""
    bad = np.isnan(xy).any(axis=1)
    coords = np.stack([xy[:, 1] - 0.5, xy[:, 0] - 0.5])  # (row, col) array indices
    coords[:, bad] = 0.0
    out = np.empty((len(xy), len(sources)), dtype=np.float64)
    for c, plane in enumerate(sources):
        out[:, c] = ndimage.map_coordinates(
            plane, coords, order=order, mode="nearest", prefilter=False, output=np.float64
        )
    out[bad] = np.nan
    return out
