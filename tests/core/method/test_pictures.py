"""The result pictures (core.method.pictures): the BRDF slice, photo against render,
the reliable-pixel overlay, written as PNG (no bpy)."""

import numpy as np

from brdf_reconstruct.core.brdf import database
from brdf_reconstruct.core.capture import photo_io
from brdf_reconstruct.core.method import pictures


def test_slice_picture_is_finite_and_brightest_at_the_specular_peak():
    spec = next(s for s in database.heldout_specs() if s["name"] == "heldout_gold_medium")
    pic = pictures.slice_image(database.make_table(spec), scale=1)
    assert pic.shape == (90, 90, 3) and np.all(np.isfinite(pic))
    assert 0.0 <= pic.min() and pic.max() <= 1.0
    assert np.unravel_index(np.argmax(pic[..., 1]), (90, 90))[1] < 5  # theta_h ~ 0


def test_photo_vs_render_round_trip_png(tmp_path):
    photo = np.random.default_rng(1).random((6, 5, 3))
    pic = pictures.photo_vs_render(photo, photo * 0.5, np.ones((6, 5), bool), gap=2)
    assert pic.shape == (6, 12, 3)
    pictures.write_png(tmp_path / "p.png", pic)
    back = photo_io.read_photo(tmp_path / "p.png", linear=True)
    np.testing.assert_allclose(back, pic, atol=0.5 / 255 + 1e-6)


def test_reliable_overlay_colours_kept_and_dropped_pixels():
    photo = np.full((4, 5, 3), 0.5)
    pic = pictures.reliable_overlay(photo, np.array([[1, 1], [2, 3]]), np.array([[1, 1]]))
    assert pic.shape == (4, 5, 3) and np.all(np.isfinite(pic))
    assert pic[1, 1, 1] > pic[1, 1, 0]  # kept: green
    assert pic[2, 3, 0] > pic[2, 3, 1]  # dropped: red
    assert pic[0, 0, 0] == pic[0, 0, 1] == pic[0, 0, 2]  # not observed: grey
