"""The scene's geographic frame: where east, north and up are in world space.

core.capture.sun gives the Sun in local east-north-up (ENU: +X east, +Y north, +Z
up). A scene's world frame need not be z-up (a COLMAP world is arbitrary), so
the sun direction in world space is ``world_from_enu(...) @ d_enu``.

Convention (the one ``brdf_addon/light_sources.py`` ``sun_position_direction`` uses
for a z-up world): the scene's north is the north hint (+Y) turned by the
north offset counter-clockwise about up, seen from above; for up = +Z,
``world_from_enu(north_offset_rad=a)`` is the rotation by a about +Z.

The scene's up, when the world is not z-up, is estimated from the cameras
(`up_from_cameras`, `estimate_up`). Camera rotations are in Blender's convention (camera
looks down its -z, +y up in the image, +x right), i.e. the (3, 3) part of
``core.capture.cameras.camera_to_world``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

# Parallel test for the north hint: |hint x up| below this (unit vectors).
_PARALLEL_SIN = 1e-6
# up_from_cameras: the cameras' right vectors span a plane well enough when the
# middle eigenvalue of mean(x x^T) reaches this (about +-20 degrees of heading).
_HORIZON_MIN_EIGENVALUE = 0.05
# ... and when the median camera pitch it implies (angle of the camera up vectors
# from it) is at most this: otherwise the right vectors are ambiguous (e.g. a few
# portrait shots among level ones) and steep top-down views are the less likely case.
_HORIZON_MAX_MEDIAN_PITCH_RAD = np.radians(60.0)
# The plane through the centres is used when they are not collinear (second
# singular value at least this fraction of the first), fit a plane (third at
# most this fraction of the second) and its normal is within this angle of
# the cameras' own up estimate.
_PLANE_MIN_ASPECT = 0.2
_PLANE_MAX_THICKNESS = 0.5
_PLANE_MAX_ANGLE_RAD = np.radians(45.0)


def _unit3(v, name: str) -> np.ndarray:
    a = np.asarray(v, dtype=np.float64)
    if a.shape != (3,):
        raise ValueError(f"{name} must be a 3-vector, got shape {a.shape}")
    norm = np.linalg.norm(a)
    if not np.all(np.isfinite(a)) or not norm > 0.0:
        raise ValueError(f"{name} must be a finite non-zero 3-vector, got {a.tolist()}")
    return a / norm


def world_from_enu(up=(0.0, 0.0, 1.0), north_offset_rad: float = 0.0, north_hint=(0.0, 1.0, 0.0)):
    """(3, 3) float64 rotation whose columns are the world-space east, north and up.

    up: (3,) world direction of the local vertical (normalised here).
    north_offset_rad: radians; the scene's north is the hint turned by this
        angle counter-clockwise about up, seen from above (right-hand rule).
    north_hint: (3,) world direction taken as north before the offset; it is
        projected onto the plane normal to up. If it is parallel to up, world
        +Y is used instead, and +X if +Y is parallel too.

    east = north x up, so the matrix is right-handed (det +1) and maps a
    direction in ENU (e.g. ``core.capture.sun.sun_direction``) to world space:
    ``d_world = world_from_enu(...) @ d_enu``. For up = +Z and the default
    hint this is the rotation by north_offset_rad about +Z.
    """
    u = _unit3(up, "up")
    a = float(north_offset_rad)
    if not np.isfinite(a):
        raise ValueError(f"north_offset_rad must be finite, got {north_offset_rad!r}")
    for candidate in (_unit3(north_hint, "north_hint"), np.array([0.0, 1.0, 0.0]),
                      np.array([1.0, 0.0, 0.0])):
        n = candidate - (candidate @ u) * u
        if np.linalg.norm(n) > _PARALLEL_SIN:
            break
    n /= np.linalg.norm(n)
    # Rodrigues about u for a vector normal to u.
    n = np.cos(a) * n + np.sin(a) * np.cross(u, n)
    n /= np.linalg.norm(n)
    e = np.cross(n, u)
    return np.stack([e, n, u], axis=1)


class UpEstimate(NamedTuple):
    """What `estimate_up` found.

    up: (3,) float64 unit world direction of the scene's up.
    spread_rad: RMS disagreement of the cameras with that up, in radians, as
        the chosen method measures it (see `estimate_up`); warn the user
        when it is large (several degrees).
    method: "centre plane", "camera horizon" or "camera up vectors".
    """

    up: np.ndarray
    spread_rad: float
    method: str


def _check_rotations(rotations) -> np.ndarray:
    R = np.asarray(rotations, dtype=np.float64)
    if R.ndim != 3 or R.shape[1:] != (3, 3) or R.shape[0] == 0:
        raise ValueError(f"rotations must have shape (N, 3, 3) with N >= 1, got {R.shape}")
    if not np.all(np.isfinite(R)):
        raise ValueError("rotations must be finite")
    gram = np.einsum("nji,njk->nik", R, R)
    if not np.allclose(gram, np.eye(3), atol=1e-6) or np.any(np.linalg.det(R) < 0.0):
        raise ValueError("rotations must be proper rotation matrices (orthonormal, det +1)")
    return R


def _spherical_median(vectors: np.ndarray, iterations: int = 50) -> np.ndarray:
    """Robust mean direction of (N, 3) unit vectors: Weiszfeld's geometric median, normalised."""
    m = vectors.mean(axis=0)
    if not np.linalg.norm(m) > 1e-12:
        m = vectors[0]
    for _ in range(iterations):
        d = np.maximum(np.linalg.norm(vectors - m, axis=1), 1e-9)
        m_new = (vectors / d[:, None]).sum(axis=0) / (1.0 / d).sum()
        if np.linalg.norm(m_new - m) < 1e-14:
            m = m_new
            break
        m = m_new
    return m / np.linalg.norm(m)


