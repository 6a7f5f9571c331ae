"""COLMAP reading (core.capture.colmap; no bpy): binary, text and pre-3.12 models,
their errors, the camera models' parameters. The camera conventions are in
test_cameras.py.
"""

import os

import numpy as np
import pytest

from brdf_reconstruct.core.capture import cameras as camconv
from brdf_reconstruct.core.capture import colmap as cm
from testkit import synthetic

pycolmap = pytest.importorskip("pycolmap")


def _project(fx, fy, cx, cy, w, h, R, t, xyz):
    """Pixels of COLMAP points through the Blender camera (test_cameras.py checks it)."""
    intr = camconv.blender_intrinsics(fx, fy, cx, cy, w, h)
    return camconv.project_blender(camconv.camera_to_world(R, t), intr, xyz)


# --------------------------------------------------------------------------- reading


def _views():
    R1, t1 = camconv.look_at([4, 0, 1], [0, 0, 0])
    R2, t2 = camconv.look_at([0, 4, 1], [0, 0, 0])
    R3, t3 = camconv.look_at([-3, -3, 2], [0, 0, 0])
    return [
        ("b.jpg", "SIMPLE_PINHOLE", [700, 240, 330], 480, 640, R2, t2),
        ("a.jpg", "PINHOLE", [800, 860, 300, 260], 640, 480, R1, t1),
        ("sub/c.jpg", "OPENCV", [700, 700, 250, 200, 0.01, 0, 0, 0], 500, 400, R3, t3),
    ]


@pytest.fixture(scope="module")
def model_dirs(tmp_path_factory):
    rng = np.random.default_rng(0)
    xyz = rng.uniform(-1, 1, (200, 3))
    rgb = rng.integers(0, 256, (200, 3), dtype=np.uint8)
    rec = synthetic.synthetic_reconstruction(_views(), xyz, rgb)
    root = tmp_path_factory.mktemp("colmap")
    dirs = {}
    for kind in ("bin", "txt", "legacy"):
        d = root / kind
        d.mkdir()
        (rec.write_text if kind != "bin" else rec.write)(str(d))
        if kind == "legacy":  # COLMAP < 3.12 writes no rigs / frames
            for f in d.iterdir():
                if f.stem in ("rigs", "frames"):
                    f.unlink()
        dirs[kind] = d
    return dirs, xyz, rgb


@pytest.mark.parametrize("kind", ["bin", "txt", "legacy"])
def test_read_model(model_dirs, kind):
    dirs, xyz, rgb = model_dirs
    model = cm.read_model(dirs[kind], observations=True)
    assert [im.name for im in model.images] == ["a.jpg", "b.jpg", "sub/c.jpg"]
    a, b, c = model.images
    assert (a.width, a.height, a.fx, a.fy, a.cx, a.cy) == (640, 480, 800, 860, 300, 260)
    assert (b.width, b.height, b.fx, b.fy, b.cx, b.cy) == (480, 640, 700, 700, 240, 330)
    assert (a.camera_model, b.camera_model, c.camera_model) == (
        "PINHOLE",
        "SIMPLE_PINHOLE",
        "OPENCV",
    )
    assert (a.distorted, b.distorted, c.distorted) == (False, False, True)
    np.testing.assert_allclose(a.centre, [4, 0, 1], atol=1e-12)
    order = np.argsort(model.point_ids)
    np.testing.assert_allclose(model.xyz[order], xyz, atol=1e-12)
    np.testing.assert_array_equal(model.rgb[order], rgb)
    lookup = dict(zip(model.point_ids.tolist(), model.xyz, strict=True))
    for im in (a, b):  # undistorted: the Blender-convention model reproduces COLMAP exactly
        assert len(im.point3D_ids) > 150
        pts = np.array([lookup[i] for i in im.point3D_ids.tolist()])
        intr = (im.fx, im.fy, im.cx, im.cy, im.width, im.height)
        px = _project(*intr, im.R_cam_from_world, im.t_cam_from_world, pts)
        np.testing.assert_allclose(px, im.points2D, atol=1e-8)


def test_read_model_without_observations(model_dirs):
    model = cm.read_model(model_dirs[0]["bin"])
    assert all(im.points2D is None and im.point3D_ids is None for im in model.images)


