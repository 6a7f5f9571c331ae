"""core.capture.scene_frame: east/north/up in world space and the scene's up from cameras.

References: the z-up convention of brdf_addon/light_sources.py ``sun_position_direction``
(rotation by the north offset about +Z applied to ENU), the NREL SPA example's
Sun (test_sun.py: azimuth 194.34024 deg, topocentric zenith
50.11162 deg), and analytic rings of look-at cameras (core.capture.cameras.look_at,
core.capture.cameras.camera_to_world) built in a rotated world whose up is known.
"""

import datetime as dt

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from brdf_reconstruct.core.capture import cameras, scene_frame, sun

SPA_WHEN = dt.datetime(2003, 10, 17, 12, 30, 30, tzinfo=dt.timezone(dt.timedelta(hours=-7)))
SPA_LAT, SPA_LON = 39.742476, -105.1786

# A world frame that is not z-up: world = Q @ (a z-up frame) + shift.
Q = Rotation.from_rotvec([0.9, -1.7, 0.4]).as_matrix()
SHIFT = np.array([3.0, -2.0, 7.5])
TRUE_UP = Q[:, 2]


def _angle_deg(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    c = a @ b / (np.linalg.norm(a) * np.linalg.norm(b))
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def _rz(a: float) -> np.ndarray:
    """light.py's matrix: rotation by a about +Z."""
    return np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])


def _cameras(headings_deg, elevation_deg, radius=2.0, roll_deg=None, rng=None, jitter=0.0):
    """Look-at cameras on a ring around the origin of the z-up frame, expressed in the world.

    Returns (rotations (N, 3, 3), centres (N, 3)) in Blender's camera convention.
    roll_deg: (N,) roll about each viewing axis; jitter: std of centre and
    target noise as a fraction of the radius.
    """
    h = np.radians(np.asarray(headings_deg, dtype=np.float64))
    el = np.radians(elevation_deg) * np.ones_like(h)
    rolls = np.zeros_like(h) if roll_deg is None else np.radians(roll_deg) * np.ones_like(h)
    rotations, centres = [], []
    for k in range(h.size):
        c = radius * np.array([np.cos(el[k]) * np.cos(h[k]), np.cos(el[k]) * np.sin(h[k]),
                               np.sin(el[k])])
        target = np.zeros(3)
        if jitter:
            c = c + rng.normal(0.0, jitter * radius, 3)
            target = target + rng.normal(0.0, jitter * radius, 3)
        R_cw, t = cameras.look_at(Q @ c + SHIFT, Q @ target + SHIFT, up=TRUE_UP)
        M = cameras.camera_to_world(R_cw, t)
        view = -M[:3, 2]
        roll = Rotation.from_rotvec(rolls[k] * view).as_matrix()
        rotations.append(roll @ M[:3, :3])
        centres.append(M[:3, 3])
    return np.array(rotations), np.array(centres)


# --- world_from_enu -------------------------------------------------------------------------


@pytest.mark.parametrize("offset_deg", [0.0, 30.0, -75.0, 180.0, 301.5])
def test_z_up_reproduces_the_light_operator_convention(offset_deg):
    a = np.radians(offset_deg)
    F = scene_frame.world_from_enu(north_offset_rad=a)
    np.testing.assert_allclose(F, _rz(a), atol=1e-15)
    d_enu = sun.sun_direction(SPA_WHEN, SPA_LAT, SPA_LON)
    np.testing.assert_allclose(F @ d_enu, _rz(a) @ d_enu, atol=1e-15)


