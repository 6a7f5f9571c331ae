"""core.capture.irradiance: irradiance ratios between photos from a Lambertian reference.

Reference model: a Lambertian surface of albedo rho under irradiance E has
radiance L = (rho / pi) E cos(theta). Synthetic references with random normals
under known per-channel E must give E_i / E_ref; a grey card tilted to
cos = 0.5 under twice the irradiance looks the same as one facing a single E.
"""

import numpy as np
import pytest

from brdf_reconstruct.core.capture import irradiance

ALBEDO = np.array([0.18, 0.21, 0.15])


def _random_normals(rng, m):
    v = rng.normal(size=(m, 3))
    v[:, 2] = np.abs(v[:, 2])  # the visible side of a scanned region
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _lambertian_reference(rng, E, light, m=3000, noise=0.02, shadow_value=0.03):
    """A region of random normals lit by irradiance E (3,) from unit `light`.

    Pixels with cos <= 0.1 get `shadow_value` (interreflections, normal errors):
    data the estimator must not use.
    """
    n = _random_normals(rng, m)
    cos = n @ light
    L = ALBEDO / np.pi * E * np.maximum(cos, 0.0)[:, None]
    L *= 1.0 + noise * rng.normal(size=L.shape)
    L[cos <= irradiance.MIN_COSINE] = shadow_value
    return irradiance.Reference(L, cos)


def _unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def test_random_normals_known_ratios_within_one_percent():
    rng = np.random.default_rng(5)
    E = np.array([[1.0, 1.0, 1.0], [0.5, 0.55, 0.6], [2.0, 1.7, 1.2], [0.8, 0.8, 0.9]]) * 3.0
    lights = [_unit(v) for v in ([0, 0, 1], [1, 0, 1], [-0.5, 0.8, 0.6], [0.2, -1, 0.4])]
    refs = [_lambertian_reference(rng, E[i], lights[i]) for i in range(4)]
    ratios, notes = irradiance.relative_irradiance(refs)
    assert ratios.shape == (4, 3) and ratios.dtype == np.float64
    np.testing.assert_allclose(ratios, E / E[0], rtol=0.01)
    np.testing.assert_array_equal(ratios[0], 1.0)
    assert len(notes) == 4
    assert notes[0].startswith("photo 1: irradiance reference from its reference region (")
    # Without the cosine threshold, the shadowed pixels would bias the fit.
    r = refs[1]
    ls = (r.cosine @ r.radiance) / (r.cosine @ r.cosine)
    assert not np.allclose(ls / (ALBEDO / np.pi * E[1]), 1.0, rtol=0.01)


def test_reference_photo_choice_is_consistent():
    rng = np.random.default_rng(8)
    E = np.array([[1.0, 1.0, 1.0], [0.4, 0.5, 0.6], [1.5, 1.5, 1.4]])
    refs = [_lambertian_reference(rng, E[i], _unit([i, 0.3, 1.0])) for i in range(3)]
    r0, _ = irradiance.relative_irradiance(refs)
    r2, notes = irradiance.relative_irradiance(refs, reference_photo=2, names=["a", "b", "c"])
    np.testing.assert_array_equal(r2[2], 1.0)
    np.testing.assert_allclose(r2, r0 / r0[2], rtol=1e-12)
    np.testing.assert_allclose(r2, E / E[2], rtol=0.01)
    assert notes[0].startswith("a: irradiance x(")
    assert " of c from its reference region (" in notes[0]


def test_grey_card_with_a_cosine_exact():
    card = ALBEDO / np.pi * 1.0  # facing irradiance 1
    refs = [
        irradiance.grey_card(card),  # faces the light
        irradiance.grey_card(card, cosine=0.5),  # same radiance at 60 degrees: E is twice
        irradiance.grey_card(np.tile(card * 0.25, (50, 1)), cosine=np.cos(np.radians(30))),
    ]
    ratios, notes = irradiance.relative_irradiance(refs, names=["a.jpg", "b.jpg", "c.jpg"])
    np.testing.assert_allclose(ratios[1], 2.0, rtol=1e-14)
    np.testing.assert_allclose(ratios[2], 0.25 / np.cos(np.radians(30)), rtol=1e-14)
    assert notes[0] == "a.jpg: irradiance reference from its gray card (1 of 1 pixels)"
    assert notes[1] == "b.jpg: irradiance x(2, 2, 2) of a.jpg from its gray card (1 of 1 pixels)"
    assert notes[2].endswith("from its gray card (50 of 50 pixels)")


