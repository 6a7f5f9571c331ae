"""Real-capture inputs through the product's path (pip bpy): photos as cameras write
them, their mistakes as one-line errors, exposure, irradiance references, lens
distortion, saturation, the sun from EXIF; on the tiny Cycles scene of
testkit/blender_scene.py (a Lambertian sphere, albedo 0.5, under one Sun)."""

import datetime as dt
import json
import math

import numpy as np
import OpenImageIO as oiio
import pytest

bpy = pytest.importorskip("bpy")

from image_files import write_image  # noqa: E402

from brdf_reconstruct.brdf_addon import (  # noqa: E402
    gathering,
    light_sources,
    photo_input,
    photo_list,
)
from brdf_reconstruct.core.capture import photo_io, sun  # noqa: E402
from testkit import blender_scene as BS  # noqa: E402


@pytest.fixture
def tiny(tiny):
    """The tiny scene, with its photo read as linear radiance."""
    tiny["linear"] = photo_io.read_photo(tiny["photo"])
    return tiny


def _entry(built, path, camera=None):
    """A photo entry for ``path`` seen by the tiny scene's camera, lit by its Sun."""
    p = built["scene"].brdf.photos.add()
    p.name = path.name
    p.filepath = str(path)
    p.camera = built["camera"] if camera is None else camera
    p.light_source, p.sun = "SUN_OBJECT", built["sun"]
    p.irradiance = (BS.lit_irradiance(),) * 3
    return p


def _reconstruct_error(match):
    with pytest.raises(RuntimeError, match=match):
        bpy.ops.brdf.reconstruct()


def _srgb_8bit(linear):
    x = np.clip(linear, 0.0, 1.0)
    encoded = np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
    return np.round(encoded * 255).astype(np.uint8)


# --- each bad input: its own one-line error ---------------------------------------

def test_8bit_photo_declared_linear_is_one_clear_error(tiny):
    path = write_image(tiny["dir"] / "view0.png", _srgb_8bit(tiny["linear"]), oiio.UINT8)
    p = _entry(tiny, path)
    p.color_space = "LINEAR"
    _reconstruct_error(r"view0\.png is 8-bit")


def test_photo_with_no_camera_is_one_clear_error(tiny):
    p = _entry(tiny, tiny["photo"])
    p.camera = None
    _reconstruct_error("Photo view0.exr has no camera")


def test_camera_with_no_photo_is_one_clear_error(tiny):
    p = _entry(tiny, tiny["photo"])
    p.filepath = ""
    _reconstruct_error("Camera view0 has no photo")


def test_resolution_mismatch_is_one_clear_error(tiny):
    path = write_image(tiny["dir"] / "crop.exr", tiny["linear"][:40].astype(np.float32),
                  oiio.FLOAT)
    _entry(tiny, path)
    _reconstruct_error(r"crop\.exr is 48x40 pixels but its camera view0 is 48x48")


def test_a_one_pixel_photo_says_its_size_and_the_cameras(tiny):
    """Issue 13: a 1x1 photo (the same aspect ratio as its 48x48 camera) ended in an
    internal array shape; Blender renders no G-buffer under 4 pixels a side."""
    path = write_image(tiny["dir"] / "dot.exr", tiny["linear"][24:25, 24:25].astype(np.float32),
                       oiio.FLOAT)
    _entry(tiny, path)
    _reconstruct_error(r"^Error: Photo dot\.exr is only 1x1 pixels, but its camera view0 "
                       r"takes 48x48 \(camera\): give the photo at its camera's size \(or "
                       r"scaled, at least 4 pixels a side\)$")
    assert not (tiny["dir"] / "out").exists()


