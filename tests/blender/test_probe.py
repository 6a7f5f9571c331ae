"""The sphere probe in the field (METHOD §7, the paper's set-up): the light's world
direction from a Cycles photo of a chrome sphere or a glossy black (clear-coat)
sphere in front of a lit grey wall, under a known Sun.

The sphere (radius 1 m, at the origin) sits right of and below the image centre
of a 35 mm perspective camera 3.7 m away, so it is seen 7 degrees off the
optical axis with a radius of 89 px in the 320 x 240 photo (32 samples, no
denoising, a 0.75 degree Sun, linear EXR). The wall behind it takes the
sphere's shadow, an ellipse of about the sphere's size: a decoy for the circle
search. The circle is found by `light_probe.locate_sphere` (or given by hand and
snapped by `refine_sphere`) and the light by `light_probe.light_from_sphere`,
with the intrinsics of `brdf_addon.light_sources.camera_intrinsics` and the camera's
rotation, as the product does. The truth is the Sun object's direction.

The resolution is what keeps every light under 1 degree with a margin: over 20
lights (bench/probe_bench.py) the worst was 0.82 degree here, but 1.6 at
256 x 192 (radius 71 px) with 16 samples, where the black sphere's unclipped
highlight, smaller than a pixel, is placed by a handful of samples.

Each photo renders in about 1.3 s; the module takes about 11 s.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")


from brdf_reconstruct.core.capture import light_probe as lp  # noqa: E402
from testkit import probe_scene as PS  # noqa: E402

TOL_DEG = 1.0


LIGHTS = {  # (angle from the sphere-to-camera direction, roll), degrees
    "near_axis": (15.0, 60.0),
    "oblique": (45.0, 200.0),
    "far_68deg": (68.0, 330.0),
}
KINDS = PS.KINDS


@pytest.fixture(scope="module")
def photos(tmp_path_factory):
    """Renders on demand, once per module: photos[(kind, light name)]."""
    folder = tmp_path_factory.mktemp("probe")
    cache = {}

    class Photos:
        def __getitem__(self, key):
            if key not in cache:
                kind, name = key
                cache[key] = PS.render_probe(folder / f"{kind}_{name}.exr", kind,
                                          PS.light_from_view(*LIGHTS[name]))
            return cache[key]

    return Photos()


def _probe(photo, image=None, circle=None, **kwargs):
    """The world light and its uncertainty (degrees) from the photo, as the product does."""
    center, radius = circle or lp.locate_sphere(photo["image"], camera=photo["camera"])
    res = lp.light_from_sphere(photo["image"] if image is None else image, center, radius,
                               photo["camera"], photo["rotation"], **kwargs)
    return PS.angle_deg(res.direction_world, photo["light"]), math.degrees(res.uncertainty_rad)


@pytest.mark.parametrize("kind", KINDS)
def test_locate_sphere_finds_the_true_circle(photos, kind):
    photo = photos[(kind, "far_68deg")]  # the wall shows the sphere's shadow beside it
    (cx, cy), r = lp.locate_sphere(photo["image"], camera=photo["camera"])
    (tx, ty), tr = photo["circle"]
    assert math.hypot(cx - tx, cy - ty) < 0.15
    if kind == "chrome":
        assert abs(r - tr) < 0.1
    else:
        # A clear coat's Fresnel-bright rim fades into the wall behind it, so its
        # outline shows about 0.4 px inside the limb (0.4 degree at 68 degrees here).
        assert -0.6 < r - tr < 0.0


@pytest.mark.parametrize("kind", KINDS)
def test_a_luminance_threshold_is_not_enough(photos, kind):
    """Why the circle comes from edges: a mask halfway up to the 99th percentile of
    luminance (the shadow, the wall seen in the mirror, the bright rim all cross it)
    puts the light degrees off."""
    photo = photos[(kind, "far_68deg")]
    lum = photo["image"] @ [0.2126, 0.7152, 0.0722]
    mask = lum > 0.5 * (lum.min() + np.percentile(lum, 99))
    circle = lp.detect_sphere(mask, camera=photo["camera"])
    assert _probe(photo, circle=circle)[0] > 5.0
    assert _probe(photo)[0] < TOL_DEG


@pytest.mark.parametrize("name", LIGHTS)
@pytest.mark.parametrize("kind", KINDS)
def test_light_direction_within_1_degree(photos, kind, name):
    err, unc = _probe(photos[(kind, name)])
    assert err < TOL_DEG
    assert err < 2.0 * unc < 2.0  # the uncertainty is an honest, useful scale


@pytest.mark.parametrize("name", LIGHTS)
@pytest.mark.parametrize("kind", KINDS)
def test_clipped_highlight(photos, kind, name):
    """The photo clipped at 1.0 as a camera would: the highlight's core is flat."""
    photo = photos[(kind, name)]
    clipped = np.minimum(photo["image"], 1.0)
    hx, hy = lp.find_highlight(clipped, *photo["circle"])[0]
    core = clipped[int(hy) - 3:int(hy) + 4, int(hx) - 3:int(hx) + 4] @ [0.2126, 0.7152, 0.0722]
    assert np.sum(core >= 0.999) >= 3  # really saturated, over more than a pixel
    err, unc = _probe(photo, image=clipped)
    assert err < TOL_DEG
    assert err < 2.0 * unc


@pytest.mark.parametrize("kind", KINDS)
def test_user_circle_a_little_off_is_snapped(photos, kind):
    """A hand-drawn circle 1.8 px off centre and 1.5 px too big costs about 2 degrees
    as it is; `refine_sphere` snaps it to the outline the automatic search finds."""
    photo = photos[(kind, "far_68deg")]
    (tx, ty), tr = photo["circle"]
    drawn = ((tx + 1.5, ty - 1.0), tr + 1.5)
    raw, raw_unc = _probe(photo, circle=drawn, circle_sigma_px=2.0)
    assert raw > 1.5  # what the slightly-off circle costs
    assert raw < raw_unc  # and its uncertainty says so when told the circle's error
    (cx, cy), r = lp.refine_sphere(photo["image"], *drawn, camera=photo["camera"])
    (ax, ay), ar = lp.locate_sphere(photo["image"], camera=photo["camera"])
    assert math.hypot(cx - ax, cy - ay) < 0.05 and abs(r - ar) < 0.05
    err, _ = _probe(photo, circle=((cx, cy), r))
    assert err < TOL_DEG


def test_clean_plate_and_no_sphere(photos, tmp_path):
    """The same view without the sphere: no sphere-like circle in it (one clear error),
    and as a clean plate (`background`) it finds the same circle."""
    plate = PS.render_probe(tmp_path / "plate.exr", None, PS.light_from_view(*LIGHTS["far_68deg"]))
    with pytest.raises(ValueError, match="no sphere-like circle"):
        lp.locate_sphere(plate["image"], camera=plate["camera"])
    photo = photos[("black", "far_68deg")]
    (cx, cy), r = lp.locate_sphere(photo["image"], camera=photo["camera"],
                                   background=plate["image"])
    (tx, ty), tr = photo["circle"]
    assert math.hypot(cx - tx, cy - ty) < 0.15 and abs(r - tr) < 0.6
