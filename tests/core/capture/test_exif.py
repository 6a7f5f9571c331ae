"""core.capture.exif: exposure, capture time and GPS from OIIO metadata.

Every parser is checked on what OpenImageIO really produces: the metadata are
written into a JPEG or TIFF through OIIO and read back from
``ImageInput.open(path).spec().extra_attribs``. Reference values: the
exposure law (pixel ~ radiance t S / N^2, so one stop of shutter, aperture or
ISO halves k), degrees-minutes-seconds by hand, and the NREL SPA example's
Julian day (2003-10-17 12:30:30 at UTC-7 -> JD 2452930.312847).
"""

import datetime as dt
import math

import numpy as np
import OpenImageIO as oiio
import pytest

from brdf_reconstruct.core.capture import exif, sun

FLOAT3 = oiio.TypeDesc("float[3]")


def _round_trip(tmp_path, ext: str, attributes) -> dict:
    """Write an 8x8 image with `attributes` through OIIO, return the read-back metadata dict."""
    spec = oiio.ImageSpec(8, 8, 3, oiio.UINT8)
    for attribute in attributes:
        spec.attribute(*attribute)
    path = str(tmp_path / f"photo.{ext}")
    out = oiio.ImageOutput.create(path)
    assert out is not None, oiio.geterror()
    assert out.open(path, spec), out.geterror()
    assert out.write_image(np.zeros((8, 8, 3), np.uint8)), out.geterror()
    out.close()
    inp = oiio.ImageInput.open(path)
    assert inp is not None, oiio.geterror()
    metadata = {p.name: p.value for p in inp.spec().extra_attribs}
    inp.close()
    return metadata


CAMERA_JPEG = [
    ("ExposureTime", 1 / 250),
    ("FNumber", 8.0),
    ("Exif:ISOSpeedRatings", 100),
    ("Exif:DateTimeOriginal", "2024:06:21 13:45:10"),
    ("Exif:SubsecTimeOriginal", "25"),
    ("Exif:OffsetTimeOriginal", "+02:00"),
    ("GPS:Latitude", FLOAT3, (33.0, 51.0, 21.6)),
    ("GPS:LatitudeRef", "S"),
    ("GPS:Longitude", FLOAT3, (151.0, 12.0, 36.0)),
    ("GPS:LongitudeRef", "W"),
    ("GPS:Altitude", 58.5),
]


def test_jpeg_round_trip_names_and_types(tmp_path):
    md = _round_trip(tmp_path, "jpg", CAMERA_JPEG)
    # What OIIO 3.0 reports (the module docstring relies on these).
    assert isinstance(md["ExposureTime"], float) and isinstance(md["FNumber"], float)
    assert "Exif:ISOSpeedRatings" not in md  # renamed by OIIO 3.0 ...
    assert md["Exif:PhotographicSensitivity"] == 100  # ... to the EXIF 2.3 name, an int
    assert isinstance(md["Exif:PhotographicSensitivity"], int)
    assert md["Exif:DateTimeOriginal"] == "2024:06:21 13:45:10"
    assert md["Exif:OffsetTimeOriginal"] == "+02:00"
    assert isinstance(md["GPS:Latitude"], tuple) and len(md["GPS:Latitude"]) == 3
    assert md["GPS:LatitudeRef"] == "S" and md["GPS:LongitudeRef"] == "W"
    assert isinstance(md["GPS:Altitude"], float)


def test_jpeg_round_trip_parsed(tmp_path):
    md = _round_trip(tmp_path, "jpg", CAMERA_JPEG)
    e = exif.exposure_settings(md)
    assert e.shutter_s == pytest.approx(1 / 250, rel=1e-6)  # float32 in OIIO
    assert e.f_number == 8.0 and e.iso == 100.0
    assert e.describe() == "1/250 s, f/8, ISO 100"
    when, has_offset = exif.capture_time(md)
    assert has_offset
    tz = dt.timezone(dt.timedelta(hours=2))
    assert when == dt.datetime(2024, 6, 21, 13, 45, 10, 250000, tzinfo=tz)
    assert when.utcoffset() == dt.timedelta(hours=2)
    lat, lon = exif.gps_position(md)
    assert lat == pytest.approx(-(33 + 51 / 60 + 21.6 / 3600), abs=1e-6)  # south
    assert lon == pytest.approx(-(151 + 12 / 60 + 36 / 3600), abs=1e-6)  # west


