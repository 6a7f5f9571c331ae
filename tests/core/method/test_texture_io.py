"""Texture files (core.method.texture_io): round trips through the readers photos use."""

import numpy as np
import pytest

from brdf_reconstruct.core.capture import photo_io
from brdf_reconstruct.core.method import texture_io


def _image(seed=0, shape=(12, 20)):
    return np.random.default_rng(seed).uniform(0.0, 1.0, (*shape, 3))


def test_srgb_encoding_inverts_the_decoding():
    x = np.linspace(0.0, 1.0, 1001)
    np.testing.assert_allclose(photo_io.srgb_to_linear(texture_io.linear_to_srgb(x)), x,
                               atol=1e-12)


def test_a_16_bit_png_albedo_reads_back_within_its_quantisation(tmp_path):
    image = _image()
    path = tmp_path / "albedo.png"
    assert texture_io.write_albedo(path, image) == 0
    back = photo_io.read_photo_file(path)  # 16-bit PNG: sRGB, decoded
    assert back.bit_depth == 16 and back.encoding == "srgb"
    np.testing.assert_allclose(back.radiance, image, atol=2e-5)  # 1/65535 in sRGB, or finer
    assert [p.name for p in tmp_path.iterdir()] == ["albedo.png"]  # no temporary left


def test_an_exr_albedo_is_linear_float32_as_given(tmp_path):
    image = _image(1) * 3.0  # above 1 too
    path = tmp_path / "albedo.exr"
    assert texture_io.write_albedo(path, image, "EXR") == 0
    back = photo_io.read_photo_file(path)
    np.testing.assert_array_equal(back.radiance, image.astype(np.float32))


def test_values_outside_0_1_are_clipped_in_a_png_and_counted(tmp_path):
    image = _image(2)
    image[0, 0] = [1.5, 0.2, 0.2]
    image[1, 1] = [-0.1, 0.2, 0.2]
    assert texture_io.write_albedo(tmp_path / "a.png", image) == 2


def test_coverage_round_trip(tmp_path):
    coverage = np.array([[0, 128, 255], [255, 0, 128]], dtype=np.uint8)
    texture_io.write_coverage(tmp_path / "c.png", coverage)
    import OpenImageIO as oiio

    back = oiio.ImageInput.open(str(tmp_path / "c.png"))
    data = back.read_image(format=oiio.UINT8)
    back.close()
    np.testing.assert_array_equal(np.asarray(data)[..., 0], coverage)


@pytest.mark.parametrize("bad, message", [
    (np.full((2, 2, 3), np.nan), "NaN or Inf"), (np.zeros((2, 2)), "shape"),
])
def test_bad_albedo_images_are_refused_and_leave_nothing(tmp_path, bad, message):
    with pytest.raises(ValueError, match=message):
        texture_io.write_albedo(tmp_path / "a.png", bad)
    with pytest.raises(ValueError, match="texture format"):
        texture_io.write_albedo(tmp_path / "a.tif", _image(), "TIFF")
    assert not list(tmp_path.iterdir())