def test_z_up_columns_by_hand():
    F = scene_frame.world_from_enu(north_offset_rad=np.pi / 2)
    # North turned 90 degrees counter-clockwise seen from above: +Y -> -X; east = north x up.
    np.testing.assert_allclose(F[:, 1], [-1.0, 0.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(F[:, 0], [0.0, 1.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(F[:, 2], [0.0, 0.0, 1.0], atol=1e-15)


@pytest.mark.parametrize(("up", "hint"), [
    ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0)),
    ((0.3, -2.0, 0.7), (0.0, 1.0, 0.0)),
    ((0.0, 1.0, 0.0), (0.0, 1.0, 0.0)),  # hint parallel to up: +Y too, so +X
    ((0.0, 0.0, -5.0), (0.0, 0.0, 1.0)),  # hint antiparallel: +Y
    ((1.0, 1.0, 1.0), (2.0, -1.0, 0.5)),
])
def test_orthonormal_right_handed(up, hint):
    F = scene_frame.world_from_enu(up, 0.7, hint)
    np.testing.assert_allclose(F.T @ F, np.eye(3), atol=1e-14)
    assert np.linalg.det(F) == pytest.approx(1.0, abs=1e-14)
    np.testing.assert_allclose(F[:, 2], np.asarray(up) / np.linalg.norm(up), atol=1e-15)
    np.testing.assert_allclose(np.cross(F[:, 1], F[:, 2]), F[:, 0], atol=1e-14)


def test_parallel_hint_fallbacks():
    F = scene_frame.world_from_enu(up=(0.0, 1.0, 0.0))  # default hint +Y is up
    np.testing.assert_allclose(F[:, 1], [1.0, 0.0, 0.0], atol=1e-15)  # north from +X
    F = scene_frame.world_from_enu(up=(0.0, 0.0, 1.0), north_hint=(0.0, 0.0, 2.0))
    np.testing.assert_allclose(F[:, 1], [0.0, 1.0, 0.0], atol=1e-15)  # north from +Y


def test_hint_is_projected_onto_the_horizontal():
    F = scene_frame.world_from_enu(up=(0.0, 0.0, 1.0), north_hint=(1.0, 1.0, 3.0))
    np.testing.assert_allclose(F[:, 1], [np.sqrt(0.5), np.sqrt(0.5), 0.0], atol=1e-15)


@pytest.mark.parametrize("offset_deg", [0.0, 42.0, -130.0])
def test_spa_sun_in_a_rotated_world(offset_deg):
    a = np.radians(offset_deg)
    F = scene_frame.world_from_enu(up=Q[:, 2], north_offset_rad=a, north_hint=Q[:, 1])
    # The rotated world's frame is Q applied to the z-up one.
    np.testing.assert_allclose(F, Q @ _rz(a), atol=1e-14)
    d_enu = sun.sun_direction(SPA_WHEN, SPA_LAT, SPA_LON)
    d_world = F @ d_enu
    np.testing.assert_allclose(Q.T @ d_world, _rz(a) @ d_enu, atol=1e-14)  # rotate back
    # Elevation and azimuth read in the world with its own east/north/up: SPA's.
    elevation = np.degrees(np.arcsin(d_world @ F[:, 2]))
    azimuth = np.degrees(np.arctan2(d_world @ F[:, 0], d_world @ F[:, 1])) % 360.0
    assert 90.0 - elevation == pytest.approx(50.11162, abs=0.05)
    assert azimuth == pytest.approx(194.34024, abs=0.05)


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"up": (0.0, 0.0, 0.0)}, "up must be a finite non-zero 3-vector"),
    ({"up": (0.0, 1.0)}, "up must be a 3-vector"),
    ({"north_hint": (np.nan, 1.0, 0.0)}, "north_hint must be a finite"),
    ({"north_offset_rad": np.inf}, "north_offset_rad must be finite"),
])
def test_world_from_enu_errors(kwargs, message):
    with pytest.raises(ValueError, match=message):
        scene_frame.world_from_enu(**kwargs)


# --- up_from_cameras ------------------------------------------------------------------------


