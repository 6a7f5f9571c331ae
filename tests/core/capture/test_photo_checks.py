"""Photos that cannot be right (core.capture.photo_checks; no bpy): black photos,
values no camera records, tiny photos, and photos whose light is not the one their
G-buffer was rendered with. The scenes are numpy spheres seen orthographically,
shaded by the physics the checks rely on (Lambert or a narrow mirror lobe, plus
an ambient term that reaches shadowed and lit pixels alike), not by the checks."""

import math

import numpy as np
import OpenImageIO as oiio
import pytest
from image_files import write_image

from brdf_reconstruct.core.capture import photo_checks, photo_io

SIZE, RADIUS = 64, 28


def _unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def _sphere():
    """Normals (H, W, 3) of a sphere filling a disc, viewed along -z (camera at +z),
    x to the right and y up; region 0 on it, -1 around."""
    rows, cols = np.indices((SIZE, SIZE), dtype=np.float64)
    x = (cols + 0.5 - SIZE / 2) / RADIUS
    y = (SIZE / 2 - rows - 0.5) / RADIUS
    inside = x ** 2 + y ** 2 < 1.0
    z = np.sqrt(np.clip(1.0 - x ** 2 - y ** 2, 0.0, None))
    normal = np.where(inside[..., None], np.stack([x, y, z], axis=-1), 0.0)
    return normal, np.where(inside, 0, -1)


def _gbuffer(light, shadow=None):
    """(normal, cosine, visibility, region) of the sphere under ``light``; ``shadow``:
    an (H, W) bool of cast shadow on top of the attached one."""
    normal, region = _sphere()
    cosine = normal @ _unit(light)
    visibility = ((cosine > 0) & (region >= 0)).astype(np.float64)
    if shadow is not None:
        visibility[shadow] = 0.0
    return normal, cosine, visibility, region


def _lambert(normal, region, light, albedo=0.5, ambient=0.0, shadow=None):
    """(H, W, 3) radiance of a Lambertian sphere under a distant light of irradiance
    pi, plus ``ambient`` times pi of irradiance from everywhere."""
    cosine = np.clip(normal @ _unit(light), 0.0, None)
    if shadow is not None:
        cosine = np.where(shadow, 0.0, cosine)
    albedo = np.broadcast_to(np.asarray(albedo, dtype=np.float64), region.shape)
    y = np.where(region >= 0, albedo * (cosine + ambient), 0.0)
    return np.repeat(y[..., None], 3, axis=-1)


def _disc(center_rc, radius):
    rows, cols = np.indices((SIZE, SIZE))
    return (rows - center_rc[0]) ** 2 + (cols - center_rc[1]) ** 2 <= radius ** 2


LIGHT = _unit([0.6, 0.3, 0.74])  # from the right, above, towards the camera
# a cast shadow on the lit side (as if another part of the scan stood in the light)
CAST = _disc((40, 42), 6)  # 13 pixels from the highlight of LIGHT


def _check(photo, light, shadow=None, usable=None):
    normal, cosine, visibility, region = _gbuffer(light, shadow)
    usable = region >= 0 if usable is None else usable
    c = photo_checks.light_consistency(photo, cosine, visibility, region, usable)
    return c, photo_checks.check_light(c, "p.exr")


# --- a photo too small, black, or beyond what a camera records -------------------

def test_a_photo_under_four_pixels_a_side_is_one_sentence_with_both_sizes():
    with pytest.raises(ValueError, match=r"^photo p\.exr is only 1x1 pixels, but its camera "
                                         r"view0 takes 48x48 \(camera\): give the photo"):
        photo_checks.check_photo_size("p.exr", (1, 1), "view0", (48, 48), "camera")
    with pytest.raises(ValueError, match="only 12x3 pixels"):
        photo_checks.check_photo_size("p.exr", (12, 3), "view0", (48, 12), "camera")
    photo_checks.check_photo_size("p.exr", (4, 4), "view0", (48, 48), "camera")  # Blender's least


