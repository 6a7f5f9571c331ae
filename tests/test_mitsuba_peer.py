"""Conventions of the Mitsuba 3 peer (testkit/mitsuba_peer.py); skipped without mitsuba.

Mitsuba is a dev-only extra (requirements-bench.txt). These checks take a few
seconds: the emitter's irradiance, the tabulation's wi/wo roles and cosine, and
the COLMAP -> Mitsuba camera conversion with an off-centre principal point.
"""

import pathlib

import numpy as np
import pytest

pytest.importorskip("mitsuba")

from testkit import mitsuba_peer  # noqa: E402

try:
    mitsuba_peer.mitsuba()
except ImportError as error:  # no libLLVM >= 17 on this machine
    pytest.skip(str(error), allow_module_level=True)


def test_directional_irradiance_gives_albedo_over_pi():
    check = mitsuba_peer.check_irradiance(albedo=0.5, incidence_deg=60.0)
    assert check["max_rel_error"] < 1e-4


def test_tabulation_of_diffuse_and_principled():
    check = mitsuba_peer.check_tabulation()
    assert check["diffuse_max_rel_error"] < 1e-5
    # trilinear lookup of the table reproduces the BSDF; nearest adds the grid's
    # own quantisation (a few % at roughness 0.3)
    assert check["sphere_rel_rmse"]["trilinear"] < 0.01
    assert check["sphere_rel_rmse"]["nearest"] < 0.06


def _camera(width=64, height=48):
    from brdf_reconstruct.core.capture import cameras, colmap

    R, t = cameras.look_at(np.array([3.0, -1.0, 1.0]), np.zeros(3))
    return colmap.ColmapImage(
        image_id=1, name="a.png", camera_id=1, width=width, height=height, fx=70.0, fy=70.0,
        cx=0.4 * width, cy=0.6 * height, camera_model="PINHOLE", distorted=False,
        R_cam_from_world=R, t_cam_from_world=t)


def test_camera_conversion_rays_and_silhouette():
    mi, _ = mitsuba_peer.mitsuba()
    cam = _camera()
    centre, radius = np.array([0.0, 0.8, 0.3]), 0.4  # off-centre: mirroring shows
    scene = mi.load_dict({"type": "scene", "sensor": mitsuba_peer.sensor_dict(cam, 1),
                          "ball": {"type": "sphere", "center": centre.tolist(),
                                   "radius": radius}})
    # expected coverage: COLMAP back-projected pixel-centre rays that pass the ball
    ys, xs = np.mgrid[0:cam.height, 0:cam.width] + 0.5
    k = np.stack([(xs - cam.cx) / cam.fx, (ys - cam.cy) / cam.fy, np.ones_like(xs)], -1)
    d = k @ cam.R_cam_from_world
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    to_c = centre - cam.centre
    miss = np.linalg.norm(np.cross(to_c, d), axis=-1)
    covered = (miss < radius).astype(float)
    photo = mitsuba_peer.Photo(pathlib.Path("a.exr"), np.zeros((cam.height, cam.width, 3)),
                               covered, cam, np.array([0.0, 0.0, 1.0]), np.ones(3))
    capture = mitsuba_peer.Capture(pathlib.Path("."), pathlib.Path("none.ply"), [photo])
    check = mitsuba_peer.camera_check(scene, capture)
    assert check["max_ray_angle_deg"] < 1e-3
    assert check["max_ray_centre_distance"] < 1e-4
    assert check["iou_alpha"][0] > 0.97
    assert check["iou_mirrored"][0] < 0.8