def test_full_ring_tilted_down():
    R, C = _cameras(np.arange(0, 360, 30), elevation_deg=35.0)
    est = scene_frame.estimate_up(R, C)
    assert est.method == "centre plane"
    assert _angle_deg(est.up, TRUE_UP) < 1e-6
    assert est.spread_rad < 1e-9
    est = scene_frame.estimate_up(R)
    assert est.method == "camera horizon"
    assert _angle_deg(est.up, TRUE_UP) < 1e-6
    assert est.spread_rad < 1e-9  # no roll
    # Each camera's up vector is tilted by the elevation from the true up.
    assert _angle_deg(R[0, :, 1], TRUE_UP) == pytest.approx(35.0, abs=1e-9)


def test_partial_arc_the_mean_up_vector_is_biased_but_the_horizon_is_not():
    R, C = _cameras(np.arange(-45, 46, 10), elevation_deg=40.0)
    naive = R[:, :, 1].mean(axis=0)
    assert _angle_deg(naive, TRUE_UP) > 25.0  # why the mean of the up vectors is not used
    est = scene_frame.estimate_up(R)
    assert est.method == "camera horizon"
    assert _angle_deg(est.up, TRUE_UP) < 1e-6
    est = scene_frame.estimate_up(R, C)
    assert _angle_deg(est.up, TRUE_UP) < 1e-6


def test_crooked_turntable_camera_plane_is_exact():
    # Half a ring, every camera rolled 8 degrees: the right vectors leave the horizontal,
    # the centres still lie in the turntable's plane.
    R, C = _cameras(np.arange(0, 181, 15), elevation_deg=25.0, roll_deg=8.0)
    horizon = scene_frame.estimate_up(R)
    assert horizon.method == "camera horizon"
    assert np.degrees(horizon.spread_rad) > 3.0  # it reports the roll
    est = scene_frame.estimate_up(R, C)
    assert est.method == "centre plane"
    assert _angle_deg(est.up, TRUE_UP) < 1e-6


def test_noisy_walk_around_within_half_a_degree():
    rng = np.random.default_rng(11)
    n = 24
    R, C = _cameras(np.linspace(0, 360, n, endpoint=False) + rng.normal(0, 5, n),
                    elevation_deg=20.0, roll_deg=rng.normal(0.0, 0.5, n), rng=rng, jitter=0.005)
    for centres in (C, None):
        est = scene_frame.estimate_up(R, centres)
        assert _angle_deg(est.up, TRUE_UP) < 0.5
        assert 0.0 < np.degrees(est.spread_rad) < 1.0
        np.testing.assert_allclose(np.linalg.norm(est.up), 1.0, atol=1e-15)
    assert scene_frame.estimate_up(R, C).method == "centre plane"


def test_horizon_error_follows_its_spread():
    # Least squares of n right vectors with independent out-of-plane errors of RMS
    # `spread` spread evenly in heading: each of the 2 error components of up has
    # std spread / sqrt(n / 2), so |error| is Rayleigh with median sqrt(2 ln 2) of that.
    n, ratios = 24, []
    for seed in range(60):
        rng = np.random.default_rng(seed)
        R, _ = _cameras(np.linspace(0, 360, n, endpoint=False) + rng.normal(0, 5, n),
                        elevation_deg=20.0, roll_deg=rng.normal(0.0, 1.5, n))
        est = scene_frame.estimate_up(R)
        assert est.method == "camera horizon"
        ratios.append(_angle_deg(est.up, TRUE_UP) / np.degrees(est.spread_rad / np.sqrt(n / 2)))
    assert np.median(ratios) == pytest.approx(np.sqrt(2 * np.log(2)), rel=0.25)


def _facing_the_facade(spots):
    """Level cameras at (x, z) spots on the plane y = -5 of the (rotated) world, each
    looking straight ahead along +y: (N, 3, 3) rotations and (N, 3) centres."""
    R, C = [], []
    for x, z in spots:
        R_cw, t = cameras.look_at(Q @ [x, -5.0, z] + SHIFT, Q @ [x, 0.0, z] + SHIFT, TRUE_UP)
        M = cameras.camera_to_world(R_cw, t)
        R.append(M[:3, :3])
        C.append(M[:3, 3])
    return np.array(R), np.array(C)