def test_an_all_black_photo_is_refused():
    with pytest.raises(ValueError, match=r"^photo p\.exr is black \(no pixel above 0\)"):
        photo_checks.check_not_black(np.zeros((8, 8, 3)), "p.exr")
    with pytest.raises(ValueError, match="is black"):  # negative values are no light either
        photo_checks.check_not_black(np.full((8, 8, 3), -0.1), "p.exr")
    one = np.zeros((8, 8, 3))
    one[2, 3, 1] = 1e-6
    photo_checks.check_not_black(one, "p.exr")  # one pixel of light is a photo
    mask = np.zeros((8, 8), bool)
    mask[5:, 5:] = True
    with pytest.raises(ValueError, match="is black inside its mask"):
        photo_checks.check_not_black(one, "p.exr", mask)


def test_nan_pixels_do_not_count_as_light():
    nan = np.full((8, 8, 3), np.nan)
    nan[0, 0] = 0.0
    with pytest.raises(ValueError, match="is black"):
        photo_checks.check_not_black(nan, "p.exr")


def test_a_few_pixels_of_1e30_are_refused_with_their_count():
    rng = np.random.default_rng(1)
    photo = rng.uniform(0.05, 0.2, (16, 16, 3))
    photo[3, 4] = photo[9, 9, 0] = photo[12, 1, 2] = 1e30
    with pytest.raises(ValueError, match=r"^photo p\.exr has 3 pixels more than 2\^32 times its "
                                         r"median value 0\.1\d* \(up to 1e\+30\), which no "
                                         r"camera records: fix the file or mask them out$"):
        photo_checks.check_range(photo, "p.exr")
    photo[12, 1, 2] = -1e30  # a negative outlier is no radiance either
    with pytest.raises(ValueError, match="has 3 pixels"):
        photo_checks.check_range(photo, "p.exr")
    mask = np.ones((16, 16), bool)
    mask[3, 4] = mask[9, 9] = mask[12, 1] = False
    photo_checks.check_range(photo, "p.exr", mask)  # masked out: nothing to say


def test_negative_values_beyond_a_black_levels_noise_are_a_note():
    """A raw photo with its black level taken off holds noise a little below 0: read,
    no note. Three pixels of -0.5 among values about 0.1 are no such noise: a note
    naming the photo, the count and the lowest value; masked out, nothing to say."""
    rng = np.random.default_rng(4)
    photo = rng.uniform(0.05, 0.2, (16, 16, 3))
    photo[:4] = rng.normal(0.0, 0.005, (4, 16, 3))  # a dark band: noise about black
    assert photo.min() < 0.0
    assert photo_checks.negative_note(photo, "p.exr") is None
    photo[8, 8] = photo[9, 2, 1] = photo[14, 14, 2] = -0.5
    note = photo_checks.negative_note(photo, "p.exr")
    assert note.startswith("photo p.exr: 3 pixels have a channel below 0 by more than "
                           "noise about a black level would (down to -0.5, the median "
                           "pixel 0.1"), note
    mask = np.ones((16, 16), bool)
    mask[8, 8] = mask[9, 2] = mask[14, 14] = False
    assert photo_checks.negative_note(photo, "p.exr", mask) is None
    assert photo_checks.negative_note(np.zeros((4, 4, 3)), "p.exr") is None  # all black


def test_a_sun_glint_twenty_stops_above_the_rest_is_radiance():
    """The sun's mirror image on a glossy object is about 2^20 times the median of
    what is lit around it: a real photo, kept."""
    photo = np.full((16, 16, 3), 0.1)
    photo[8, 8] = 0.1 * 2.0 ** 20
    photo_checks.check_range(photo, "p.exr")
    photo[8, 8] = 0.1 * 2.0 ** 33
    with pytest.raises(ValueError, match="has 1 pixel more than"):
        photo_checks.check_range(photo, "p.exr")


def test_1e30_in_a_float_exr_is_read_and_refused(tmp_path):
    """A float32 EXR holds 1e30 (a half EXR cannot: tests/core/capture/test_photo_io.py)."""
    pixels = np.full((8, 8, 3), 0.1, np.float32)
    pixels[1, 1] = 1e30
    path = write_image(tmp_path / "hot.exr", pixels, oiio.FLOAT)
    read = photo_io.read_photo_file(path)
    assert read.radiance[1, 1, 0] == pytest.approx(1e30, rel=1e-6) and read.nonfinite == 0
    with pytest.raises(ValueError, match=r"hot\.exr has 1 pixel more than 2\^32"):
        photo_checks.check_range(read.radiance, str(path))