def test_northern_eastern_gps_round_trip(tmp_path):
    md = _round_trip(tmp_path, "jpg", [
        ("GPS:Latitude", FLOAT3, (48.0, 12.0, 30.0)),
        ("GPS:LatitudeRef", "N"),
        ("GPS:Longitude", FLOAT3, (16.0, 22.0, 0.0)),
        ("GPS:LongitudeRef", "E"),
    ])
    lat, lon = exif.gps_position(md)
    assert lat == pytest.approx(48 + 12 / 60 + 30 / 3600, abs=1e-6)
    assert lon == pytest.approx(16 + 22 / 60, abs=1e-6)


def test_gps_void_status_or_missing_ref_gives_none(tmp_path):
    fix = [("GPS:Latitude", FLOAT3, (10.0, 0.0, 0.0)), ("GPS:Longitude", FLOAT3, (20.0, 0.0, 0.0))]
    refs = [("GPS:LatitudeRef", "N"), ("GPS:LongitudeRef", "E")]
    assert exif.gps_position(_round_trip(tmp_path, "jpg", fix + refs)) == pytest.approx((10, 20))
    void = _round_trip(tmp_path, "jpg", fix + refs + [("GPS:Status", "V")])
    assert void["GPS:Status"] == "V"
    assert exif.gps_position(void) is None
    assert exif.gps_position(_round_trip(tmp_path, "jpg", fix)) is None  # hemisphere unknown
    assert exif.gps_position({}) is None
    bad = {"GPS:Latitude": (95.0, 0.0, 0.0), "GPS:LatitudeRef": "N",
           "GPS:Longitude": (1.0, 0.0, 0.0), "GPS:LongitudeRef": "E"}
    assert exif.gps_position(bad) is None  # latitude out of range
    bad.update({"GPS:Latitude": (10.0, 75.0, 0.0)})
    assert exif.gps_position(bad) is None  # 75 minutes


def test_tiff_round_trip(tmp_path):
    md = _round_trip(tmp_path, "tif", [
        ("ExposureTime", 1 / 60),
        ("FNumber", 5.6),
        ("Exif:PhotographicSensitivity", 400),  # OIIO's TIFF writer drops this tag ...
        ("Exif:ISOSpeed", 400),  # ... but keeps this one
        ("Exif:DateTimeOriginal", "2023:12:24 08:15:00"),
    ])
    assert "Exif:PhotographicSensitivity" not in md and md["Exif:ISOSpeed"] == 400
    assert "DateTime" in md  # the writer stamps its own (current) time here
    e = exif.exposure_settings(md)
    assert e.shutter_s == pytest.approx(1 / 60, rel=1e-6)
    assert e.f_number == pytest.approx(5.6, rel=1e-6) and e.iso == 400.0
    when, has_offset = exif.capture_time(md)
    assert not has_offset and when.tzinfo is None
    assert when == dt.datetime(2023, 12, 24, 8, 15, 0)
    with pytest.raises(ValueError, match="naive"):
        sun.julian_day(when)  # the caller must ask for the offset


def test_tiff_without_original_time_ignores_file_datetime(tmp_path):
    md = _round_trip(tmp_path, "tif", [("FNumber", 4.0)])
    assert "DateTime" in md
    assert exif.capture_time(md) is None
    assert exif.gps_position(md) is None  # OIIO's TIFF writer keeps no GPS
    assert exif.exposure_settings(md) is None  # no shutter, no ISO


def test_capture_time_feeds_the_sun(tmp_path):
    # NREL SPA example: 2003-10-17 12:30:30 local at UTC-7, JD 2452930.312847.
    md = _round_trip(tmp_path, "jpg", [
        ("Exif:DateTimeOriginal", "2003:10:17 12:30:30"),
        ("Exif:OffsetTimeOriginal", "-07:00"),
    ])
    when, has_offset = exif.capture_time(md)
    assert has_offset
    assert sun.julian_day(when) == pytest.approx(2452930.312847, abs=1e-6)


def test_high_iso_overflow_uses_recommended_exposure_index(tmp_path):
    md = _round_trip(tmp_path, "jpg", [
        ("ExposureTime", 1 / 8000), ("FNumber", 2.8),
        ("Exif:PhotographicSensitivity", 65535), ("Exif:SensitivityType", 2),
        ("Exif:RecommendedExposureIndex", 102400),
    ])
    assert md["Exif:PhotographicSensitivity"] == 65535
    e = exif.exposure_settings(md)
    assert e.iso == 102400.0
    assert e.describe() == "1/8000 s, f/2.8, ISO 102400"


