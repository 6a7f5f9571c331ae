"""Photos and masks read as linear floats (core.capture.photo_io; no bpy). The result
pictures are in tests/core/method/test_pictures.py."""

import numpy as np
import OpenImageIO as oiio
import pytest
from image_files import write_image

from brdf_reconstruct.core.capture import photo_io


def test_srgb_decoding_matches_the_standard():
    # IEC 61966-2-1 reference points
    np.testing.assert_allclose(photo_io.srgb_to_linear([0.0, 0.04045, 0.5, 1.0]),
                               [0.0, 0.04045 / 12.92, 0.21404114, 1.0], rtol=1e-7)


def test_png_is_decoded_from_srgb_exr_is_linear(tmp_path):
    rng = np.random.default_rng(0)
    png = rng.integers(0, 256, (5, 7, 3)).astype(np.uint8)
    write_image(tmp_path / "a.png", png, oiio.UINT8)
    np.testing.assert_allclose(photo_io.read_photo(tmp_path / "a.png"),
                               photo_io.srgb_to_linear(png / 255.0), atol=1e-7)
    np.testing.assert_allclose(photo_io.read_photo(tmp_path / "a.png", linear=True),
                               png / 255.0, atol=1e-7)
    exr = rng.random((5, 7, 3)).astype(np.float32) * 40.0
    exr[1, 2, 0] = np.nan
    write_image(tmp_path / "a.exr", exr, oiio.FLOAT)
    back = photo_io.read_photo(tmp_path / "a.exr")
    assert back.dtype == np.float64 and back.shape == (5, 7, 3)
    np.testing.assert_array_equal(back, exr.astype(np.float64))  # NaN kept for observe


def test_grey_image_becomes_rgb(tmp_path):
    grey = np.linspace(0, 1, 12, dtype=np.float32).reshape(3, 4, 1)
    write_image(tmp_path / "g.exr", grey, oiio.FLOAT)
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
    write_image(tmp_path / "m.png", m, oiio.UINT8)
    mask = photo_io.read_mask(tmp_path / "m.png", (4, 6))
    assert mask.sum() == 6 and mask[1, 2] and not mask[0, 0]
    with pytest.raises(ValueError, match="but its photo is 5x5"):
        photo_io.read_mask(tmp_path / "m.png", (5, 5))


# ---------------------------------------------------------------------------
# read_photo_file: photos as cameras produce them



def _png_bytes(path, codes, chunks=()):
    """A PNG written by hand (8-bit RGB or RGBA codes (H, W, 3|4)) with extra chunks."""
    import struct
    import zlib

    def chunk(kind, body):
        return (struct.pack(">I", len(body)) + kind + body
                + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF))

    h, w, c = codes.shape
    raw = b"".join(b"\x00" + codes[y].astype(np.uint8).tobytes() for y in range(h))
    header = struct.pack(">IIBBBBB", w, h, 8, {3: 2, 4: 6}[c], 0, 0, 0)
    extra = b"".join(chunk(kind, body) for kind, body in chunks)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + extra
                     + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


def _gama(gamma_times_100000):
    import struct

    return (b"gAMA", struct.pack(">I", gamma_times_100000))


def _srgb_reference(v):
    """IEC 61966-2-1 decoding written out independently of photo_io."""
    v = np.asarray(v, dtype=np.float64)
    out = v / 12.92
    high = v > 0.04045
    out[high] = ((v[high] + 0.055) / 1.055) ** 2.4
    return out


def test_float_exr_is_linear_with_nan_and_inf_kept_and_counted(tmp_path):
    rng = np.random.default_rng(2)
    exr = (rng.random((6, 8, 3)) * 50.0).astype(np.float32)
    exr[1, 2, 0] = np.nan
    exr[4, 5, 2] = np.inf
    write_image(tmp_path / "f.exr", exr, oiio.FLOAT)
    photo = photo_io.read_photo_file(tmp_path / "f.exr")
    assert photo.radiance.dtype == np.float64 and photo.radiance.shape == (6, 8, 3)
    np.testing.assert_array_equal(photo.radiance, exr.astype(np.float64))
    assert (photo.encoding, photo.encoding_reason) == ("linear", "float EXR is scene-linear")
    assert (photo.file_format, photo.bit_depth, photo.is_float) == ("openexr", 32, True)
    assert photo.white_level is None and not photo.saturated.any()
    assert photo.saturated.shape == (6, 8) and photo.saturated.dtype == bool
    assert photo.nonfinite == 2
    # the lenient entry gives the same float64 values
    np.testing.assert_array_equal(photo_io.read_photo(tmp_path / "f.exr"), photo.radiance)