def test_corrupt_file_is_one_clear_error(tiny):
    data = tiny["photo"].read_bytes()
    path = tiny["dir"] / "cut.exr"
    path.write_bytes(data[: len(data) // 3])
    _entry(tiny, path)
    _reconstruct_error(r"Cannot read image .*cut\.exr")


def test_nan_in_an_exr_is_one_clear_error(tiny):
    photo = tiny["linear"].astype(np.float32)
    photo[20:22, 20:23] = np.nan
    path = write_image(tiny["dir"] / "nan.exr", photo, oiio.FLOAT)
    _entry(tiny, path)
    _reconstruct_error(r"nan\.exr has 6 pixels with NaN or Inf")


def test_light_below_every_surface_is_one_clear_error(tiny):
    p = _entry(tiny, tiny["photo"])
    # straight from behind the sphere: every point the camera sees has n.l < 0
    behind = -np.array(tiny["camera"].location) / np.linalg.norm(tiny["camera"].location)
    p.light_source, p.direction = "DIRECTION", behind.tolist()
    _reconstruct_error("below every surface")


# --- what is allowed, and said ----------------------------------------------------

def test_scaled_photo_is_allowed_and_said(tiny):
    twice = np.repeat(np.repeat(tiny["linear"], 2, axis=0), 2, axis=1).astype(np.float32)
    path = write_image(tiny["dir"] / "twice.exr", twice, oiio.FLOAT)
    _entry(tiny, tiny["photo"])
    _entry(tiny, path)
    inputs, capture = gathering.gather_capture(tiny["scene"])
    assert "scaled" not in capture["photos"][0]
    assert inputs[1].photo.shape == (96, 96, 3) and inputs[1].normal.shape == (96, 96, 3)
    assert "2 times its camera's 48x48" in capture["photos"][1]["scaled"]
    # the G-buffers at twice the size see the same sphere: the silhouettes agree
    # but for the outline's pixels
    native = np.repeat(np.repeat(inputs[0].region >= 0, 2, axis=0), 2, axis=1)
    scaled = inputs[1].region >= 0
    assert np.count_nonzero(native ^ scaled) < 0.1 * np.count_nonzero(scaled)


def test_exposure_from_exif_brings_photos_to_one_scale(tiny):
    """The same radiance shot at 1/100 s and at 1/400 s (two stops less light), f/8
    against f/4 (two stops more) and ISO 200 against 100 (one stop more): the second
    file holds twice the first's values; after normalisation they agree."""
    linear = tiny["linear"].astype(np.float32)
    first = write_image(tiny["dir"] / "a.exr", linear, oiio.FLOAT,
                   [("ExposureTime", 0.01), ("FNumber", 8.0),
                    ("Exif:PhotographicSensitivity", 100)])
    second = write_image(tiny["dir"] / "b.exr", linear * 2.0, oiio.FLOAT,
                    [("ExposureTime", 0.0025), ("FNumber", 4.0),
                     ("Exif:PhotographicSensitivity", 200)])
    _entry(tiny, first)
    _entry(tiny, second)
    inputs, capture = gathering.gather_capture(tiny["scene"])
    assert capture["photos"][0]["exposure_scale"] == pytest.approx(1.0)
    # EXIF stores 1/400 s as a float32: the scale is 1/2 to float32 precision
    assert capture["photos"][1]["exposure_scale"] == pytest.approx(0.5, rel=1e-6)
    assert "EXIF" in capture["photos"][1]["exposure"]
    seen = inputs[0].region >= 0
    np.testing.assert_allclose(inputs[1].photo[seen], inputs[0].photo[seen], rtol=1e-6)
    # a user's own scale wins over the EXIF
    tiny["scene"].brdf.photos[1].exposure = 3.0
    inputs, capture = gathering.gather_capture(tiny["scene"])
    assert capture["photos"][1]["exposure_scale"] == pytest.approx(3.0)


def test_irradiance_ratio_from_a_diffuse_region_of_the_scan(tiny):
    """A second photo under 2.5 times the irradiance (the same picture, brighter),
    with the scan's diffuse region as the reference: its irradiance becomes 2.5
    times the first photo's, found from the photos alone."""
    bright = write_image(tiny["dir"] / "bright.exr", (tiny["linear"] * 2.5).astype(np.float32),
                    oiio.FLOAT)
    everywhere = write_image(tiny["dir"] / "all.png", np.full((48, 48, 1), 255, np.uint8),
                        oiio.UINT8)
    for path in (tiny["photo"], bright):
        p = _entry(tiny, path)
        p.reference_kind, p.reference_mask_path = "SCAN", str(everywhere)
    tiny["scene"].brdf.photos[1].irradiance = (1.0, 1.0, 1.0)  # ignored: the reference wins
    inputs, capture = gathering.gather_capture(tiny["scene"])
    # the first photo keeps its own (a float32 property)
    np.testing.assert_allclose(inputs[0].irradiance, BS.lit_irradiance(), rtol=1e-7)
    np.testing.assert_allclose(inputs[1].irradiance, 2.5 * BS.lit_irradiance(), rtol=0.01)


def test_without_references_irradiance_is_assumed_equal_and_said(tiny):
    _entry(tiny, tiny["photo"])
    _, capture = gathering.gather_capture(tiny["scene"])
    assert any("assumed equal" in line for line in capture["irradiance"])


def test_clipped_pixels_of_an_8bit_photo_are_counted_and_used_unless_the_level_leaves_them_out(
        tiny):
    """Exposed 3 times too long, the sphere's bright side clips at 255. Those pixels
    are counted and said, and used at their value (on a blunted scan that gives the
    better table: bench/results/clipping.json); a Saturation Level of 1.0 (the
    file's largest code) leaves them out, counted as saturated. A clipped pixel
    never sets an irradiance reference either way."""
    codes = _srgb_8bit(tiny["linear"] * 3.0)
    path = write_image(tiny["dir"] / "hot.png", codes, oiio.UINT8)
    _entry(tiny, path)
    inputs, capture = gathering.gather_capture(tiny["scene"])
    clipped = np.any(codes == 255, axis=-1) & (inputs[0].region >= 0)
    assert clipped.sum() > 20
    assert capture["photos"][0]["clipped_pixels"] == int(clipped.sum())
    assert capture["photos"][0]["saturated_pixels"] == 0 and not inputs[0].saturated.any()
    assert bpy.ops.brdf.reconstruct() == {"FINISHED"}
    report = json.loads((tiny["dir"] / "out" / "report.json").read_text())
    assert report["photos"][0]["removed"]["saturated"] == 0
    notes = json.loads(tiny["scene"].brdf.capture_notes)  # the Results panel says so
    assert any(line.startswith(f"hot.png: {int(clipped.sum())} pixels on the scan are at "
                               "the file's largest code, a highlight") for line in notes)
    everywhere = write_image(tiny["dir"] / "all.png", np.full((48, 48, 1), 255, np.uint8),
                             oiio.UINT8)
    entry = tiny["scene"].brdf.photos[0]
    entry.reference_kind, entry.reference_mask_path = "SCAN", str(everywhere)
    reference = photo_input.gather_photo(tiny["scene"], entry).reference
    assert int(np.count_nonzero(reference.saturated)) == int(clipped.sum())
    entry.reference_kind = "NONE"
    tiny["scene"].brdf.clip_level = 1.0  # the user's level: left out
    inputs, capture = gathering.gather_capture(tiny["scene"])
    assert capture["photos"][0]["saturated_pixels"] == int(clipped.sum())
    assert capture["photos"][0]["clipped_pixels"] == 0
    np.testing.assert_array_equal(inputs[0].saturated & (inputs[0].region >= 0), clipped)
    assert f"hot.png: {int(clipped.sum())} saturated pixels excluded" in \
        gathering.capture_notes(capture)


def test_a_photo_on_black_with_float_dust_in_its_background_is_read(tiny):
    """An undistorted (resampled) EXR of the object on black holds float dust about
    1e-17 where the background was 0. Its range is checked on the scan's pixels, so
    it runs; before, the dust was the frame's median and every lit pixel was refused
    as 2^32 times it (the camera-inputs bench's lens photos, 2026-12-07)."""
    dusty = tiny["linear"].copy()
    rng = np.random.default_rng(0)
    black = np.all(dusty == 0.0, axis=-1)
    assert black.mean() > 0.5  # the background is most of the frame
    dusty[black] = np.abs(rng.normal(0.0, 1e-17, (int(black.sum()), 3)))
    path = write_image(tiny["dir"] / "dusty.exr", dusty.astype(np.float32), oiio.FLOAT)
    entry = _entry(tiny, path)
    gathered = photo_input.gather_photo(tiny["scene"], entry)
    np.testing.assert_array_equal(gathered.input.photo, dusty.astype(np.float32))


def test_silhouette_margin_shrinks_the_mask(tiny):
    p = _entry(tiny, tiny["photo"])
    inputs, _ = gathering.gather_capture(tiny["scene"])
    assert inputs[0].mask is None
    p.silhouette_margin = 2
    inputs, _ = gathering.gather_capture(tiny["scene"])
    silhouette = inputs[0].region >= 0
    assert inputs[0].mask.sum() < silhouette.sum() and not (inputs[0].mask & ~silhouette).any()
    # two pixels in from a disc of radius r leaves about pi (r - 2)^2
    r = math.sqrt(silhouette.sum() / math.pi)
    assert inputs[0].mask.sum() == pytest.approx(math.pi * (r - 2) ** 2, rel=0.1)


def test_the_pixel_footprint_is_rendered_only_where_a_refit_reads_it(tiny):
    """Pixel Footprint (on in Accurate): 2 x 2 normals per pixel of the sphere, whose
    mean is the pixel's own normal; not rendered when off (Balanced's default), nor
    without a refit (the Paper preset), since only the refits read it."""
    _entry(tiny, tiny["photo"])
    settings = tiny["scene"].brdf
    assert not settings.pixel_footprint  # Balanced
    settings.preset = "ACCURATE"
    assert settings.pixel_footprint and settings.keep_highlight_energy
    inputs, capture = gathering.gather_capture(tiny["scene"])
    fp, g = inputs[0].footprint_normal, inputs[0]
    assert fp.shape == (48, 48, 4, 3) and capture["photos"][0]["pixel_footprint"] == 4
    inner = np.isfinite(fp).all(axis=(2, 3)) & (g.region >= 0)
    assert inner.sum() > 100

    def angle(a, b):
        cos = np.sum(a * b, axis=-1) / np.linalg.norm(a, axis=-1) / np.linalg.norm(b, axis=-1)
        return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))

    spread = angle(fp[inner][:, 0], fp[inner][:, 3])  # a pixel's diagonal points
    off = angle(fp[inner].mean(axis=1), g.normal[inner])
    assert np.median(spread) > 1.0 and np.median(off) < 0.1 * np.median(spread)
    settings.pixel_footprint = False
    inputs, capture = gathering.gather_capture(tiny["scene"])
    assert inputs[0].footprint_normal is None and "pixel_footprint" not in capture["photos"][0]
    settings.preset = "PAPER"  # no refit, and the preset turns the footprint off
    assert not settings.pixel_footprint
    settings.pixel_footprint = True  # on again by hand: still nothing reads it
    assert not settings.keep_highlight_energy and not settings.refine_to_photos
    assert gathering.gather_capture(tiny["scene"])[0][0].footprint_normal is None


