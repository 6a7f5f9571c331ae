"""Undistorting photos of distorted COLMAP cameras to their Blender pinhole (no bpy).

Distorted photos are made analytically: each pixel centre q of the distorted
image is unprojected with pycolmap's ``cam_from_img`` (the inverse of the
lens, iterated) to its normalized ray n, and takes the value of a pattern
drawn on the pinhole image, at the pinhole pixel (fx n_x + cx, fy n_y + cy).
That is what a camera with that lens records of a scene whose pinhole image
is the pattern. Undistortion goes the other way (``img_from_cam``), so a
correct resampling gives back the pattern on the pinhole grid. Blob centres
are projections of 3-D points, checked against ``core.capture.colmap``'s Blender
projection of the same points.
"""

import numpy as np
import pytest

from brdf_reconstruct.core.capture import cameras as camconv
from brdf_reconstruct.core.capture import colmap as cm
from brdf_reconstruct.core.capture import undistort as ud

pycolmap = pytest.importorskip("pycolmap")

W, H = 320, 240
SIGMA = 1.6  # blob radius on the pinhole image, pixels

# fx, fy, cx, cy are the first params, or f, cx, cy for the single-focal models.
MODELS = {
    "SIMPLE_RADIAL": [260.0, 163.2, 118.7, -0.15],  # barrel
    "RADIAL": [255.0, 158.4, 121.9, 0.12, -0.02],  # pincushion
    "OPENCV": [250.0, 265.0, 161.3, 117.6, -0.12, 0.03, 0.004, -0.003],
    "FULL_OPENCV": [250.0, 262.0, 159.1, 121.4, -0.1, 0.02, 0.002, -0.002, 0.01, 0.05, 0.0, 0.01],
    "OPENCV_FISHEYE": [200.0, 210.0, 162.0, 119.0, 0.05, -0.01, 0.002, 0.0],
    "SIMPLE_RADIAL_FISHEYE": [205.0, 160.5, 120.5, 0.03],
    "THIN_PRISM_FISHEYE": [
        200.0, 208.0, 158.7, 121.1, 0.05, -0.01, 0.001, 0.001, 0.002, 0.0, 0.001, -0.001,
    ],
}  # fmt: skip


def _pinhole(model, params):
    """(fx, fy, cx, cy) read off the params by hand (independent of core.capture.colmap)."""
    p = list(params)
    if model.startswith(("SIMPLE_", "RADIAL")):
        return p[0], p[0], p[1], p[2]
    return p[0], p[1], p[2], p[3]


def _centres(w, h):
    """(h * w, 2) COLMAP positions of the pixel centres, row-major."""
    y, x = np.mgrid[0:h, 0:w] + 0.5
    return np.column_stack([x.ravel(), y.ravel()])


def _draw_distorted(model, params, w, h, pattern):
    """(h, w) photo through the lens of a pattern given on the pinhole image.

    pattern: function of (N, 2) pinhole pixel positions -> (N,) values.
    """
    camera = pycolmap.Camera(model=model, width=w, height=h, params=params)
    n = camera.cam_from_img(_centres(w, h))
    fx, fy, cx, cy = _pinhole(model, params)
    pin = np.column_stack([fx * n[:, 0] + cx, fy * n[:, 1] + cy])
    return pattern(pin).reshape(h, w)


def _blobs(centres):
    def pattern(px):
        d2 = ((px[:, None, :] - centres[None, :, :]) ** 2).sum(-1)
        return np.exp(-d2 / (2 * SIGMA**2)).sum(axis=1)

    return pattern


def _smooth(px):
    return 1.0 + 0.5 * np.sin(px[:, 0] / 7.0) * np.cos(px[:, 1] / 9.0) + 0.002 * px[:, 0]


def _scene(model, params, w=W, h=H):
    """World points, a pose, and their pinhole pixels from
     the Blender projection (core.capture.cameras)."""
    R, t = camconv.look_at([0.4, -5.0, 1.0], [0.1, 0.0, 0.2])
    g = np.linspace(-1.0, 1.0, 5)  # spans most of the frame: normalized x to 0.45, y to 0.3
    xyz = np.array([[a, 0.3 * a * b, b] for a in g for b in g]) * [2.2, 1.0, 1.4]
    intr = camconv.blender_intrinsics(*_pinhole(model, params), w, h)
    px = camconv.project_blender(camconv.camera_to_world(R, t), intr, xyz)
    cam = xyz @ R.T + t
    return cam, px