def test_half_exr_is_linear_and_16_bit(tmp_path):
    values = (np.random.default_rng(3).random((5, 4, 3)) * 8.0).astype(np.float16)
    write_image(tmp_path / "h.exr", values.astype(np.float32), oiio.HALF)
    photo = photo_io.read_photo_file(tmp_path / "h.exr")
    np.testing.assert_array_equal(photo.radiance, values.astype(np.float64))
    assert (photo.bit_depth, photo.is_float, photo.encoding) == (16, True, "linear")


def test_half_exr_beyond_its_range_reads_as_inf_and_is_refused_as_non_finite(tmp_path):
    """Half floats end at 65504: a larger value written to a half EXR is stored as
    Inf, so it reaches the user as the NaN/Inf sentence (photo_checks.check_range
    takes the values a float32 EXR can hold beyond any camera)."""
    values = np.full((4, 4, 3), 0.1, np.float32)
    values[1, 1], values[2, 2, 0], values[3, 0] = 1e30, 7e4, 65504.0
    write_image(tmp_path / "over.exr", values, oiio.HALF)
    photo = photo_io.read_photo_file(tmp_path / "over.exr")
    assert np.isposinf(photo.radiance[1, 1]).all() and np.isposinf(photo.radiance[2, 2, 0])
    assert photo.radiance[3, 0, 0] == 65504.0  # the largest half is kept as it is
    assert photo.nonfinite == 2
    with pytest.raises(ValueError, match="has 2 pixels with NaN or Inf values"):
        photo_io.check_finite(photo, "over.exr")


def test_16_bit_tiff_is_linear_code_over_65535_exactly(tmp_path):
    codes = np.random.default_rng(4).integers(0, 65536, (7, 5, 3)).astype(np.uint16)
    codes[0, 0] = [65535, 0, 12]
    codes[3, 1, 2] = 65535
    write_image(tmp_path / "t16.tif", codes, oiio.UINT16)
    photo = photo_io.read_photo_file(tmp_path / "t16.tif")
    expected = codes.astype(np.float64) / 65535.0
    np.testing.assert_array_equal(photo.radiance, expected)  # float64, not float32-rounded
    assert not np.array_equal(photo.radiance, expected.astype(np.float32).astype(np.float64))
    assert (photo.encoding, photo.encoding_reason) == ("linear", "16-bit TIFF is scene-linear")
    assert (photo.file_format, photo.bit_depth, photo.is_float) == ("tiff", 16, False)
    assert photo.white_level == 1.0
    np.testing.assert_array_equal(photo.saturated, np.any(codes == 65535, axis=-1))
    assert photo.saturated[0, 0] and photo.saturated[3, 1]


def test_float_tiff_is_linear(tmp_path):
    values = (np.random.default_rng(5).random((4, 6, 3)) * 3.0 - 0.5).astype(np.float32)
    write_image(tmp_path / "f.tif", values, oiio.FLOAT)
    photo = photo_io.read_photo_file(tmp_path / "f.tif")
    np.testing.assert_array_equal(photo.radiance, values.astype(np.float64))
    assert (photo.encoding, photo.encoding_reason) == ("linear", "float TIFF is scene-linear")
    assert (photo.file_format, photo.bit_depth, photo.is_float) == ("tiff", 32, True)


def test_8_and_16_bit_png_and_8_bit_tiff_are_decoded_from_srgb(tmp_path):
    rng = np.random.default_rng(6)
    c8 = rng.integers(0, 256, (5, 7, 3)).astype(np.uint8)
    c16 = rng.integers(0, 65536, (5, 7, 3)).astype(np.uint16)
    write_image(tmp_path / "a8.png", c8, oiio.UINT8)
    write_image(tmp_path / "a16.png", c16, oiio.UINT16)
    write_image(tmp_path / "a8.tif", c8, oiio.UINT8)
    p8 = photo_io.read_photo_file(tmp_path / "a8.png")
    p16 = photo_io.read_photo_file(tmp_path / "a16.png")
    t8 = photo_io.read_photo_file(tmp_path / "a8.tif")
    np.testing.assert_allclose(p8.radiance, _srgb_reference(c8 / 255.0), rtol=1e-15, atol=0)
    np.testing.assert_allclose(p16.radiance, _srgb_reference(c16 / 65535.0), rtol=1e-15, atol=0)
    np.testing.assert_allclose(t8.radiance, _srgb_reference(c8 / 255.0), rtol=1e-15, atol=0)
    assert (p8.encoding, p8.encoding_reason, p8.bit_depth) == ("srgb", "8-bit PNG is sRGB", 8)
    assert (p16.encoding, p16.encoding_reason, p16.bit_depth) == ("srgb", "16-bit PNG is sRGB", 16)
    assert (t8.encoding, t8.encoding_reason) == ("srgb", "8-bit TIFF is sRGB")
    assert p8.file_format == "png" and p8.white_level == 1.0 and p16.white_level == 1.0