def test_read_model_accepts_a_file_inside(model_dirs):
    model = cm.read_model(model_dirs[0]["txt"] / "cameras.txt")
    assert len(model.images) == 3


def test_missing_folder(tmp_path):
    with pytest.raises(ValueError, match="folder not found") as err:
        cm.read_model(tmp_path / "nope")
    assert "\n" not in str(err.value)


def test_folder_without_model_hints_at_subfolder(tmp_path, model_dirs):
    with pytest.raises(ValueError, match="No COLMAP model"):
        cm.read_model(tmp_path)
    parent = tmp_path / "sparse"
    parent.mkdir()
    os.symlink(model_dirs[0]["bin"], parent / "0", target_is_directory=True)
    with pytest.raises(ValueError, match="did you mean"):
        cm.read_model(parent)


def test_unreadable_model(tmp_path):
    (tmp_path / "cameras.txt").write_text("1 PINHOLE 640\n")
    (tmp_path / "images.txt").write_text("")
    (tmp_path / "points3D.txt").write_text("")
    with pytest.raises(ValueError, match="Could not read the COLMAP model") as err:
        cm.read_model(tmp_path)
    assert "\n" not in str(err.value)


def test_model_without_registered_images(tmp_path):
    for f in ("cameras", "images", "points3D"):
        (tmp_path / f"{f}.txt").write_text("")
    with pytest.raises(ValueError, match="no registered images"):
        cm.read_model(tmp_path)


def test_fisheye_is_flagged_and_spherical_rejected(tmp_path):
    R, t = camconv.look_at([4, 0, 1], [0, 0, 0])
    fisheye = [("f.jpg", "SIMPLE_RADIAL_FISHEYE", [500, 320, 240, 0.0], 640, 480, R, t)]
    (tmp_path / "f").mkdir()
    (tmp_path / "s").mkdir()
    synthetic.synthetic_reconstruction(fisheye, np.zeros((0, 3))).write(str(tmp_path / "f"))
    (im,) = cm.read_model(tmp_path / "f").images
    assert im.distorted  # a fisheye is not a pinhole even with zero coefficients
    sphere = [("s.jpg", "EQUIRECTANGULAR", [640, 320], 640, 320, R, t)]
    synthetic.synthetic_reconstruction(sphere, np.zeros((0, 3))).write(str(tmp_path / "s"))
    with pytest.raises(ValueError, match="EQUIRECTANGULAR"):
        cm.read_model(tmp_path / "s")


def test_records_carry_the_model_params_and_the_helpers_agree(model_dirs):
    model = cm.read_model(model_dirs[0]["txt"])
    by_name = {v[0]: v for v in _views()}
    for im in model.images:
        _, name, params, *_ = by_name[im.name]
        assert im.camera_model == name
        assert im.params == tuple(float(p) for p in params)
        assert all(isinstance(p, float) for p in im.params)
        assert cm.pinhole_params(im.camera_model, im.params) == (im.fx, im.fy, im.cx, im.cy)
        assert cm.is_distorted(im.camera_model, im.params) == im.distorted


@pytest.mark.parametrize(
    ("model", "params", "expected"),
    [
        ("SIMPLE_PINHOLE", [700, 240, 330], (700, 700, 240, 330)),
        ("RADIAL", [650, 250, 190, 0.1, 0.0], (650, 650, 250, 190)),
        ("FULL_OPENCV", [700, 720, 250, 200, *[0.0] * 8], (700, 720, 250, 200)),
        ("OPENCV_FISHEYE", [300, 310, 250, 200, 0.1, 0, 0, 0], (300, 310, 250, 200)),
        ("RADIAL_FISHEYE", [300, 250, 200, 0.0, 0.0], (300, 300, 250, 200)),
    ],
)
def test_pinhole_params_of_any_model(model, params, expected):
    assert cm.pinhole_params(model, params) == expected


def test_camera_model_helpers_reject_bad_input():
    with pytest.raises(ValueError, match="Unknown COLMAP camera model 'OPENCVX'"):
        cm.is_distorted("OPENCVX", [1, 2, 3, 4])
    with pytest.raises(ValueError, match="takes 4 parameters") as err:
        cm.pinhole_params("PINHOLE", [1, 2, 3])
    assert "\n" not in str(err.value)
    with pytest.raises(ValueError, match="finite"):
        cm.pycolmap_camera("PINHOLE", [1, 2, np.inf, 4])