def test_a_photo_black_over_the_scan_is_refused_with_its_pixel_count():
    normal, region = _sphere()
    photo = np.zeros((SIZE, SIZE, 3))
    photo[:3] = 0.5  # light in the background only: the camera looks elsewhere
    scan = region >= 0
    with pytest.raises(ValueError, match=rf"^photo p\.exr is black over the scan \(all "
                                         rf"{scan.sum()} of its pixels are 0\): check the "
                                         r"photo's camera"):
        photo_checks.check_scan_not_black(photo, "p.exr", scan)
    photo_checks.check_scan_not_black(_lambert(normal, region, LIGHT), "p.exr", scan)


# --- the photo's light against the G-buffer's ------------------------------------

def test_the_right_light_with_a_cast_shadow_and_sky_light_passes():
    """Lambert under the given light, its cast shadow, and an ambient tenth of the
    light everywhere: the brightest shadowed pixels are the ambient level, a / (1 + a)
    of the brightest lit one."""
    normal, region = _sphere()
    ambient = 0.1
    photo = _lambert(normal, region, LIGHT, ambient=ambient, shadow=CAST)
    c, notes = _check(photo, LIGHT, shadow=CAST)
    assert notes == []
    assert c.shadow_pixels > 100 and c.lit_pixels > 1000 and c.brighter_in_shadow == 0
    # the third brightest lit pixel faces the light to within a pixel's turn
    assert c.shadow_to_lit == pytest.approx(ambient / (1 + ambient), rel=0.01)
    assert c.dark_where_lit == 0.0


def test_the_opposite_light_is_refused_naming_the_photo_and_what_to_check():
    normal, region = _sphere()
    photo = _lambert(normal, region, -LIGHT)
    _, cosine, visibility, region = _gbuffer(LIGHT)
    c = photo_checks.light_consistency(photo, cosine, visibility, region, region >= 0)
    assert c.shadow_to_lit == math.inf and c.as_dict()["shadow_to_lit"] == "inf"
    with pytest.raises(ValueError, match=r"^photo p\.exr is brighter where its G-buffer puts "
                                         r"the scan in shadow than where it lights it \(\d+ of "
                                         r"those \d+ shadowed pixels .*check the photo's light "
                                         r"\(direction, Sun object or sun position\) and its "
                                         r"camera$"):
        photo_checks.check_light(c, "p.exr")


def test_the_opposite_light_under_a_grey_sky_is_still_refused():
    normal, region = _sphere()
    photo = _lambert(normal, region, -LIGHT, ambient=0.15)
    with pytest.raises(ValueError, match="brighter where its G-buffer puts the scan in shadow"):
        _check(photo, LIGHT)


def test_a_polished_metal_dark_off_its_highlight_is_no_false_alarm():
    """A narrow mirror lobe about the half vector of the light and the view (+z), a
    black world: every lit pixel but the highlight is 0, and so is the shadow."""
    normal, region = _sphere()
    half = _unit(LIGHT + np.array([0.0, 0.0, 1.0]))
    lit = (normal @ LIGHT > 0) & ~CAST & (region >= 0)  # where the light reaches
    lobe = np.clip(normal @ half, 0.0, None) ** 2000
    photo = np.repeat(np.where(lit, 50.0 * lobe, 0.0)[..., None], 3, axis=-1)
    c, notes = _check(photo, LIGHT, shadow=CAST)
    assert notes == [] and c.shadow_to_lit == 0.0
    # with a grey world reflected everywhere the highlight still outshines the shadow
    c, notes = _check(photo + 0.05 * (region >= 0)[..., None], LIGHT, shadow=CAST)
    assert notes == [] and c.shadow_to_lit < 0.01


def test_a_light_off_by_ninety_degrees_is_a_note_not_a_refusal():
    normal, region = _sphere()
    turned = _unit([-0.3, 0.6, 0.74])  # LIGHT turned 90 degrees about the view axis
    photo = _lambert(normal, region, turned, ambient=0.05)
    c, notes = _check(photo, LIGHT)
    assert 0.5 < c.shadow_to_lit <= 1.0
    assert len(notes) == 1 and notes[0].startswith(f"the brightest of the {c.shadow_pixels} "
                                                   "pixels its G-buffer puts in shadow are")