def _centroids(image, expected, radius=8):
    """(K, 2) intensity centroids (COLMAP positions) in windows around the expected spots."""
    out = []
    for x, y in expected:
        c0, r0 = int(round(x - 0.5)), int(round(y - 0.5))
        win = image[r0 - radius : r0 + radius + 1, c0 - radius : c0 + radius + 1]
        assert win.shape == (2 * radius + 1,) * 2 and np.isfinite(win).all()
        rr, cc = np.mgrid[r0 - radius : r0 + radius + 1, c0 - radius : c0 + radius + 1]
        out.append([(win * (cc + 0.5)).sum() / win.sum(), (win * (rr + 0.5)).sum() / win.sum()])
    return np.array(out)


# --------------------------------------------------------------------------- alignment


@pytest.mark.parametrize("model", sorted(MODELS))
def test_blobs_of_3d_points_land_on_the_pinhole_projection(model):
    params = MODELS[model]
    cam, px = _scene(model, params)
    fx, fy, cx, cy = _pinhole(model, params)
    # the blobs are drawn at each point's own ray, not from core.capture.colmap's pixels
    ray_px = np.column_stack(
        [fx * cam[:, 0] / cam[:, 2] + cx, fy * cam[:, 1] / cam[:, 2] + cy]
    )
    photo = _draw_distorted(model, params, W, H, _blobs(ray_px))
    lens = pycolmap.Camera(model=model, width=W, height=H, params=params)
    shift = np.linalg.norm(lens.img_from_cam(cam) - px, axis=1)
    assert shift.max() > 3.0  # the lens moves the blobs: without undistortion this fails

    out = ud.undistort_image(photo, model, params, W, H)
    assert out.shape == (H, W) and out.dtype == np.float64
    err = np.linalg.norm(_centroids(out, px) - px, axis=1)
    print(f"\n{model}: lens shift up to {shift.max():.1f} px, centroid error {err.max():.4f} px")
    assert err.max() < 0.1
    assert np.linalg.norm(_centroids(photo, px) - px, axis=1).max() > 1.0  # the photo itself


@pytest.mark.parametrize("model", sorted(MODELS))
def test_smooth_pattern_is_recovered_on_the_pinhole_grid(model):
    params = MODELS[model]
    photo = _draw_distorted(model, params, W, H, _smooth)
    out = ud.undistort_image(photo, model, params, W, H)
    truth = _smooth(_centres(W, H)).reshape(H, W)
    fx, fy, cx, cy = _pinhole(model, params)
    rays = np.column_stack([(_centres(W, H) - [cx, cy]) / [fx, fy], np.ones(W * H)])
    xd = pycolmap.Camera(model=model, width=W, height=H, params=params).img_from_cam(rays)
    inner = ((xd > 0.5) & (xd < [W - 0.5, H - 0.5])).all(axis=1).reshape(H, W)
    assert inner.mean() > 0.6 and np.isfinite(out[inner]).all()
    # bilinear error on a 44-px-period pattern (the outer half pixel is clamped, not compared)
    assert np.abs(out - truth)[inner].max() < 0.01
    assert np.abs(photo - truth).max() > 0.3  # and the photo itself is far from it


def test_bilinear_sampling_at_the_lens_position_with_the_half_pixel_convention():
    # A linear ramp in array index is reproduced exactly by bilinear sampling, so
    # each output equals the ramp at the analytic SIMPLE_RADIAL position, index = x - 0.5.
    f, cx, cy, k = 300.0, 161.0, 118.0, -0.08
    rows, cols = np.mgrid[0:H, 0:W].astype(np.float64)
    ramp = 3.0 * cols - 2.0 * rows + 7.0
    out = ud.undistort_image(ramp, "SIMPLE_RADIAL", [f, cx, cy, k], W, H)
    q = _centres(W, H)
    n = (q - [cx, cy]) / f
    xd = f * n * (1 + k * (n**2).sum(1, keepdims=True)) + [cx, cy]
    inner = (xd[:, 0] > 0.5) & (xd[:, 0] < W - 0.5) & (xd[:, 1] > 0.5) & (xd[:, 1] < H - 0.5)
    expected = 3.0 * (xd[:, 0] - 0.5) - 2.0 * (xd[:, 1] - 0.5) + 7.0
    np.testing.assert_allclose(out.ravel()[inner], expected[inner], rtol=0, atol=1e-9)
    np.testing.assert_allclose(
        ud.distorted_positions("SIMPLE_RADIAL", [f, cx, cy, k], W, H).reshape(-1, 2)[inner],
        xd[inner],
        atol=1e-9,
    )