def test_apex_fallbacks_round_trip(tmp_path):
    # Tv = 8 -> t = 2^-8 s; Av = 6 -> N = 2^3 = 8.
    md = _round_trip(tmp_path, "jpg", [
        ("Exif:ShutterSpeedValue", 8.0), ("Exif:ApertureValue", 6.0),
        ("Exif:PhotographicSensitivity", 200),
    ])
    assert "ExposureTime" not in md and "FNumber" not in md
    e = exif.exposure_settings(md)
    assert e.shutter_s == pytest.approx(1 / 256, rel=1e-6)
    assert e.f_number == pytest.approx(8.0, rel=1e-6)
    assert e.iso == 200.0


def test_names_are_case_insensitive():
    md = {"exposuretime": 0.01, "fnumber": 2.0, "EXIF:ISOSpeedRatings": 100}
    assert exif.exposure_settings(md) == exif.Exposure(0.01, 2.0, 100.0)


@pytest.mark.parametrize("bad", [
    {"FNumber": 8.0, "Exif:PhotographicSensitivity": 100},
    {"ExposureTime": 0.0, "FNumber": 8.0, "Exif:PhotographicSensitivity": 100},
    {"ExposureTime": -0.01, "FNumber": 8.0, "Exif:PhotographicSensitivity": 100},
    {"ExposureTime": float("nan"), "FNumber": 8.0, "Exif:PhotographicSensitivity": 100},
    {"ExposureTime": 0.01, "FNumber": "f/8", "Exif:PhotographicSensitivity": 100},
    {"ExposureTime": 0.01, "FNumber": 8.0},
    {"ExposureTime": 0.01, "FNumber": 8.0, "Exif:PhotographicSensitivity": 0},
])
def test_missing_or_invalid_exposure_is_none(bad):
    assert exif.exposure_settings(bad) is None


REF = exif.Exposure(1 / 125, 8.0, 100.0)


@pytest.mark.parametrize(("other", "k"), [
    (exif.Exposure(2 / 125, 8.0, 100.0), 0.5),  # double the shutter: half the factor
    (exif.Exposure(1 / 250, 8.0, 100.0), 2.0),
    (exif.Exposure(1 / 125, 8.0 / math.sqrt(2.0), 100.0), 0.5),  # one stop wider
    (exif.Exposure(1 / 125, 8.0 * math.sqrt(2.0), 100.0), 2.0),  # one stop narrower
    (exif.Exposure(1 / 125, 8.0, 200.0), 0.5),  # double the ISO
    (exif.Exposure(1 / 500, 4.0, 100.0), 1.0),  # 2 stops less shutter, 2 stops more aperture
    (exif.Exposure(1 / 500, 4.0, 400.0), 0.25),  # ... and 2 stops more ISO
    (exif.Exposure(1 / 30, 16.0, 100.0), 1.0 / (125 / 30 / 4)),
])
def test_exposure_scale_analytic(other, k):
    scales, notes = exif.exposure_scales([REF, other], [None, None], names=["a.jpg", "b.jpg"])
    assert scales.dtype == np.float64 and scales.shape == (2,)
    assert scales[0] == 1.0
    assert scales[1] == pytest.approx(k, rel=1e-12)
    assert notes[0] == "a.jpg: x1, exposure reference (1/125 s, f/8, ISO 100)"
    assert notes[1].startswith(f"b.jpg: x{k:.4g} from EXIF (")
    assert notes[1].endswith(" vs 1/125 s, f/8, ISO 100)")


def test_exposure_note_text():
    _, notes = exif.exposure_scales(
        [REF, exif.Exposure(1 / 250, 8.0, 100.0)], [None, None], names=["a.jpg", "b.jpg"]
    )
    assert notes[1] == "b.jpg: x2 from EXIF (1/250 s, f/8, ISO 100 vs 1/125 s, f/8, ISO 100)"


def test_scaled_photos_of_one_radiance_agree():
    rng = np.random.default_rng(3)
    radiance = rng.uniform(0.0, 5.0, size=(6, 7, 3))
    exposures = [
        exif.Exposure(1 / 60, 5.6, 100.0),
        exif.Exposure(1 / 250, 2.8, 400.0),
        exif.Exposure(1 / 15, 11.0, 50.0),
        exif.Exposure(0.5, 22.0, 800.0),
    ]
    gain = 0.37  # unknown camera constant, common to all photos
    photos = [radiance * gain * e.shutter_s * e.iso / e.f_number**2 for e in exposures]
    scales, _ = exif.exposure_scales(exposures, [None] * 4)
    for photo, k in zip(photos, scales, strict=True):
        np.testing.assert_allclose(photo * k, photos[0], rtol=1e-12)
    assert not np.allclose(photos[1], photos[0])