def test_no_reference_anywhere_is_equal_irradiance_with_one_note():
    ratios, notes = irradiance.relative_irradiance([None, None, None])
    np.testing.assert_array_equal(ratios, np.ones((3, 3)))
    assert notes == ["no gray card or reference region: irradiance assumed equal across photos"]


def test_mixed_references_is_an_error_naming_the_photo():
    card = irradiance.grey_card([0.05, 0.05, 0.05])
    with pytest.raises(ValueError, match=r"^b\.jpg has no gray card or reference region while"):
        irradiance.relative_irradiance([card, None, card, None], names=["a.jpg", "b.jpg", "c", "d"])


def test_non_finite_and_saturated_pixels_are_left_out():
    rng = np.random.default_rng(2)
    E = np.array([[1.0, 1.0, 1.0], [0.6, 0.7, 0.8]])
    clean = [_lambertian_reference(rng, E[i], _unit([i, 0.0, 1.0]), m=500) for i in range(2)]
    expected, _ = irradiance.relative_irradiance(clean)

    L = clean[1].radiance.copy()
    cos = clean[1].cosine.copy()
    extra = [[np.nan, 0.1, 0.1], [np.inf, 0.1, 0.1], [1.0, 1.0, 1.0], [1.0, 0.2, 0.2]]
    bad_L = np.vstack([L, extra])
    bad_cos = np.concatenate([cos, [0.9, 0.9, 0.9, 0.9]])
    saturated = np.zeros(bad_L.shape, dtype=bool)
    saturated[-2:, 0] = True  # the last two pixels clipped in red
    refs = [clean[0], irradiance.Reference(bad_L, bad_cos, saturated)]
    ratios, notes = irradiance.relative_irradiance(refs)
    np.testing.assert_allclose(ratios, expected, rtol=1e-13)
    used = int(np.count_nonzero(cos > irradiance.MIN_COSINE))
    assert notes[1].endswith(f"({used} of {bad_L.shape[0]} pixels)")
    # The (M,) form of the mask and non-finite cosines.
    bad_cos[-3] = np.nan
    refs = [clean[0], irradiance.Reference(bad_L, bad_cos, saturated.any(axis=1))]
    np.testing.assert_allclose(irradiance.relative_irradiance(refs)[0], expected, rtol=1e-13)


def test_float32_matches_float64():
    rng = np.random.default_rng(4)
    refs64 = [_lambertian_reference(rng, np.array([1.0, 0.9, 0.8]) * (i + 1),
                                    _unit([0.3 * i, 0.1, 1.0])) for i in range(3)]
    refs32 = [irradiance.Reference(r.radiance.astype(np.float32), r.cosine.astype(np.float32))
              for r in refs64]
    r64, _ = irradiance.relative_irradiance(refs64)
    r32, _ = irradiance.relative_irradiance(refs32)
    assert r32.dtype == np.float64
    np.testing.assert_allclose(r32, r64, rtol=1e-5)
    np.testing.assert_allclose(r64[:, 0], [1.0, 2.0, 3.0], rtol=0.01)


def test_errors():
    card = irradiance.grey_card([0.05, 0.05, 0.05])
    with pytest.raises(ValueError, match="the gray card of photo 2 has no usable pixel"):
        irradiance.relative_irradiance([card, irradiance.grey_card([0.1, 0.1, 0.1], cosine=0.05)])
    with pytest.raises(ValueError, match="the reference region of photo 1 has no usable pixel"):
        irradiance.relative_irradiance(
            [irradiance.Reference(np.full((3, 3), np.nan), np.ones(3)), card])
    with pytest.raises(ValueError, match="black in some channel"):
        irradiance.relative_irradiance([irradiance.grey_card([0.1, 0.0, 0.1]), card])
    with pytest.raises(ValueError, match=r"radiance of photo 1 must have shape \(M, 3\)"):
        irradiance.relative_irradiance([irradiance.Reference(np.ones((4, 2)), 1.0), card])
    with pytest.raises(ValueError, match=r"cosines of photo 1 must be a number or have shape \(4,"):
        irradiance.relative_irradiance([irradiance.Reference(np.ones((4, 3)), np.ones(3)), card])
    with pytest.raises(ValueError, match=r"saturated mask of photo 1 must have shape \(4,\)"):
        irradiance.relative_irradiance(
            [irradiance.Reference(np.ones((4, 3)), 1.0, np.zeros(5, bool)), card])
    with pytest.raises(ValueError, match=r"reference_photo must be a photo index in \[0, 2\)"):
        irradiance.relative_irradiance([card, card], reference_photo=2)
    with pytest.raises(ValueError, match="one entry per photo"):
        irradiance.relative_irradiance([card, card], names=["a"])