def test_a_run_with_the_pixel_footprint_reads_it_and_says_so(tiny):
    """The whole run with Pixel Footprint on (Balanced otherwise): it finishes, the
    report names the 4 points per pixel and the setting, and the table is finite."""
    from brdf_reconstruct.core.brdf import merl

    _entry(tiny, tiny["photo"])
    tiny["scene"].brdf.pixel_footprint = True
    assert bpy.ops.brdf.reconstruct() == {"FINISHED"}
    report = json.loads((tiny["dir"] / "out" / "report.json").read_text())
    assert report["settings"]["pixel_footprint"] is True
    assert report["capture"]["photos"][0]["pixel_footprint"] == 4
    table = merl.read(tiny["dir"] / "out" / "brdf_0.binary")
    assert np.all(np.isfinite(table))


# --- the sun from EXIF and GPS, in a scene whose up is not +Z ---------------------

def test_sun_from_exif_time_and_gps_place(tiny):
    when = dt.datetime(2026, 6, 21, 15, 30, 0, tzinfo=dt.timezone(dt.timedelta(hours=2)))
    lat, lon = 48.1375, -11.575  # 48 8' 15" N, 11 34' 30" W
    path = write_image(tiny["dir"] / "sun.exr", tiny["linear"].astype(np.float32), oiio.FLOAT, [
        ("Exif:DateTimeOriginal", "2026:06:21 15:30:00"), ("Exif:OffsetTimeOriginal", "+02:00"),
        ("GPS:LatitudeRef", "N"), ("GPS:LongitudeRef", "W"),
        ("GPS:Latitude", (48.0, 8.0, 15.0)), ("GPS:Longitude", (11.0, 34.0, 30.0))])
    p = _entry(tiny, path)
    p.light_source, p.time_from_exif, p.place_from_exif = "SUN_POSITION", True, True
    details = {}
    found = light_sources.photo_light(tiny["scene"], p, details)
    np.testing.assert_allclose(found, sun.sun_direction(when, lat, lon), atol=1e-9)
    assert any("EXIF" in note for note in details["notes"])
    # a scene whose sky is +X: the sun's elevation is measured from that up
    tiny["scene"].brdf.scene_up = (1.0, 0.0, 0.0)
    found = light_sources.photo_light(tiny["scene"], p)
    elevation, _ = sun.solar_position(when, lat, lon)
    assert math.asin(found[0]) == pytest.approx(float(elevation), abs=1e-9)