@pytest.mark.parametrize("order", [0, 3])
def test_other_interpolation_orders(order):
    params = MODELS["OPENCV"]
    rows, cols = np.mgrid[0:H, 0:W].astype(np.float64)
    ramp = 0.5 * cols + 0.25 * rows
    out = ud.undistort_image(ramp, "OPENCV", params, W, H, order=order)
    xy = ud.distorted_positions("OPENCV", params, W, H)
    if order == 0:  # nearest: the value of the pixel holding the position
        idx = np.floor(xy).astype(int)
        ok = np.isfinite(xy).all(-1) & (idx[..., 0] < W) & (idx[..., 1] < H)
        expected = 0.5 * idx[..., 0] + 0.25 * idx[..., 1]
        np.testing.assert_array_equal(out[ok], expected[ok])
    else:  # a cubic spline reproduces a ramp away from the clamped border
        inner = ((xy > 12) & (xy < [W - 12, H - 12])).all(axis=-1)
        expected = 0.5 * (xy[..., 0] - 0.5) + 0.25 * (xy[..., 1] - 0.5)
        assert inner.sum() > 0.5 * W * H
        np.testing.assert_allclose(out[inner], expected[inner], atol=1e-6)
    assert np.array_equal(np.isnan(out), np.isnan(xy[..., 0]))


# --------------------------------------------------------------------------- outside


def test_pixels_whose_rays_leave_the_photo_are_nan():
    f, cx, cy, k = 220.0, 160.0, 120.0, 0.2  # pincushion: the pinhole's edges lie outside
    photo = np.ones((H, W))
    out = ud.undistort_image(photo, "SIMPLE_RADIAL", [f, cx, cy, k], W, H)
    n = (_centres(W, H) - [cx, cy]) / f
    xd = f * n * (1 + k * (n**2).sum(1, keepdims=True)) + [cx, cy]
    margin = np.minimum.reduce([xd[:, 0], W - xd[:, 0], xd[:, 1], H - xd[:, 1]]).reshape(H, W)
    assert (margin < -1).sum() > 1000 and (margin > 1).sum() > 1000
    assert np.isnan(out[margin < -1e-6]).all()
    # inside, edge pixels extend over the outer half pixel (bilinear weights sum to 1)
    np.testing.assert_allclose(out[margin > 1e-6], 1.0, rtol=0, atol=1e-12)


def test_rays_beyond_the_fold_of_strong_barrel_distortion_are_nan():
    # r_d = r (1 - 0.5 r^2) peaks at r = 1/sqrt(1.5) and comes back into the image
    # beyond it: those rays would show a mirrored ghost of the centre.
    f, cx, cy, k = 110.0, 160.0, 120.0, -0.5
    out = ud.undistort_image(np.ones((H, W)), "SIMPLE_RADIAL", [f, cx, cy, k], W, H)
    r = np.linalg.norm((_centres(W, H) - [cx, cy]) / f, axis=1).reshape(H, W)
    r_fold = 1 / np.sqrt(1.5)
    xd_edge = f * 1.45 * (1 - 0.5 * 1.45**2)  # the corner ray (r ~ 1.82) lands inside
    assert r.max() > 1.8 and abs(xd_edge) < cx
    assert np.isnan(out[r > r_fold + 0.01]).all()
    np.testing.assert_allclose(out[r < r_fold - 0.01], 1.0, rtol=0, atol=1e-12)


