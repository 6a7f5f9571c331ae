"""The COLMAP -> Blender camera conventions (core.capture.cameras; no bpy): intrinsics
as Blender's sensor, shift and pixel aspect, poses, and the projection.

`project_blender` is a numpy model of Blender's own viewplane rule; it is
checked against real Blender in tests/blender/test_colmap_import.py. Here it is
checked against analytic pinhole projections and pycolmap's projection.
"""

import math

import numpy as np
import pytest

from brdf_reconstruct.core.capture import cameras as camconv

pycolmap = pytest.importorskip("pycolmap")


def _pinhole(fx, fy, cx, cy, R, t, xyz):
    cam = np.asarray(xyz) @ np.asarray(R).T + t
    return np.stack([fx * cam[:, 0] / cam[:, 2] + cx, fy * cam[:, 1] / cam[:, 2] + cy], axis=1)


def _project(fx, fy, cx, cy, w, h, R, t, xyz):
    intr = camconv.blender_intrinsics(fx, fy, cx, cy, w, h)
    return camconv.project_blender(camconv.camera_to_world(R, t), intr, xyz)


# --------------------------------------------------------------------------- intrinsics


def test_landscape_centred_square_pixels():
    intr = camconv.blender_intrinsics(800.0, 800.0, 320.0, 240.0, 640, 480)
    assert intr.sensor_fit == "HORIZONTAL"
    assert intr.sensor_width == 36.0
    assert intr.lens == pytest.approx(800.0 * 36.0 / 640.0)  # 45 mm
    assert intr.sensor_height == pytest.approx(27.0)
    assert (intr.shift_x, intr.shift_y) == (0.0, 0.0)
    assert (intr.pixel_aspect_x, intr.pixel_aspect_y) == (1.0, 1.0)
    assert (intr.resolution_x, intr.resolution_y) == (640, 480)


def test_landscape_off_centre_shift_in_units_of_width():
    # Optical axis 64 px right of and 48 px above the centre: the view moves
    # left and down, by fractions of the larger dimension (the width).
    intr = camconv.blender_intrinsics(800.0, 800.0, 384.0, 192.0, 640, 480)
    assert intr.shift_x == pytest.approx(-0.1)
    assert intr.shift_y == pytest.approx(-48.0 / 640.0)


def test_portrait_fits_vertically_and_shifts_in_units_of_height():
    intr = camconv.blender_intrinsics(800.0, 800.0, 200.0, 360.0, 480, 640)
    assert intr.sensor_fit == "VERTICAL"
    assert intr.sensor_height == 36.0
    assert intr.sensor_width == pytest.approx(27.0)
    assert intr.lens == pytest.approx(800.0 * 36.0 / 640.0)
    assert intr.shift_x == pytest.approx(40.0 / 640.0)
    assert intr.shift_y == pytest.approx(40.0 / 640.0)


def test_square_image_fits_horizontally():
    assert camconv.blender_intrinsics(500, 500, 256, 256, 512, 512).sensor_fit == "HORIZONTAL"


@pytest.mark.parametrize(
    ("fx", "fy", "ax", "ay"), [(900.0, 800.0, 1.0, 1.125), (800, 900, 1.125, 1)]
)
def test_unequal_focal_lengths_become_pixel_aspect(fx, fy, ax, ay):
    intr = camconv.blender_intrinsics(fx, fy, 320, 240, 640, 480)
    assert (intr.pixel_aspect_x, intr.pixel_aspect_y) == pytest.approx((ax, ay))
    assert min(intr.pixel_aspect_x, intr.pixel_aspect_y) == 1.0


def test_fit_follows_displayed_aspect_not_pixel_count():
    # 500 x 480 pixels, each 1.25 times as tall as wide: displayed 500 x 600, portrait.
    intr = camconv.blender_intrinsics(1000.0, 800.0, 250, 240, 500, 480)
    assert intr.pixel_aspect_y == pytest.approx(1.25)
    assert intr.sensor_fit == "VERTICAL"


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize(("w", "h"), [(640, 480), (480, 640), (4000, 3000), (1, 1), (512, 512)])
def test_intrinsics_round_trip(w, h, seed):
    rng = np.random.default_rng(seed)
    fx, fy = rng.uniform(0.5, 2.0, 2) * max(w, h)
    cx, cy = rng.uniform(-0.2, 1.2) * w, rng.uniform(-0.2, 1.2) * h
    back = camconv.pinhole_from_blender(camconv.blender_intrinsics(fx, fy, cx, cy, w, h))
    np.testing.assert_allclose(back, (fx, fy, cx, cy), rtol=1e-12, atol=1e-9)


def test_float32_inputs_give_float64_results():
    f32 = np.float32
    intr = camconv.blender_intrinsics(f32(800), f32(820), f32(300.5), f32(250.25), 640, 480)
    back = camconv.pinhole_from_blender(intr)
    np.testing.assert_allclose(back, (800, 820, 300.5, 250.25), rtol=1e-12)
    assert all(isinstance(v, float) for v in back)


@pytest.mark.parametrize(
    ("kwargs", "word"),
    [
        ({"fx": 0.0}, "fx"),
        ({"fy": -1.0}, "fy"),
        ({"fx": math.nan}, "fx"),
        ({"cx": math.inf}, "cx"),
        ({"width": 0}, "width"),
        ({"height": 480.5}, "height"),
        ({"fx": 800.0 * 201}, "pixel aspect"),
    ],
)
def test_intrinsics_reject_bad_input(kwargs, word):
    args = {"fx": 800.0, "fy": 800.0, "cx": 320.0, "cy": 240.0, "width": 640, "height": 480}
    args.update(kwargs)
    with pytest.raises(ValueError, match=word):
        camconv.blender_intrinsics(**args)