def test_forward_facing_line_uses_the_up_vectors():
    # Level cameras side by side, all facing the same way (a facade): collinear centres,
    # parallel right vectors; only the up vectors tell.
    R, C = _facing_the_facade([(x, 1.0) for x in np.linspace(-3, 3, 7)])
    est = scene_frame.estimate_up(R, C)
    assert est.method == "camera up vectors"
    assert _angle_deg(est.up, TRUE_UP) < 1e-6


def test_facade_grid_plane_is_rejected():
    # Centres on a vertical plane (its normal is horizontal): not the scene's up.
    R, C = _facing_the_facade([(x, z) for x in np.linspace(-3, 3, 4) for z in (0.5, 1.5, 2.5)])
    est = scene_frame.estimate_up(R, C)
    assert est.method == "camera up vectors"
    assert _angle_deg(est.up, TRUE_UP) < 1e-6


def test_a_few_portrait_shots_do_not_fool_it():
    # Forward-facing level cameras, two of them rolled 90 degrees (portrait): the right
    # vectors then span the facade's plane, whose normal (the viewing direction) is wrong.
    R = []
    for k, x in enumerate(np.linspace(-3, 3, 10)):
        R_cw, t = cameras.look_at(Q @ [x, -5.0, 1.0] + SHIFT, Q @ [x, 0.0, 1.0] + SHIFT, TRUE_UP)
        M = cameras.camera_to_world(R_cw, t)
        roll = Rotation.from_rotvec(np.pi / 2 * -M[:3, 2]).as_matrix() if k in (2, 7) else np.eye(3)
        R.append(roll @ M[:3, :3])
    est = scene_frame.estimate_up(np.array(R))
    assert est.method == "camera up vectors"
    assert _angle_deg(est.up, TRUE_UP) < 1e-6  # the geometric median ignores the two
    assert np.degrees(est.spread_rad) == pytest.approx(np.sqrt(2 / 10) * 90.0, abs=1e-6)


def test_up_from_cameras_is_estimate_up_as_a_pair():
    R, C = _cameras(np.arange(0, 360, 45), elevation_deg=30.0, roll_deg=2.0)
    est = scene_frame.estimate_up(R, C)
    up, spread = scene_frame.up_from_cameras(R, C)
    np.testing.assert_array_equal(up, est.up)
    assert spread == est.spread_rad
    assert _angle_deg(up, TRUE_UP) < 1e-6
    up, spread = scene_frame.up_from_cameras(R)
    assert _angle_deg(up, TRUE_UP) < 1e-6  # the full ring's symmetry cancels the roll
    assert np.degrees(spread) > 1.0


def test_single_camera():
    R, C = _cameras([0.0], elevation_deg=0.0)
    est = scene_frame.estimate_up(R, C)
    assert est.method == "camera up vectors"
    assert _angle_deg(est.up, TRUE_UP) < 1e-6 and est.spread_rad < 1e-12


def test_up_from_cameras_errors():
    R, C = _cameras(np.arange(0, 360, 90), elevation_deg=10.0)
    with pytest.raises(ValueError, match=r"rotations must have shape \(N, 3, 3\)"):
        scene_frame.up_from_cameras(R[:, :2])
    with pytest.raises(ValueError, match="proper rotation"):
        scene_frame.estimate_up(R * 2.0)
    with pytest.raises(ValueError, match="proper rotation"):
        scene_frame.estimate_up(-R)
    with pytest.raises(ValueError, match=r"centres must have shape \(4, 3\)"):
        scene_frame.estimate_up(R, C[:3])
    with pytest.raises(ValueError, match="centres must be finite"):
        scene_frame.estimate_up(R, np.full((4, 3), np.nan))
