"""Photos and masks read as linear floats; result pictures (no bpy)."""

import numpy as np
import OpenImageIO as oiio
import pytest

from brdf_reconstruct.core import database, photo_io, pictures


def _write(path, pixels, fmt):
    h, w, c = pixels.shape
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), oiio.ImageSpec(w, h, c, fmt))
    out.write_image(pixels)
    out.close()


def test_srgb_decoding_matches_the_standard():
    # IEC 61966-2-1 reference points
    np.testing.assert_allclose(photo_io.srgb_to_linear([0.0, 0.04045, 0.5, 1.0]),
                               [0.0, 0.04045 / 12.92, 0.21404114, 1.0], rtol=1e-7)


def test_png_is_decoded_from_srgb_exr_is_linear(tmp_path):
    rng = np.random.default_rng(0)
    png = rng.integers(0, 256, (5, 7, 3)).astype(np.uint8)
    _write(tmp_path / "a.png", png, oiio.UINT8)
    np.testing.assert_allclose(photo_io.read_photo(tmp_path / "a.png"),
                               photo_io.srgb_to_linear(png / 255.0), atol=1e-7)
    np.testing.assert_allclose(photo_io.read_photo(tmp_path / "a.png", linear=True),
                               png / 255.0, atol=1e-7)
    exr = rng.random((5, 7, 3)).astype(np.float32) * 40.0
    exr[1, 2, 0] = np.nan
    _write(tmp_path / "a.exr", exr, oiio.FLOAT)
    back = photo_io.read_photo(tmp_path / "a.exr")
    assert back.dtype == np.float64 and back.shape == (5, 7, 3)
    np.testing.assert_array_equal(back, exr.astype(np.float64))  # NaN kept for observe


def test_grey_image_becomes_rgb(tmp_path):
    grey = np.linspace(0, 1, 12, dtype=np.float32).reshape(3, 4, 1)
    _write(tmp_path / "g.exr", grey, oiio.FLOAT)
    rgb = photo_io.read_photo(tmp_path / "g.exr")
    assert rgb.shape == (3, 4, 3) and np.all(rgb[..., 0] == rgb[..., 2])


def test_bad_files_are_one_sentence(tmp_path):
    with pytest.raises(ValueError, match="image file not found"):
        photo_io.read_photo(tmp_path / "nope.exr")
    (tmp_path / "corrupt.png").write_bytes(b"not a png at all")
    with pytest.raises(ValueError, match="cannot read image"):
        photo_io.read_photo(tmp_path / "corrupt.png")


def test_mask_size_must_match_the_photo(tmp_path):
    m = np.zeros((4, 6, 1), dtype=np.uint8)
    m[1:3, 2:5] = 255
    _write(tmp_path / "m.png", m, oiio.UINT8)
    mask = photo_io.read_mask(tmp_path / "m.png", (4, 6))
    assert mask.sum() == 6 and mask[1, 2] and not mask[0, 0]
    with pytest.raises(ValueError, match="but its photo is 5x5"):
        photo_io.read_mask(tmp_path / "m.png", (5, 5))


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