def test_reference_is_first_photo_with_exif_and_user_scale_wins():
    e2 = exif.Exposure(1 / 250, 8.0, 100.0)
    # Photo 0 has no EXIF but a user scale; photo 1 is the EXIF reference.
    scales, notes = exif.exposure_scales([None, REF, e2], [3.0, None, None])
    np.testing.assert_allclose(scales, [3.0, 1.0, 2.0])
    assert notes[0] == "photo 1: x3 from the user's exposure scale"
    assert "exposure reference" in notes[1]
    # A user scale beats the photo's own EXIF.
    scales, notes = exif.exposure_scales([REF, e2], [None, 0.7])
    np.testing.assert_allclose(scales, [1.0, 0.7])
    assert "user" in notes[1]


def test_no_exif_at_all_is_equal_exposure_with_a_note():
    scales, notes = exif.exposure_scales([None, None, None], [None, 2.0, None], names="abc")
    np.testing.assert_array_equal(scales, [1.0, 2.0, 1.0])
    assert notes == [
        "a: x1, no exposure EXIF: photos assumed equally exposed",
        "b: x2 from the user's exposure scale",
        "c: x1, no exposure EXIF: photos assumed equally exposed",
    ]
    # All user scales: nothing was assumed.
    scales, notes = exif.exposure_scales([None, REF], [1.5, 0.5])
    np.testing.assert_array_equal(scales, [1.5, 0.5])
    assert len(notes) == 2 and all("user" in note for note in notes)


def test_mixed_exif_is_an_error_naming_the_photo():
    message = r"^b\.jpg has no exposure EXIF .*give its exposure scale$"
    with pytest.raises(ValueError, match=message):
        exif.exposure_scales([REF, None, None], [None, None, None],
                             names=["a.jpg", "b.jpg", "c.jpg"])
    # Giving the missing photos a scale resolves it.
    scales, _ = exif.exposure_scales([REF, None, None], [None, 1.0, 4.0])
    np.testing.assert_array_equal(scales, [1.0, 1.0, 4.0])


@pytest.mark.parametrize("bad", [0.0, -1.0, float("inf"), float("nan"), "2", True])
def test_invalid_user_scale(bad):
    with pytest.raises(ValueError, match="exposure scale of photo 2 must be a finite number > 0"):
        exif.exposure_scales([REF, REF], [None, bad])


def test_length_mismatch():
    with pytest.raises(ValueError, match="one entry per photo"):
        exif.exposure_scales([REF, REF], [None])
    with pytest.raises(ValueError, match="one entry per photo"):
        exif.exposure_scales([REF], [None], names=["a", "b"])


@pytest.mark.parametrize(("text", "hours"), [
    ("+02:00", 2.0), ("-05:30", -5.5), ("+00:00", 0.0), ("+05:45", 5.75), ("-12:00", -12.0),
])
def test_offset_parsing(text, hours):
    md = {"Exif:DateTimeOriginal": "2024:01:02 03:04:05", "Exif:OffsetTimeOriginal": text}
    when, has_offset = exif.capture_time(md)
    assert has_offset
    assert when.utcoffset() == dt.timedelta(hours=hours)
    assert when.replace(tzinfo=None) == dt.datetime(2024, 1, 2, 3, 4, 5)


@pytest.mark.parametrize("text", ["   :  ", "", "+2:00", "+25:00", "UTC", "+02:75", None])
def test_bad_offset_is_treated_as_missing(text):
    md = {"Exif:DateTimeOriginal": "2024:01:02 03:04:05\x00"}
    if text is not None:
        md["Exif:OffsetTimeOriginal"] = text
    assert exif.capture_time(md) == (dt.datetime(2024, 1, 2, 3, 4, 5), False)


@pytest.mark.parametrize("text", ["    :  :     :  :  ", "0000:00:00 00:00:00", "2024-01-02",
                                  "2024:13:02 03:04:05", 20240102])
def test_bad_datetime_is_none(text):
    assert exif.capture_time({"Exif:DateTimeOriginal": text}) is None


def test_digitized_time_is_the_fallback():
    md = {"Exif:DateTimeDigitized": "2022:08:01 18:00:00", "Exif:OffsetTimeDigitized": "-03:00",
          "Exif:OffsetTimeOriginal": "+09:00", "DateTime": "2025:01:01 00:00:00"}
    when, has_offset = exif.capture_time(md)
    assert has_offset
    assert when == dt.datetime(2022, 8, 1, 21, 0, 0, tzinfo=dt.UTC)