def test_jpeg_flat_colour_is_decoded_from_srgb(tmp_path):
    colour = np.array([200, 100, 30], dtype=np.uint8)
    write_image(tmp_path / "flat.jpg", np.tile(colour, (16, 16, 1)), oiio.UINT8,
                 {"Compression": "jpeg:100"})
    photo = photo_io.read_photo_file(tmp_path / "flat.jpg")
    assert (photo.file_format, photo.encoding, photo.encoding_reason) == \
        ("jpeg", "srgb", "8-bit JPEG is sRGB")
    # JPEG's colour conversion may move a flat colour by a code or two
    low = _srgb_reference((colour - 2) / 255.0)
    high = _srgb_reference((colour + 2) / 255.0)
    assert np.all(photo.radiance >= low) and np.all(photo.radiance <= high)
    assert not photo.saturated.any()


def test_png_the_file_marks_as_linear_is_not_decoded(tmp_path):
    codes = np.random.default_rng(7).integers(0, 255, (4, 5, 3)).astype(np.uint8)
    # written by OpenImageIO with the attribute: kept in a tEXt chunk (and gAMA 1.0)
    write_image(tmp_path / "lin.png", codes, oiio.UINT8, {"oiio:ColorSpace": "Linear"})
    photo = photo_io.read_photo_file(tmp_path / "lin.png")
    np.testing.assert_array_equal(photo.radiance, codes / 255.0)
    assert (photo.encoding, photo.encoding_reason) == \
        ("linear", "file says linear (oiio:ColorSpace=Linear)")
    # written by hand: only a gAMA chunk of 1.0, which OpenImageIO 3.0 reads as lin_srgb
    _png_bytes(tmp_path / "gamma1.png", codes, [_gama(100000)])
    photo = photo_io.read_photo_file(tmp_path / "gamma1.png")
    np.testing.assert_array_equal(photo.radiance, codes / 255.0)
    assert photo.encoding == "linear" and photo.encoding_reason.startswith("file says linear")
    # gAMA of 1/2.2 is a gamma encoding, not linear: decoded as sRGB
    _png_bytes(tmp_path / "gamma22.png", codes, [_gama(45455)])
    photo = photo_io.read_photo_file(tmp_path / "gamma22.png")
    assert (photo.encoding, photo.encoding_reason) == ("srgb", "8-bit PNG is sRGB")
    # LINEAR is accepted on an 8-bit file that itself says linear
    photo = photo_io.read_photo_file(tmp_path / "lin.png", color_space="linear")
    np.testing.assert_array_equal(photo.radiance, codes / 255.0)


def test_declared_linear_names_and_gamma():
    for space in ["Linear", "linear", "lin_srgb", "lin_rec709", "scene_linear", "ACEScg",
                  "Linear Rec.709", "ACES2065-1", "Linear CIE-XYZ D65"]:
        assert photo_io.declared_linear({"oiio:ColorSpace": space}), space
    for space in ["sRGB", "g22_rec709", "Gamma2", "Non-Color", "non-linear", "", "-", "Rec709"]:
        assert photo_io.declared_linear({"oiio:ColorSpace": space}) is None, space
    assert photo_io.declared_linear({"oiio:Gamma": 1.0}) == "file says linear (oiio:Gamma=1.0)"
    assert photo_io.declared_linear({"oiio:Gamma": 2.2}) is None
    assert photo_io.declared_linear({}) is None


def test_user_srgb_override_on_16_bit_tiff(tmp_path):
    codes = np.random.default_rng(8).integers(0, 65536, (3, 4, 3)).astype(np.uint16)
    write_image(tmp_path / "s.tif", codes, oiio.UINT16)
    photo = photo_io.read_photo_file(tmp_path / "s.tif", color_space="SRGB")
    np.testing.assert_allclose(photo.radiance, _srgb_reference(codes / 65535.0),
                               rtol=1e-15, atol=0)
    assert (photo.encoding, photo.encoding_reason) == ("srgb", "user said sRGB")
    # "srgb" is case-insensitive; a 16-bit file declared linear is fine
    assert photo_io.read_photo_file(tmp_path / "s.tif", color_space="srgb").encoding == "srgb"
    write_image(tmp_path / "s16.png", codes, oiio.UINT16)
    photo = photo_io.read_photo_file(tmp_path / "s16.png", color_space="LINEAR")
    np.testing.assert_array_equal(photo.radiance, codes / 65535.0)
    assert (photo.encoding, photo.encoding_reason) == ("linear", "user said linear")
    with pytest.raises(ValueError, match="must be AUTO, SRGB or LINEAR, not 'rec709'"):
        photo_io.read_photo_file(tmp_path / "s.tif", color_space="rec709")