def test_pinhole_from_blender_rejects_auto_fit():
    intr = camconv.blender_intrinsics(800, 800, 320, 240, 640, 480)
    bad = camconv.BlenderIntrinsics(**{**intr.__dict__, "sensor_fit": "AUTO"})
    with pytest.raises(ValueError, match="sensor_fit"):
        camconv.pinhole_from_blender(bad)


# --------------------------------------------------------------------------- poses


def test_identity_pose_flips_y_and_z():
    M = camconv.camera_to_world(np.eye(3), np.zeros(3))
    np.testing.assert_array_equal(M, np.diag([1.0, -1.0, -1.0, 1.0]))


def test_pose_axes_and_centre():
    R, t = camconv.look_at([3.0, -2.0, 1.5], [0.2, 0.1, -0.3])
    M = camconv.camera_to_world(R, t)
    np.testing.assert_allclose(M[:3, :3].T @ M[:3, :3], np.eye(3), atol=1e-12)
    assert np.linalg.det(M[:3, :3]) == pytest.approx(1.0)
    np.testing.assert_allclose(M[:3, 3], [3.0, -2.0, 1.5], atol=1e-12)
    np.testing.assert_allclose(camconv.camera_centre(R, t), [3.0, -2.0, 1.5], atol=1e-12)
    view = np.array([0.2, 0.1, -0.3]) - [3.0, -2.0, 1.5]
    np.testing.assert_allclose(-M[:3, 2], view / np.linalg.norm(view), atol=1e-12)  # Blender -z
    np.testing.assert_allclose(M[:3, 1], -R[1], atol=1e-12)  # Blender +y is COLMAP -y
    assert M[2, 1] > 0  # world up (+z) appears up in the image


def test_pose_rejects_non_rotation():
    with pytest.raises(ValueError, match="R_cam_from_world"):
        camconv.camera_to_world(np.diag([1.0, 1.0, -1.0]), np.zeros(3))
    with pytest.raises(ValueError, match="R_cam_from_world"):
        camconv.camera_to_world(np.eye(2), np.zeros(3))
    with pytest.raises(ValueError, match="t must"):
        camconv.camera_centre(np.eye(3), np.zeros(4))


def test_look_at_rejects_degenerate():
    with pytest.raises(ValueError, match="target"):
        camconv.look_at([1, 2, 3], [1, 2, 3])
    with pytest.raises(ValueError, match="up"):
        camconv.look_at([0, 0, 5], [0, 0, 0])


# --------------------------------------------------------------------------- projection


def test_known_point_projects_to_known_pixel():
    # Camera at the origin looking down world +z (COLMAP identity pose);
    # (0.5, -0.25, 2) lies 0.25 right and 0.125 up per unit depth.
    fx, fy, cx, cy = 800.0, 800.0, 300.0, 260.0
    px = _project(fx, fy, cx, cy, 640, 480, np.eye(3), np.zeros(3), [[0.5, -0.25, 2.0]])
    np.testing.assert_allclose(px, [[300.0 + 200.0, 260.0 - 100.0]], atol=1e-12)


def test_target_of_look_at_lands_on_principal_point():
    R, t = camconv.look_at([4, 1, 2], [0, 0, 0])
    for w, h, cx, cy in [(640, 480, 301.7, 255.2), (480, 640, 250.0, 300.0)]:
        px = _project(900, 870, cx, cy, w, h, R, t, [[0, 0, 0]])
        np.testing.assert_allclose(px, [[cx, cy]], atol=1e-10)


@pytest.mark.parametrize(
    ("w", "h", "params"),
    [
        (640, 480, (800.0, 800.0, 320.0, 240.0)),  # centred
        (640, 480, (800.0, 860.0, 290.0, 265.0)),  # off-centre, fx < fy
        (480, 640, (700.0, 650.0, 250.0, 300.0)),  # portrait, fx > fy
        (300, 900, (1200.0, 1200.0, 100.0, 500.0)),  # tall portrait
    ],
)
def test_projection_matches_pinhole_and_pycolmap(w, h, params):
    rng = np.random.default_rng(1)
    xyz = rng.uniform(-1, 1, (300, 3))
    R, t = camconv.look_at([0.5, -4.0, 1.0], [0.1, 0.0, 0.0])
    px = _project(*params, w, h, R, t, xyz)
    np.testing.assert_allclose(px, _pinhole(*params, R, t, xyz), atol=1e-9)
    camera = pycolmap.Camera.create_from_model_name(1, "PINHOLE", 1.0, w, h)
    camera.params = params
    np.testing.assert_allclose(px, camera.img_from_cam(xyz @ R.T + t), atol=1e-9)


def test_points_behind_camera_are_nan_and_empty_input_is_empty():
    px = _project(800, 800, 320, 240, 640, 480, np.eye(3), np.zeros(3), [[0, 0, -1], [0, 0, 0]])
    assert np.isnan(px).all()
    empty = _project(800, 800, 320, 240, 640, 480, np.eye(3), np.zeros(3), np.zeros((0, 3)))
    assert empty.shape == (0, 2)


def test_view_scale():
    centres = [[5, 0, 0], [0, 5, 0], [-5, 0, 0], [0, 0, 5]]
    xyz = np.random.default_rng(0).normal(size=(1001, 3)) * 0.1
    assert camconv.view_scale(centres, xyz) == pytest.approx(5.0, rel=0.05)
    assert camconv.view_scale(centres) == pytest.approx(5.0)  # about their median, the origin
    assert camconv.view_scale(np.zeros((0, 3))) == 1.0
    assert camconv.view_scale([[1, 2, 3]]) == 1.0  # one camera, no points: degenerate