def test_up_from_cameras_of_a_tilted_ring(tiny):
    """Eight cameras on a ring about the world's +Y, all looking at the centre: the
    scene's up is the ring's axis."""
    scene = tiny["scene"]
    for k in range(8):
        a = 2 * math.pi * k / 8
        cam = bpy.data.objects.new(f"ring{k}", bpy.data.cameras.new(f"ring{k}"))
        cam.location = (4 * math.cos(a), 0.8, 4 * math.sin(a))
        cam.rotation_mode = "QUATERNION"
        cam.rotation_quaternion = (-cam.location).to_track_quat("-Z", "Y")
        scene.collection.objects.link(cam)
    bpy.data.objects.remove(scene.objects["view0"])
    up, _ = light_sources.up_from_cameras(scene)
    assert math.degrees(math.acos(np.clip(up @ [0.0, 1.0, 0.0], -1, 1))) < 0.5


def test_distorted_photo_is_undistorted_onto_the_blender_camera(tiny):
    """The tiny render seen through a SIMPLE_RADIAL lens (k = 1.5, about 1.4 px
    outwards at the sphere's outline): after gathering, the photo lines up with the
    pinhole render again."""
    import pycolmap

    f = tiny["camera"].data.lens / tiny["camera"].data.sensor_width * BS.SIZE
    params = [f, BS.SIZE / 2, BS.SIZE / 2, 1.5]
    lens = pycolmap.Camera(model="SIMPLE_RADIAL", width=BS.SIZE, height=BS.SIZE,
                           params=params)
    # the distorted photo: each of its pixel centres looks along cam_from_img, which
    # the pinhole render shows at f * ray + c
    rows, cols = np.indices((BS.SIZE, BS.SIZE), dtype=np.float64)
    ray = lens.cam_from_img(np.column_stack([cols.ravel() + 0.5, rows.ravel() + 0.5]))
    xy = f * np.asarray(ray)[:, :2] + BS.SIZE / 2 - 0.5  # array index of the render
    from scipy import ndimage

    truth = tiny["linear"]
    distorted = np.stack([ndimage.map_coordinates(truth[..., c], [xy[:, 1], xy[:, 0]],
                                                  order=1, mode="nearest")
                          for c in range(3)], axis=-1).reshape(truth.shape)
    path = write_image(tiny["dir"] / "lens.exr", distorted.astype(np.float32), oiio.FLOAT)
    cam = tiny["camera"]
    cam["brdf_colmap_distorted"], cam["brdf_colmap_camera_model"] = True, "SIMPLE_RADIAL"
    cam["brdf_colmap_params"] = params
    _entry(tiny, path)
    inputs, capture = gathering.gather_capture(tiny["scene"])
    assert capture["photos"][0]["undistorted"].startswith("SIMPLE_RADIAL")
    # away from the outline, where resampling the edge twice blurs it whatever the lens
    inside = ndimage.binary_erosion(inputs[0].region >= 0, iterations=3)
    inside &= np.all(np.isfinite(inputs[0].photo), axis=-1)
    before = np.abs(distorted - truth)[inside].mean()
    after = np.abs(inputs[0].photo - truth)[inside].mean()
    assert after < 0.25 * before, (after, before)
    # the image's scale about the principal point is the pinhole's again: the
    # radiance-weighted RMS radius (resampling blur moves it by ~0.02 px only)
    def rms_radius(photo):
        lum = np.nan_to_num(photo).sum(axis=-1)
        r2 = (rows + 0.5 - BS.SIZE / 2) ** 2 + (cols + 0.5 - BS.SIZE / 2) ** 2
        return math.sqrt((lum * r2).sum() / lum.sum())

    grown = rms_radius(distorted) - rms_radius(truth)
    assert grown > 0.3  # k > 0 pushes the image outwards, measurably
    assert abs(rms_radius(inputs[0].photo) - rms_radius(truth)) < 0.1 * grown