def test_8_bit_photo_declared_linear_is_one_sentence_error(tmp_path):
    codes = np.full((3, 3, 3), 90, dtype=np.uint8)
    write_image(tmp_path / "a.png", codes, oiio.UINT8)
    write_image(tmp_path / "b.jpg", codes, oiio.UINT8)
    for name in ["a.png", "b.jpg"]:
        with pytest.raises(ValueError) as err:
            photo_io.read_photo_file(tmp_path / name, color_space="LINEAR")
        msg = str(err.value)
        assert f"{name} is 8-bit, which holds sRGB-encoded values, not linear radiance" in msg
        assert "declare it sRGB or export 16-bit/float" in msg and "\n" not in msg


def test_saturation_at_the_largest_code_8_and_16_bit(tmp_path):
    c8 = np.full((4, 5, 3), 120, dtype=np.uint8)
    c8[1, 1, 0] = 255
    c8[2, 3] = 255
    c8[0, 4, 2] = 254  # one code below white: not saturated
    write_image(tmp_path / "s8.png", c8, oiio.UINT8)
    photo = photo_io.read_photo_file(tmp_path / "s8.png")
    expected = np.zeros((4, 5), bool)
    expected[1, 1] = expected[2, 3] = True
    np.testing.assert_array_equal(photo.saturated, expected)
    c16 = np.full((4, 5, 3), 1000, dtype=np.uint16)
    c16[3, 0, 1] = 65535
    c16[0, 0, 2] = 65534
    write_image(tmp_path / "s16.tif", c16, oiio.UINT16)
    photo = photo_io.read_photo_file(tmp_path / "s16.tif")
    expected = np.zeros((4, 5), bool)
    expected[3, 0] = True
    np.testing.assert_array_equal(photo.saturated, expected)
    # a caller's lower level (linear units) is combined with the largest code
    c16[1, 2] = [30000, 40000, 100]  # 40000 / 65535 = 0.61 >= 0.6
    c16[2, 2] = [39000, 39000, 39000]  # 0.595 < 0.6
    write_image(tmp_path / "s16.tif", c16, oiio.UINT16)
    photo = photo_io.read_photo_file(tmp_path / "s16.tif", white_level=0.6)
    expected[1, 2] = True
    expected[0, 0] = True  # 65534 / 65535 is above 0.6 too
    np.testing.assert_array_equal(photo.saturated, expected)
    assert photo.white_level == 0.6


def test_float_saturation_only_with_a_white_level(tmp_path):
    values = np.full((3, 4, 3), 2.0, dtype=np.float32)
    values[0, 1, 1] = 4.0  # at the level: saturated
    values[2, 3] = [5.0, 6.0, 7.0]
    values[1, 1, 0] = 3.999
    values[1, 2, 0] = np.nan  # NaN is not saturated, only non-finite
    write_image(tmp_path / "w.exr", values, oiio.FLOAT)
    assert not photo_io.read_photo_file(tmp_path / "w.exr").saturated.any()
    photo = photo_io.read_photo_file(tmp_path / "w.exr", white_level=4.0)
    expected = np.zeros((3, 4), bool)
    expected[0, 1] = expected[2, 3] = True
    np.testing.assert_array_equal(photo.saturated, expected)
    assert photo.white_level == 4.0 and photo.nonfinite == 1
    for bad in [0.0, -1.0, float("nan"), float("inf")]:
        with pytest.raises(ValueError, match="white level for photo .*w.exr must be a positive"):
            photo_io.read_photo_file(tmp_path / "w.exr", white_level=bad)


def _highlight(noise: float, seed: int = 0) -> np.ndarray:
    """(64, 64, 3) a diffuse level of 0.2 with a Gaussian highlight of 8 on it, its
    colour slightly warm, with relative Gaussian noise."""
    y, x = np.mgrid[0:64, 0:64]
    lobe = np.exp(-((x - 30.0) ** 2 + (y - 34.0) ** 2) / (2 * 6.0**2))
    values = (0.2 + 8.0 * lobe)[..., None] * np.array([1.0, 0.9, 0.8])
    rng = np.random.default_rng(seed)
    return values * (1.0 + noise * rng.standard_normal(values.shape))