def test_a_photo_dark_where_its_light_falls_is_a_note():
    """The G-buffer's light from the camera lights every visible pixel; the photo's
    came from the right, so the left of the sphere is dark where the G-buffer says
    fully lit. No shadowed pixel to compare: a note about the dark, no refusal."""
    normal, region = _sphere()
    photo = _lambert(normal, region, [0.9, 0.0, 0.44])
    c, notes = _check(photo, [0.0, 0.0, 1.0])
    assert c.shadow_to_lit is None
    # the left part of the disc where the camera's light has n.l >= 1/2 is unlit
    assert c.dark_where_lit > 0.25
    assert len(notes) == 1 and "lights fully are dark" in notes[0]
    assert "polished metal" in notes[0]


def test_each_region_is_compared_with_its_own_lit_pixels():
    """A white half in partial shadow beside a black half in the light: the white
    shadow outshines the black light, which is one light on two materials, not a
    wrong light."""
    normal, region = _sphere()
    rows, cols = np.indices((SIZE, SIZE))
    region = np.where(region >= 0, (cols >= SIZE // 2).astype(int), -1)
    albedo = np.where(region == 1, 0.03, 0.9)
    light = _unit([-0.2, 0.9, 0.4])  # from above: the lower part of both halves is shadow
    photo = _lambert(normal, region, light, albedo=albedo, ambient=0.2)
    _, cosine, visibility, _ = _gbuffer(light)
    c = photo_checks.light_consistency(photo, cosine, visibility, region, region >= 0)
    assert photo_checks.check_light(c, "p.exr") == []
    assert c.shadow_to_lit == pytest.approx(0.2 / 1.2, rel=0.05)
    # pooled, the white shadow would be brighter than the black half's lit pixels
    white_shadow = photo[..., 0][(region == 0) & (visibility == 0)].max()
    assert white_shadow > photo[..., 0][region == 1].max()


def test_a_shadow_edge_one_pixel_off_is_no_false_alarm(monkeypatch):
    """The photo's cast shadow one pixel right of the G-buffer's (a pixel of camera
    misregistration): the G-buffer's shadow pixels next to its light are left out."""
    normal, region = _sphere()
    photo = _lambert(normal, region, LIGHT, shadow=np.roll(CAST, 1, axis=1))
    c, notes = _check(photo, LIGHT, shadow=CAST)
    assert notes == [] and c.shadow_to_lit == 0.0
    # counted without that rule, the lit edge column in the G-buffer's shadow says
    # the light is off
    edge = CAST & ~np.roll(CAST, 1, axis=1)
    assert edge.sum() > 0 and photo[..., 0][edge].min() > 0.2
    monkeypatch.setattr(photo_checks, "EDGE_PX", 0)
    c, notes = _check(photo, LIGHT, shadow=CAST)
    assert c.shadow_to_lit > photo_checks.NOTE_RATIO and len(notes) == 1


def test_too_few_pixels_say_nothing():
    normal, region = _sphere()
    photo = _lambert(normal, region, -LIGHT)
    _, cosine, visibility, region = _gbuffer(LIGHT)
    few = np.zeros_like(region, dtype=bool)
    few[30:33, 30:33] = True  # 9 lit pixels
    c = photo_checks.light_consistency(photo, cosine, visibility, region, few)
    assert c.shadow_to_lit is None and c.dark_where_lit is None
    assert photo_checks.check_light(c, "p.exr") == []


def test_a_black_backgrounds_float_dust_does_not_make_the_lit_scan_out_of_range():
    """A resampled (undistorted) EXR of an object on black holds float dust about
    1e-17 in its background: over the whole frame that is the median of the non-zero
    pixels, and every lit pixel is 2^32 times it. Over the scan's pixels, which the
    add-on checks, the photo is in range, and a 1e30 there is still refused."""
    rng = np.random.default_rng(2)
    photo = np.abs(rng.normal(0.0, 1e-17, (32, 32, 3)))  # the background's dust
    scan = np.zeros((32, 32), bool)
    scan[12:20, 12:20] = True  # the object: 6 % of the frame
    photo[scan] = rng.uniform(0.02, 0.17, (scan.sum(), 3))
    with pytest.raises(ValueError, match="more than 2\\^32 times its median value 1"):
        photo_checks.check_range(photo, "p.exr")  # the whole frame: the dust's median
    photo_checks.check_range(photo, "p.exr", scan, where=" on the scan")
    photo[15, 15] = 1e30
    with pytest.raises(ValueError, match=r"^photo p\.exr has 1 pixel on the scan more than "):
        photo_checks.check_range(photo, "p.exr", scan, where=" on the scan")
