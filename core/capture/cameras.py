"""COLMAP cameras <-> Blender cameras: poses, intrinsics and projections.

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

from dataclasses import dataclass

import numpy as np

SENSOR_SIZE_MM = 36.0
"""Width of the fitted (larger) sensor dimension given to imported cameras, mm."""

_MAX_PIXEL_ASPECT = 200.0  # Blender's hard limit on pixel_aspect_x / _y


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
    w, h = check_size(width, height)
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
    w, h = check_size(intr.resolution_x, intr.resolution_y)
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
    R, t = check_pose(R_cam_from_world, t)
    return -R.T @ t


def camera_to_world(R_cam_from_world, t) -> np.ndarray:
    """(4, 4) float64 Blender ``matrix_world`` of a camera with a COLMAP pose.

    R_cam_from_world: (3, 3) rotation, t: (3,) translation, with
    X_cam = R X + t in COLMAP's camera frame (x right, y down, z forward).
    The result maps Blender camera coordinates (x right, y up, looking down
    -z) to world coordinates: rotation R^T diag(1, -1, -1), translation the
    camera centre -R^T t. No scale.
    """
    R, t = check_pose(R_cam_from_world, t)
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


def check_size(width, height) -> tuple[int, int]:
    w, h = int(width), int(height)
    if w != width or w <= 0:
        raise ValueError(f"width must be a positive whole number of pixels, got {width}")
    if h != height or h <= 0:
        raise ValueError(f"height must be a positive whole number of pixels, got {height}")
    return w, h


def check_pose(R, t) -> tuple[np.ndarray, np.ndarray]:
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