@pytest.mark.parametrize("fmt", [oiio.FLOAT, oiio.HALF])
def test_a_float_photo_clipped_at_an_unstated_white_level_is_found_by_its_plateau(
        tmp_path, fmt):
    """A camera's highlight clipped at its white level, written to a float file (a RAW
    converter's EXR), piles up at one value per channel (after white balance, a level
    of each channel's own): found without being told the level, those pixels marked
    as at the file's white level (saturated, as an integer file's largest code) and
    no value changed; not looked for unless asked, nor where the caller gives a
    white level."""
    values = _highlight(0.01)
    levels = np.array([3.0, 2.5, 2.0])
    clipped = np.minimum(values, levels)
    path = write_image(tmp_path / "clipped.exr", clipped.astype(np.float32), fmt)
    stored = photo_io.read_photo_file(path).radiance  # as the file holds it
    photo = photo_io.read_photo_file(path, find_clipping=True)
    np.testing.assert_allclose(photo.plateau, levels, rtol=1e-3)  # half: its rounding
    np.testing.assert_array_equal(photo.saturated, np.any(values >= levels, axis=-1))
    assert 50 < photo.saturated.sum() < 400  # the highlight's core, not the shoulder
    np.testing.assert_array_equal(photo.radiance, stored)  # no value changed
    assert photo_io.read_photo_file(path).plateau is None  # not asked
    assert not photo_io.read_photo_file(path).saturated.any()
    told = photo_io.read_photo_file(path, white_level=10.0, find_clipping=True)
    assert told.plateau is None and not told.saturated.any()  # the caller's level rules


@pytest.mark.parametrize("fmt", [oiio.FLOAT, oiio.HALF])
@pytest.mark.parametrize("noise", [0.0, 0.01])
def test_an_unclipped_float_photo_has_no_plateau(tmp_path, fmt, noise):
    """The same highlight not clipped, noise-free or noisy, in float or half (whose
    10-bit mantissa rounds the values near the peak together): no channel's largest
    value is taken for a white level, and no pixel is saturated."""
    path = write_image(tmp_path / "lit.exr", _highlight(noise).astype(np.float32), fmt)
    photo = photo_io.read_photo_file(path, find_clipping=True)
    assert np.all(np.isnan(photo.plateau)) and not photo.saturated.any()


def test_plateau_levels_needs_a_pile_at_the_top_not_a_few_equal_pixels():
    values = np.zeros((10, 10, 3))
    values[..., :] = np.linspace(0.1, 1.0, 100).reshape(10, 10, 1)
    values[0, :7] = 2.0  # seven at the top: fewer than PLATEAU_PIXELS
    assert np.all(np.isnan(photo_io.plateau_levels(values)))
    values[1, :photo_io.PLATEAU_PIXELS] = 2.0  # a pile: 15 at the top, none just below
    np.testing.assert_array_equal(photo_io.plateau_levels(values), [2.0, 2.0, 2.0])
    values[2:6] = 1.99  # 40 just below the top: a smooth peak, not a clip
    assert np.all(np.isnan(photo_io.plateau_levels(values)))
    values[..., 2] = np.nan  # a channel with no finite value has none
    assert np.isnan(photo_io.plateau_levels(values)[2])


_EXIF = {
    "ExposureTime": 1.0 / 125.0,
    "FNumber": 8.0,
    "Exif:PhotographicSensitivity": 200,
    "Exif:DateTimeOriginal": "2024:06:21 12:30:45",
    "Exif:OffsetTimeOriginal": "+02:00",
    "Exif:FocalLength": 50.0,
    "GPS:Latitude": (48.0, 51.0, 29.5),
    "GPS:LatitudeRef": "N",
    "GPS:Longitude": (2.0, 17.0, 40.25),
    "GPS:LongitudeRef": "E",
    "GPS:Altitude": 35.0,
    "Make": "Canon",
    "Model": "EOS R5",
    "Orientation": 6,
}


def test_jpeg_exif_exposure_date_and_gps_come_back_in_metadata(tmp_path):
    write_image(tmp_path / "m.jpg", np.full((8, 8, 3), 100, np.uint8), oiio.UINT8, _EXIF)
    meta = photo_io.read_photo_file(tmp_path / "m.jpg").metadata
    assert isinstance(meta["ExposureTime"], float)
    assert meta["ExposureTime"] == pytest.approx(1.0 / 125.0, rel=1e-6)
    assert isinstance(meta["FNumber"], float) and meta["FNumber"] == 8.0
    assert isinstance(meta["Exif:PhotographicSensitivity"], int)
    assert meta["Exif:PhotographicSensitivity"] == 200
    assert meta["Exif:DateTimeOriginal"] == "2024:06:21 12:30:45"
    assert meta["Exif:OffsetTimeOriginal"] == "+02:00"
    assert meta["Exif:FocalLength"] == 50.0
    assert isinstance(meta["GPS:Latitude"], tuple) and len(meta["GPS:Latitude"]) == 3
    np.testing.assert_allclose(meta["GPS:Latitude"], (48.0, 51.0, 29.5))
    np.testing.assert_allclose(meta["GPS:Longitude"], (2.0, 17.0, 40.25))
    assert (meta["GPS:LatitudeRef"], meta["GPS:LongitudeRef"]) == ("N", "E")
    assert isinstance(meta["GPS:Altitude"], float) and meta["GPS:Altitude"] == 35.0
    assert (meta["Make"], meta["Model"]) == ("Canon", "EOS R5")
    assert meta["Orientation"] == 6 and isinstance(meta["Orientation"], int)
    # the header-only reader gives the same dict
    assert photo_io.read_metadata(tmp_path / "m.jpg") == meta