def _angles(vectors: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """(N,) angles in radians between (N, 3) unit vectors and a unit (3,) direction,
    from the chord (2 asin(|a - b| / 2)): exact near 0, where ``arccos`` of a dot
    product a rounding below 1 gives 2e-8 rad for identical directions."""
    chord = np.linalg.norm(vectors - direction, axis=-1)
    return 2.0 * np.arcsin(np.clip(chord / 2.0, 0.0, 1.0))


def _rms(angles: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(angles))))


def up_from_cameras(rotations, centres=None) -> tuple[np.ndarray, float]:
    """(up (3,) unit float64, spread_rad): `estimate_up` without the method's name."""
    estimate = estimate_up(rotations, centres)
    return estimate.up, estimate.spread_rad


def estimate_up(rotations, centres=None) -> UpEstimate:
    """The scene's up from its cameras, people holding cameras roughly upright.

    rotations: (N, 3, 3) camera-to-world rotations in Blender's convention
        (columns: the camera's right x, up y and backward z in world space).
    centres: optional (N, 3) camera centres in world space.

    Three estimates, the first that applies is returned (`UpEstimate.method`):
    1. "centre plane" (needs centres, N >= 3): the normal of the least-squares
       plane through the centres, for cameras on a ring around the object
       (turntables, walk-arounds). Used only if the centres are not collinear,
       do lie near a plane, and the normal is within 45 degrees of estimate 2
       or 3 (which also orients it). spread: RMS elevation of the centres
       above / below the plane seen from their centroid.
    2. "camera horizon": the direction most normal to every camera's right
       vector (the smallest eigenvector of mean(x x^T)), exact for cameras
       without roll however much they tilt down at the object. Used when the
       right vectors point in enough different headings (about +-20 degrees
       or more) and the median camera pitch it implies is at most 60 degrees
       (else the right vectors are ambiguous, e.g. a few portrait shots among
       level ones); oriented to agree with the mean camera up vector.
       spread: RMS angle of the right vectors out of the horizontal plane
       (camera roll); with n cameras evenly around, the up's error is about
       spread / sqrt(n / 2) (the centre plane is better on a ring).
    3. "camera up vectors": the robust mean (geometric median on the unit
       sphere) of the cameras' up vectors y. Biased by the cameras' common
       tilt. spread: RMS angle between each y and the mean.
    """
    R = _check_rotations(rotations)
    n_cam = R.shape[0]
    rights, ups = R[:, :, 0], R[:, :, 1]
    mean_up = _spherical_median(ups)

    estimate = UpEstimate(
        mean_up, _rms(_angles(ups, mean_up)), "camera up vectors"
    )
    eigenvalues, eigenvectors = np.linalg.eigh(rights.T @ rights / n_cam)
    if eigenvalues[1] >= _HORIZON_MIN_EIGENVALUE:
        up = eigenvectors[:, 0]
        up = up if ups.sum(axis=0) @ up >= 0.0 else -up
        pitch = np.arccos(np.clip(ups @ up, -1.0, 1.0))
        if np.median(pitch) <= _HORIZON_MAX_MEDIAN_PITCH_RAD:
            spread = _rms(np.arcsin(np.clip(np.abs(rights @ up), 0.0, 1.0)))
            estimate = UpEstimate(up, spread, "camera horizon")

    if centres is None:
        return estimate
    C = np.asarray(centres, dtype=np.float64)
    if C.shape != (n_cam, 3):
        raise ValueError(f"centres must have shape ({n_cam}, 3) like rotations, got {C.shape}")
    if not np.all(np.isfinite(C)):
        raise ValueError("centres must be finite")
    if n_cam < 3:
        return estimate
    offsets = C - C.mean(axis=0)
    _, s, vt = np.linalg.svd(offsets, full_matrices=False)
    planar = s[1] >= _PLANE_MIN_ASPECT * s[0] and s[2] <= _PLANE_MAX_THICKNESS * s[1]
    if not (s[0] > 0.0 and planar):
        return estimate
    normal = vt[2]
    if normal @ estimate.up < 0.0:
        normal = -normal
    if np.arccos(np.clip(normal @ estimate.up, -1.0, 1.0)) > _PLANE_MAX_ANGLE_RAD:
        return estimate
    height = offsets @ normal
    radius = np.linalg.norm(offsets - height[:, None] * normal, axis=1)
    spread = _rms(np.arctan2(np.abs(height), radius))
    return UpEstimate(normal, spread, "centre plane")