@pytest.mark.parametrize("model", ["OPENCV_FISHEYE", "SIMPLE_RADIAL_FISHEYE", "SIMPLE_RADIAL"])
def test_a_wider_lens_covers_the_whole_pinhole_view(model):
    # f tan(theta) > f theta: a fisheye (or barrel) photo sees all its pinhole does
    out = ud.undistort_image(np.full((H, W, 2), 2.0), model, MODELS[model], W, H)
    assert out.shape == (H, W, 2)
    np.testing.assert_allclose(out, 2.0, rtol=0, atol=1e-12)


# --------------------------------------------------------------------------- undistorted cameras


@pytest.mark.parametrize(
    ("model", "params"),
    [
        ("PINHOLE", [250.0, 260.0, 150.3, 121.7]),
        ("SIMPLE_PINHOLE", [250.0, 150.3, 121.7]),
        ("SIMPLE_RADIAL", [250.0, 150.3, 121.7, 0.0]),
        ("OPENCV", [250.0, 260.0, 150.3, 121.7, 0, 0, 0, 0]),
    ],
)
def test_undistorted_camera_returns_the_photo_unchanged(model, params):
    rng = np.random.default_rng(3)
    photo = rng.uniform(0, 5, (H, W, 3))
    photo[5, 7, 1] = np.nan
    assert not ud.is_distorted(model, params)
    out = ud.undistort_image(photo, model, params, W, H)
    assert out.dtype == np.float64 and out is not photo
    np.testing.assert_array_equal(out, photo)
    scaled = ud.undistort_image(np.repeat(np.repeat(photo, 2, 0), 2, 1), model, params, W, H)
    assert scaled.shape == (2 * H, 2 * W, 3)
    # the mapping itself is the identity on pixel centres (no half-pixel slip)
    xy = ud.distorted_positions(model, params, W, H)
    np.testing.assert_allclose(xy.reshape(-1, 2), _centres(W, H), rtol=0, atol=1e-9)


def test_float32_and_float64_inputs_give_the_same_result():
    params = MODELS["OPENCV"]
    photo = _draw_distorted("OPENCV", params, W, H, _smooth).astype(np.float32)
    a = ud.undistort_image(photo, "OPENCV", params, W, H)
    b = ud.undistort_image(photo.astype(np.float64), "OPENCV", params, W, H)
    assert a.dtype == b.dtype == np.float64
    np.testing.assert_array_equal(a, b)


def test_channels_are_undistorted_alike():
    params = MODELS["RADIAL"]
    grey = _draw_distorted("RADIAL", params, W, H, _smooth)
    rgb = np.stack([grey, 2 * grey, -grey], axis=-1)
    out = ud.undistort_image(rgb, "RADIAL", params, W, H)
    one = ud.undistort_image(grey, "RADIAL", params, W, H)
    np.testing.assert_array_equal(out[..., 0], one)
    np.testing.assert_allclose(out[..., 1], 2 * one, rtol=1e-15)
    np.testing.assert_allclose(out[..., 2], -one, rtol=1e-15)


# --------------------------------------------------------------------------- masks


def test_mask_follows_the_pattern_and_is_false_outside():
    model, params = "SIMPLE_RADIAL", MODELS["SIMPLE_RADIAL"]
    centre, radius = np.array([140.0, 110.0]), 60.0

    def disc(px):
        return (np.linalg.norm(px - centre, axis=1) < radius).astype(float)

    mask = _draw_distorted(model, params, W, H, disc) > 0.5
    out = ud.undistort_mask(mask, model, params, W, H)
    assert out.dtype == np.bool_ and out.shape == (H, W)
    d = np.linalg.norm(_centres(W, H) - centre, axis=1).reshape(H, W)
    assert out[d < radius - 1.5].all() and not out[d > radius + 1.5].any()
    assert np.array_equal(out, ud.undistort_mask(mask.astype(np.float32), model, params, W, H))

    model, params = "RADIAL", MODELS["RADIAL"]  # pincushion: the pinhole's corners are outside
    full = ud.undistort_mask(np.ones((H, W), bool), model, params, W, H)
    inside = np.isfinite(ud.undistort_image(np.ones((H, W)), model, params, W, H))
    assert np.array_equal(full, inside) and not full.all() and full.mean() > 0.8


def test_mask_must_be_2d():
    with pytest.raises(ValueError, match="2-D"):
        ud.undistort_mask(np.ones((H, W, 1), bool), "PINHOLE", [200, 200, 160, 120], W, H)


# --------------------------------------------------------------------------- photo size