def test_tiff_exif_exposure_and_date_come_back_in_metadata(tmp_path):
    # OpenImageIO 3.0's TIFF writer stores the EXIF exposure and date tags but
    # not ISO or GPS, so only those it writes are checked here.
    write_image(tmp_path / "m.tif", np.full((8, 8, 3), 100, np.uint16), oiio.UINT16, _EXIF)
    photo = photo_io.read_photo_file(tmp_path / "m.tif")
    meta = photo.metadata
    assert meta["ExposureTime"] == pytest.approx(1.0 / 125.0, rel=1e-6)
    assert meta["FNumber"] == 8.0 and meta["Exif:FocalLength"] == 50.0
    assert meta["Exif:DateTimeOriginal"] == "2024:06:21 12:30:45"
    assert meta["Orientation"] == 6 and meta["Make"] == "Canon"
    # the EXIF block makes OpenImageIO report sRGB; a 16-bit TIFF stays linear
    assert photo.encoding == "linear"


def test_raw_support_check_matches_the_build():
    assert photo_io.raw_supported() == (
        "raw" in oiio.get_string_attribute("format_list").split(","))


def test_camera_raw_without_libraw_is_one_sentence(tmp_path, monkeypatch):
    monkeypatch.setattr(photo_io, "raw_supported", lambda: False)
    (tmp_path / "IMG_0001.CR2").write_bytes(b"II*\x00" + bytes(200))
    for reader in (photo_io.read_photo_file, photo_io.read_photo, photo_io.read_metadata):
        with pytest.raises(ValueError) as err:
            reader(tmp_path / "IMG_0001.CR2")
        msg = str(err.value)
        assert "camera RAW file" in msg and "IMG_0001.CR2 cannot be read: this OpenImageIO " \
            "build has no RAW (LibRaw) support; convert it to a 16-bit linear TIFF" in msg
        assert "dcraw -4 -T" in msg and "\n" not in msg


def test_camera_raw_with_libraw_is_read_linear(tmp_path, monkeypatch):
    # The LibRaw branch can only be unit-tested by monkeypatching raw_supported():
    # neither the PyPI OpenImageIO nor Blender's has LibRaw. A DNG is TIFF-based,
    # so a 16-bit TIFF named .dng is opened by OpenImageIO's TIFF reader (which
    # ignores the raw:* settings); this checks our RAW handling, not LibRaw.
    monkeypatch.setattr(photo_io, "raw_supported", lambda: True)
    codes = np.random.default_rng(9).integers(0, 65536, (4, 6, 3)).astype(np.uint16)
    codes[2, 2, 1] = 65535
    write_image(tmp_path / "shot.tif", codes, oiio.UINT16)
    (tmp_path / "shot.dng").write_bytes((tmp_path / "shot.tif").read_bytes())
    photo = photo_io.read_photo_file(tmp_path / "shot.dng")
    np.testing.assert_array_equal(photo.radiance, codes / 65535.0)
    assert (photo.encoding, photo.encoding_reason) == \
        ("linear", "camera RAW decoded to linear by LibRaw")
    assert photo.white_level == 1.0
    np.testing.assert_array_equal(photo.saturated, np.any(codes == 65535, axis=-1))
    np.testing.assert_array_equal(photo_io.read_photo(tmp_path / "shot.dng"), photo.radiance)
    # a RAW file the decoder cannot open is the usual one-sentence read error
    (tmp_path / "junk.nef").write_bytes(np.random.default_rng(1).bytes(500))
    with pytest.raises(ValueError, match=r"cannot read image .*junk.nef: \S"):
        photo_io.read_photo_file(tmp_path / "junk.nef")


def _truncated(tmp_path, name, fmt, keep=0.5):
    values = np.random.default_rng(10).random((64, 80, 3)).astype(np.float32)
    write_image(tmp_path / name, values, fmt)
    data = (tmp_path / name).read_bytes()
    (tmp_path / name).write_bytes(data[:int(len(data) * keep)])
    return tmp_path / name


@pytest.mark.parametrize("name, fmt", [("cut.png", oiio.UINT8), ("cut.exr", oiio.HALF),
                                       ("cut.tif", oiio.UINT16), ("cut.jpg", oiio.UINT8)])