def test_cameras_from_another_importer_use_the_scene_render_size(tiny):
    """The Photogrammetry Importer route (Meshroom, Metashape, ...): a camera object
    named after its image, no COLMAP properties, the scene's render size set to the
    photo's. A photo finds it by name; a photo of another aspect ratio is refused
    with the size's source named."""
    camera = tiny["camera"]
    for key in ("brdf_image_name", "brdf_width", "brdf_height"):
        del camera[key]
    camera.name = "view0.jpg"
    added, unmatched = photo_list.add_photos(tiny["scene"], [str(tiny["photo"])])
    assert unmatched == [] and added[0].camera == camera
    inputs, capture = gathering.gather_capture(tiny["scene"])
    assert inputs[0].photo.shape == (48, 48, 3) and "scaled" not in capture["photos"][0]
    tiny["scene"].render.resolution_x = 64  # 64 x 48 is not the photo's 48 x 48
    with pytest.raises(ValueError, match=r"48x48 pixels but its camera view0\.jpg is 64x48 "
                                         r"\(scene render size\)"):
        gathering.gather_capture(tiny["scene"])


def test_a_new_photo_takes_the_last_ones_light_with_its_date_and_place(tiny):
    first = _entry(tiny, tiny["photo"])
    first.light_source, first.when, first.latitude = "SUN_POSITION", "2026-03-01 10:00:00", 35.0
    first.place_from_exif, first.color_space = True, "SRGB"
    other = tiny["dir"] / "view0_b.exr"
    other.write_bytes(tiny["photo"].read_bytes())
    tiny["camera"]["brdf_image_name"] = "view0_b.jpg"
    (added,), unmatched = photo_list.add_photos(tiny["scene"], [str(other)])
    assert unmatched == []
    assert (added.light_source, added.when, added.latitude, added.place_from_exif,
            added.color_space) == ("SUN_POSITION", "2026-03-01 10:00:00", 35.0, True, "SRGB")


def test_a_distorted_camera_without_lens_parameters_is_one_clear_error(tiny):
    """A camera imported before the lens parameters were stored: flagged distorted,
    nothing to undistort with."""
    cam = tiny["camera"]
    cam["brdf_colmap_distorted"], cam["brdf_colmap_camera_model"] = True, "OPENCV"
    _entry(tiny, tiny["photo"])
    with pytest.raises(ValueError, match="no stored lens parameters; import its COLMAP"):
        gathering.gather_capture(tiny["scene"])