def test_photo_at_twice_the_camera_size():
    model, params = "OPENCV", MODELS["OPENCV"]
    s = 2
    fx, fy, cx, cy = _pinhole(model, params)
    params2 = [s * fx, s * fy, s * cx, s * cy, *params[4:]]  # COLMAP convention: plain scaling
    cam, px = _scene(model, params)
    ray_px2 = np.column_stack(
        [s * fx * cam[:, 0] / cam[:, 2] + s * cx, s * fy * cam[:, 1] / cam[:, 2] + s * cy]
    )
    photo = _draw_distorted(model, params2, s * W, s * H, _blobs(ray_px2))
    out = ud.undistort_image(photo, model, params, W, H)  # the camera at COLMAP's size
    assert out.shape == (s * H, s * W)
    err = np.linalg.norm(_centroids(out, s * px) - s * px, axis=1)
    assert err.max() < 0.1
    direct = ud.undistort_image(photo, model, params2, s * W, s * H)
    np.testing.assert_allclose(out, direct, rtol=0, atol=1e-12, equal_nan=True)
    half = ud.undistort_image(photo[::2, ::2], model, params2, s * W, s * H)  # and downscaled
    assert half.shape == (H, W)


@pytest.mark.parametrize("shape", [(H, W + 1), (2 * H, 3 * W), (H + 2, W)])
def test_photo_of_another_aspect_is_refused_in_one_sentence(shape):
    with pytest.raises(ValueError, match="COLMAP camera is 320 x 240") as err:
        ud.undistort_image(np.zeros(shape), "OPENCV", MODELS["OPENCV"], W, H)
    assert "\n" not in str(err.value) and str(err.value).count(". ") == 0


@pytest.mark.parametrize(
    ("args", "kwargs", "word"),
    [
        ((np.zeros((H, W)), "NOPE", [1, 2, 3], W, H), {}, "Unknown COLMAP camera model"),
        ((np.zeros((H, W)), "OPENCV", [1, 2, 3], W, H), {}, "takes 8 parameters"),
        ((np.zeros((H, W)), "OPENCV", [np.nan] * 8, W, H), {}, "finite"),
        ((np.zeros((H, W)), "EQUIRECTANGULAR", [W, H], W, H), {}, "not a perspective"),
        ((np.zeros((H, W)), "PINHOLE", [1, 1, 1, 1], W, H), {"order": 6}, "order"),
        ((np.zeros((H, W)), "PINHOLE", [1, 1, 1, 1], W, H), {"order": 1.5}, "order"),
        ((np.zeros(W), "PINHOLE", [1, 1, 1, 1], W, H), {}, "image must be"),
        ((np.zeros((H, W), complex), "PINHOLE", [1, 1, 1, 1], W, H), {}, "real numbers"),
        ((np.zeros((H, W)), "PINHOLE", [1, 1, 1, 1], 0, H), {}, "width"),
    ],
)
def test_bad_input_is_a_one_sentence_value_error(args, kwargs, word):
    with pytest.raises(ValueError, match=word) as err:
        ud.undistort_image(*args, **kwargs)
    assert "\n" not in str(err.value)


# --------------------------------------------------------------------------- model helpers


@pytest.mark.parametrize(
    ("model", "params", "distorted"),
    [
        ("PINHOLE", [1, 2, 3, 4], False),
        ("SIMPLE_RADIAL", [1, 3, 4, 0.0], False),
        ("SIMPLE_RADIAL", [1, 3, 4, -0.01], True),
        ("RADIAL", [1, 3, 4, 0.0, 1e-3], True),
        ("OPENCV", [1, 2, 3, 4, 0, 0, 0, 1e-4], True),
        ("SIMPLE_RADIAL_FISHEYE", [1, 3, 4, 0.0], True),  # a fisheye even without coefficients
        ("OPENCV_FISHEYE", [1, 2, 3, 4, 0, 0, 0, 0], True),
    ],
)
def test_is_distorted_and_pinhole_params(model, params, distorted):
    assert ud.is_distorted(model, params) is distorted
    assert ud.pinhole_params(model, params) == pytest.approx(_pinhole(model, params))
    assert ud.is_distorted is cm.is_distorted and ud.pinhole_params is cm.pinhole_params