def test_truncated_files_are_one_sentence(tmp_path, name, fmt):
    path = _truncated(tmp_path, name, fmt)
    for read in (photo_io.read_photo_file, photo_io.read_photo, photo_io.read_mask):
        with pytest.raises(ValueError) as err:
            read(path)
        msg = str(err.value)
        assert msg.startswith(f"cannot read image {path}: ") and "\n" not in msg
        assert len(msg) > len(f"cannot read image {path}: ")


def test_junk_and_empty_files_are_one_sentence(tmp_path):
    (tmp_path / "junk.exr").write_bytes(np.random.default_rng(11).bytes(1000))
    (tmp_path / "empty.png").write_bytes(b"")
    for name in ["junk.exr", "empty.png"]:
        with pytest.raises(ValueError) as err:
            photo_io.read_photo_file(tmp_path / name)
        msg = str(err.value)
        assert msg.startswith(f"cannot read image {tmp_path / name}: ") and "\n" not in msg
    for read in (photo_io.read_photo_file, photo_io.read_metadata):
        with pytest.raises(ValueError, match="image file not found"):
            read(tmp_path / "missing.exr")
        with pytest.raises(ValueError, match=r"cannot read image .*junk.exr: \S"):
            read(tmp_path / "junk.exr")


def test_rgba_png_keeps_its_own_colour_codes_and_grey_becomes_rgb(tmp_path):
    rgba = np.array([[[200, 100, 50, 128], [255, 0, 10, 0]]], dtype=np.uint8)
    _png_bytes(tmp_path / "rgba.png", rgba)
    photo = photo_io.read_photo_file(tmp_path / "rgba.png")
    np.testing.assert_allclose(photo.radiance, _srgb_reference(rgba[..., :3] / 255.0),
                               rtol=1e-15, atol=0)
    np.testing.assert_array_equal(photo.saturated, [[False, True]])
    grey = np.array([[[10], [255]]], dtype=np.uint16) * 257
    write_image(tmp_path / "grey.tif", grey, oiio.UINT16)
    photo = photo_io.read_photo_file(tmp_path / "grey.tif")
    np.testing.assert_array_equal(photo.radiance, np.repeat(grey / 65535.0, 3, axis=-1))
    np.testing.assert_array_equal(photo.saturated, [[False, True]])


def test_check_finite_counts_bad_pixels_inside_the_mask(tmp_path):
    values = np.ones((4, 5, 3), dtype=np.float32)
    values[0, 0, 0] = np.nan
    values[0, 0, 1] = np.inf  # same pixel: counted once
    values[1, 3, 2] = -np.inf
    values[3, 4, 1] = np.nan
    write_image(tmp_path / "bad.exr", values, oiio.FLOAT)
    photo = photo_io.read_photo_file(tmp_path / "bad.exr")
    assert photo.nonfinite == 3
    with pytest.raises(ValueError) as err:
        photo_io.check_finite(photo, "bad.exr")
    assert str(err.value) == ("photo bad.exr has 3 pixels with NaN or Inf values; "
                              "fix the file or mask them out")
    mask = np.zeros((4, 5), bool)
    mask[1:, :] = True
    with pytest.raises(ValueError, match="has 2 pixels with NaN or Inf values inside its mask"):
        photo_io.check_finite(photo.radiance, "bad.exr", mask)
    mask[3, 4] = False
    with pytest.raises(ValueError, match="has 1 pixel with NaN or Inf values inside its mask"):
        photo_io.check_finite(photo, "bad.exr", mask)
    mask[1, 3] = False
    photo_io.check_finite(photo, "bad.exr", mask)  # all bad pixels masked out
    photo_io.check_finite(np.zeros((4, 5)), "grey")
    with pytest.raises(ValueError, match="mask for photo bad.exr is 4x4 pixels"):
        photo_io.check_finite(photo, "bad.exr", np.ones((4, 4), bool))


def _write_windowed_exr(path, pixels, origin, frame):
    """A float EXR of ``pixels`` (h, w, 3) whose data window at ``origin`` differs from
    its display window ``frame`` (x, y, width, height)."""
    return write_image(path, pixels.astype(np.float32), oiio.FLOAT, origin=origin, frame=frame)


def test_an_exr_holding_part_of_its_frame_is_placed_in_it(tmp_path):
    """A crop (data window 4 x 3 at 5, 2 of a 12 x 8 frame) is read as the 12 x 8 frame,
    each pixel at its place, 0 outside and ``covered`` saying which pixels the file
    holds; overscan (the frame inside a larger data window) is read as the frame with
    ``covered`` None, as is a file whose windows agree."""
    rng = np.random.default_rng(2)
    frame = rng.uniform(0.1, 2.0, size=(8, 12, 3))
    _write_windowed_exr(tmp_path / "crop.exr", frame[2:5, 5:9], (5, 2), (0, 0, 12, 8))
    crop = photo_io.read_photo_file(tmp_path / "crop.exr")
    assert crop.radiance.shape == (8, 12, 3)
    want = np.zeros((8, 12), bool)
    want[2:5, 5:9] = True
    np.testing.assert_array_equal(crop.covered, want)
    np.testing.assert_allclose(crop.radiance[want], frame[want].astype(np.float32), rtol=0)
    assert np.all(crop.radiance[~want] == 0.0)
    padded = np.zeros((12, 16, 3))
    padded[2:10, 2:14] = frame
    _write_windowed_exr(tmp_path / "overscan.exr", padded, (-2, -2), (0, 0, 12, 8))
    over = photo_io.read_photo_file(tmp_path / "overscan.exr")
    assert over.covered is None
    np.testing.assert_allclose(over.radiance, frame.astype(np.float32), rtol=0)
    _write_windowed_exr(tmp_path / "whole.exr", frame, (0, 0), (0, 0, 12, 8))
    assert photo_io.read_photo_file(tmp_path / "whole.exr").covered is None


def test_an_exr_whose_pixels_lie_outside_its_frame_is_one_sentence(tmp_path):
    _write_windowed_exr(tmp_path / "off.exr", np.ones((3, 4, 3)), (40, 40), (0, 0, 12, 8))
    with pytest.raises(ValueError, match="holds no pixel of its frame") as error:
        photo_io.read_photo_file(tmp_path / "off.exr")
    assert "off.exr" in str(error.value) and "\n" not in str(error.value)


def test_display_frame_places_a_window_with_a_shifted_frame_origin():
    """The frame need not start at 0, 0: a data window at (3, 1) in a frame at (2, 0)
    lands one column and one row in."""
    codes = np.arange(2 * 2 * 3).reshape(2, 2, 3)
    out, covered = photo_io.display_frame(codes, (3, 1), (2, 0, 4, 3))
    assert out.shape == (3, 4, 3) and out.dtype == codes.dtype
    np.testing.assert_array_equal(out[1:3, 1:3], codes)
    assert covered.sum() == 4 and covered[1:3, 1:3].all()


def test_a_multilayer_exr_is_read_from_its_combined_layer_not_its_first_pass(tmp_path):
    """Blender's multilayer EXR with an AO pass: the AO layer's channels come first.
    The photo is the Combined layer's R, G, B (before, the first three channels: the
    AO, a wrong photo without a word); its layer is reported."""
    names = ["ViewLayer.AO.R", "ViewLayer.AO.G", "ViewLayer.AO.B", "ViewLayer.Combined.B",
             "ViewLayer.Combined.G", "ViewLayer.Combined.R", "ViewLayer.Combined.A",
             "ViewLayer.Depth.Z"]
    pixels = np.zeros((4, 5, len(names)))
    pixels[..., :3] = 0.9
    pixels[..., 3:8] = (0.3, 0.2, 0.1, 1.0, 7.0)  # Combined B, G, R (this order), A; Z
    write_image(tmp_path / "layers.exr", pixels.astype(np.float32), oiio.FLOAT, names=names)
    photo = photo_io.read_photo_file(tmp_path / "layers.exr")
    np.testing.assert_allclose(photo.radiance, np.broadcast_to(
        np.float32([0.1, 0.2, 0.3]), (4, 5, 3)), rtol=0)
    assert photo.layer == "ViewLayer.Combined"


@pytest.mark.parametrize("names, rgb, layer", [
    (["R", "G", "B", "A"], [0, 1, 2], None),
    (["A", "B", "G", "R"], [3, 2, 1], None),  # EXR's alphabetical order
    (["Y"], None, None),
    (["diffuse.R", "diffuse.G", "diffuse.B"], [0, 1, 2], "diffuse"),  # the one layer
    (["albedo.R", "albedo.G", "albedo.B", "R", "G", "B"], [3, 4, 5], None),
    (["a.beauty.red", "a.beauty.green", "a.beauty.blue", "z.spec.R", "z.spec.G", "z.spec.B"],
     [0, 1, 2], "a.beauty"),
    (["Combined.R", "Combined.G"], None, None),  # no blue: no colour layer
])
def test_colour_channels_by_name(names, rgb, layer):
    assert photo_io.colour_channels(names) == (rgb, layer)


def test_several_colour_layers_and_none_the_image_is_one_sentence(tmp_path):
    names = ["AO.R", "AO.G", "AO.B", "Albedo.R", "Albedo.G", "Albedo.B"]
    write_image(tmp_path / "passes.exr", np.ones((3, 3, 6), np.float32), oiio.FLOAT,
                names=names)
    with pytest.raises(ValueError, match="several colour layers .AO, Albedo.") as error:
        photo_io.read_photo_file(tmp_path / "passes.exr")
    assert "passes.exr" in str(error.value) and "\n" not in str(error.value)
