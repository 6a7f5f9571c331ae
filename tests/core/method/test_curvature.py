"""Per-pixel curvature from G-buffers, against ray-cast analytic surfaces."""

import time

import numpy as np
import pytest

from brdf_reconstruct.core.method import curvature

# ---------------------------------------------------------------- ray casting


def _camera(eye, target, size, focal=None, ortho_width=None):
    """Rays (H, W, 3) origins and unit directions for a pinhole (focal in pixels) or ortho camera.

    Pixel (row i, column j) looks through its centre; u = column to the right,
    v = row downwards, the camera looks from ``eye`` to ``target`` with world +z up.
    """
    h, w = size
    eye = np.asarray(eye, float)
    fwd = np.asarray(target, float) - eye
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    if np.linalg.norm(right) < 1e-9:
        right = np.cross(fwd, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    x = np.arange(w) + 0.5 - w / 2
    y = h / 2 - (np.arange(h) + 0.5)
    x, y = np.meshgrid(x, y)
    if focal is not None:
        d = fwd * focal + x[..., None] * right + y[..., None] * up
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        o = np.broadcast_to(eye, d.shape).copy()
    else:
        s = ortho_width / w
        o = eye + s * (x[..., None] * right + y[..., None] * up)
        d = np.broadcast_to(fwd, o.shape).copy()
    return o, d


def _sphere(o, d, c, r, inside=False):
    """Near hit (outward normal) or, with ``inside``, far hit with inward normal (a bowl)."""
    oc = o - c
    b = np.sum(oc * d, axis=-1)
    disc = b * b - (np.sum(oc * oc, axis=-1) - r * r)
    root = np.sqrt(np.where(disc >= 0, disc, np.nan))
    t = -b + root if inside else -b - root
    t = np.where(t > 0, t, np.nan)
    p = o + t[..., None] * d
    n = (p - c) / r
    return t, p, -n if inside else n


def _plane(o, d, p0, n0):
    n0 = np.asarray(n0, float) / np.linalg.norm(n0)
    den = np.sum(d * n0, axis=-1)
    t = np.sum((p0 - o) * n0, axis=-1) / den
    t = np.where(t > 0, t, np.nan)
    p = o + t[..., None] * d
    n = np.where((den < 0)[..., None], n0, -n0)
    return t, p, np.broadcast_to(n, p.shape)


def _cylinder(o, d, c, axis, r):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    oc = o - c
    dp = d - np.sum(d * a, axis=-1, keepdims=True) * a
    op = oc - np.sum(oc * a, axis=-1, keepdims=True) * a
    qa = np.sum(dp * dp, axis=-1)
    qb = np.sum(dp * op, axis=-1)
    disc = qb * qb - qa * (np.sum(op * op, axis=-1) - r * r)
    t = (-qb - np.sqrt(np.where(disc >= 0, disc, np.nan))) / qa
    t = np.where(t > 0, t, np.nan)
    p = o + t[..., None] * d
    radial = p - c - np.sum((p - c) * a, axis=-1, keepdims=True) * a
    return t, p, radial / r


def _ellipsoid(o, d, radii):
    """Near hit on ``sum((x / radii)^2) = 1`` with the outward normal."""
    radii = np.asarray(radii, float)
    os_, ds = o / radii, d / radii
    qa = np.sum(ds * ds, axis=-1)
    qb = np.sum(os_ * ds, axis=-1)
    disc = qb * qb - qa * (np.sum(os_ * os_, axis=-1) - 1.0)
    t = (-qb - np.sqrt(np.where(disc >= 0, disc, np.nan))) / qa
    t = np.where(t > 0, t, np.nan)
    p = o + t[..., None] * d
    g = p / radii**2
    return t, p, g / np.linalg.norm(g, axis=-1, keepdims=True)


def _ellipsoid_curvatures(p, radii):
    """Analytic mean (convex positive) and Gaussian curvature on the ellipsoid."""
    a2, b2, c2 = np.asarray(radii, float) ** 2
    q = np.sum(p**2 / np.array([a2, b2, c2]) ** 2, axis=-1)
    q = np.where(q > 0, q, np.nan)  # background positions are 0
    mean = (a2 + b2 + c2 - np.sum(p**2, axis=-1)) / (2.0 * a2 * b2 * c2 * q**1.5)
    return mean, 1.0 / (a2 * b2 * c2 * q**2)


def _gbuffer(*hits):
    """Nearest of several hits -> (normal, position, index of the surface hit or -1)."""
    ts = np.stack([np.where(np.isfinite(t), t, np.inf) for t, _, _ in hits])
    which = np.argmin(ts, axis=0)
    hit = np.isfinite(np.min(ts, axis=0))
    normal = np.zeros(ts.shape[1:] + (3,))
    position = np.zeros_like(normal)
    for k, (_, p, n) in enumerate(hits):
        sel = hit & (which == k)
        normal[sel] = n[sel]
        position[sel] = p[sel]
    return normal, position, np.where(hit, which, -1)


def _interior(normal, d, max_angle_deg=70.0, erode=2):
    """Samples whose normal is within max_angle of the view ray, away from image/object edges."""
    ok = np.sum(normal * -d, axis=-1) >= np.cos(np.deg2rad(max_angle_deg))
    for _ in range(erode):
        e = ok.copy()
        e[1:] &= ok[:-1]
        e[:-1] &= ok[1:]
        e[:, 1:] &= ok[:, :-1]
        e[:, :-1] &= ok[:, 1:]
        e[[0, -1], :] = False
        e[:, [0, -1]] = False
        ok = e
    return ok


def _rel_err(h, truth, sel):
    err = np.abs(h[sel] - truth) / abs(truth)
    return float(np.median(err)), float(np.percentile(err, 95))


SIZE = (160, 200)


def _sphere_scene(r, camera):
    c = np.array([0.1, -0.2, 0.3]) * r
    if camera == "ortho":
        o, d = _camera(c + [0, -10 * r, 2 * r], c, SIZE, ortho_width=3.0 * r)
    else:
        o, d = _camera(c + [3 * r, -5 * r, 2 * r], c, SIZE, focal=250.0)
    normal, position, _ = _gbuffer(_sphere(o, d, c, r))
    return normal, position, d


# ---------------------------------------------------------------- analytic cases


@pytest.mark.parametrize("camera", ["ortho", "persp"])
@pytest.mark.parametrize("r", [0.5, 3.0])
def test_sphere_gives_one_over_r(r, camera):
    normal, position, d = _sphere_scene(r, camera)
    h, valid = curvature.mean_curvature(normal, position)
    _, k, _ = curvature.curvatures(normal, position)
    sel = _interior(normal, d)
    assert sel.sum() > 1000 and np.all(valid[sel])
    med, p95 = _rel_err(h, 1.0 / r, sel)
    kmed, kp95 = _rel_err(k, 1.0 / r**2, sel)
    print(f"sphere R={r} {camera}: |H-1/R|R median {med:.2e} p95 {p95:.2e}; K p95 {kp95:.2e}")
    assert med < 0.01 and p95 < 0.02 and kp95 < 0.04
    # every valid pixel, silhouette included, is right or absent, never huge
    assert np.nanmax(np.abs(h - 1.0 / r)) * r < 0.05


@pytest.mark.parametrize("camera", ["ortho", "persp"])
def test_oblique_plane_gives_zero(camera):
    p0 = np.array([0.3, 0.2, 0.0])
    n0 = np.array([0.1, 0.2, 1.0])
    eye = p0 + np.array([0.0, -4.0, 2.5])  # about 60 degrees from the plane normal
    if camera == "ortho":
        o, d = _camera(eye, p0, SIZE, ortho_width=2.0)
    else:
        o, d = _camera(eye, p0, SIZE, focal=150.0)
    normal, position, which = _gbuffer(_plane(o, d, p0, n0))
    h, valid = curvature.mean_curvature(normal, position)
    _, k, _ = curvature.curvatures(normal, position)
    hit = which >= 0  # the perspective view sees the horizon
    print(f"plane {camera}: valid {valid[hit].mean():.4f}, max |H| {np.nanmax(np.abs(h)):.2e}")
    # all but the last rows before the horizon (steps of 100s of units at 89.9 degrees)
    assert valid[hit].mean() > 0.99
    assert np.nanmax(np.abs(h)) < 1e-6 and np.nanmax(np.abs(k)) < 1e-9


@pytest.mark.parametrize("camera", ["ortho", "persp"])
@pytest.mark.parametrize("r", [0.5, 3.0])
def test_cylinder_gives_one_over_two_r(r, camera):
    c = np.array([0.0, 0.0, 0.0])
    axis = [0.3, 0.2, 1.0]
    if camera == "ortho":
        o, d = _camera([0, -10 * r, 0], c, SIZE, ortho_width=3.0 * r)
    else:
        o, d = _camera([2 * r, -5 * r, 1 * r], c, SIZE, focal=200.0)
    normal, position, _ = _gbuffer(_cylinder(o, d, c, axis, r))
    h, k, valid = curvature.curvatures(normal, position)
    sel = _interior(normal, d)
    assert sel.sum() > 1000 and np.all(valid[sel])
    med, p95 = _rel_err(h, 0.5 / r, sel)
    print(f"cylinder R={r} {camera}: |H-1/2R|2R median {med:.2e} p95 {p95:.2e}")
    assert med < 0.01 and p95 < 0.02
    assert np.nanmax(np.abs(k[sel])) * r**2 < 1e-3


@pytest.mark.parametrize("camera", ["ortho", "persp"])
def test_ellipsoid_matches_the_analytic_curvature(camera):
    # Unlike the quadrics above (dN is linear in dP there, so the differences are
    # exact), the ellipsoid shows the discretisation error.
    radii = (1.0, 0.6, 0.35)
    if camera == "ortho":
        o, d = _camera([2.0, -4.0, 1.5], np.zeros(3), SIZE, ortho_width=2.4)
    else:
        o, d = _camera([2.0, -4.0, 1.5], np.zeros(3), SIZE, focal=300.0)
    normal, position, _ = _gbuffer(_ellipsoid(o, d, radii))
    h, k, valid = curvature.curvatures(normal, position)
    h_true, k_true = _ellipsoid_curvatures(position, radii)
    sel = _interior(normal, d)
    assert sel.sum() > 1000 and np.all(valid[sel])
    err = np.abs(h - h_true)[sel] / h_true[sel]
    kerr = np.abs(k - k_true)[sel] / k_true[sel]
    med, p95 = np.median(err), np.percentile(err, 95)
    print(
        f"ellipsoid {camera}: H {h_true[sel].min():.2f}..{h_true[sel].max():.2f}, "
        f"rel. error median {med:.2e} p95 {p95:.2e}; K p95 {np.percentile(kerr, 95):.2e}"
    )
    assert med < 0.01 and p95 < 0.02


def test_bowl_is_concave_and_filtered_by_magnitude():
    r = 1.0
    c = np.zeros(3)
    o, d = _camera([0, -6, 0], c, SIZE, focal=300.0)
    normal, position, _ = _gbuffer(_sphere(o, d, c, r, inside=True))
    h, valid = curvature.mean_curvature(normal, position)
    sel = _interior(normal, d)
    med, p95 = _rel_err(h, -1.0 / r, sel)
    print(f"bowl: |H+1/R|R median {med:.2e} p95 {p95:.2e}")
    assert p95 < 0.02
    reliable = curvature.curvature_mask(normal, position, threshold=0.5)
    assert not reliable[sel].any()
    assert (
        reliable[sel].sum() == 0
        and curvature.curvature_mask(normal, position, threshold=1.5)[sel].all()
    )


# ---------------------------------------------------------------- units


def test_units_scale_as_one_over_r_and_length_scale():
    n1, p1, d = _sphere_scene(0.5, "persp")
    n2, p2, _ = _sphere_scene(3.0, "persp")
    h1, v1 = curvature.mean_curvature(n1, p1)
    h2, v2 = curvature.mean_curvature(n2, p2)
    # The same image scaled by 6: H scales by 1/6, and with length_scale = R both are 1.
    np.testing.assert_array_equal(v1, v2)
    np.testing.assert_allclose(h1[v1] / 6.0, h2[v2], rtol=1e-9)
    hs, _ = curvature.mean_curvature(n2, p2, length_scale=3.0)
    sel = _interior(n2, d)
    assert np.allclose(hs[sel], 1.0, rtol=1e-6)
    # Per pixel: radians of normal turn per pixel, footprint / R on the sphere's centre.
    hp, vp = curvature.mean_curvature(n1, p1, length_scale="pixel")
    hp2, _ = curvature.mean_curvature(n2, p2, length_scale="pixel")
    np.testing.assert_allclose(hp[vp], hp2[vp], rtol=1e-9)
    centre = (80, 100)  # looks at the sphere's centre: footprint = distance / focal
    eye = np.array([0.1 + 3.0, -0.2 - 5.0, 0.3 + 2.0]) * 0.5
    dist = np.linalg.norm(p1[centre] - eye)
    assert hp[centre] == pytest.approx(dist / 250.0 / 0.5, rel=0.01)


def test_threshold_units():
    normal, position, d = _sphere_scene(3.0, "ortho")  # H = 1/3 per scene unit
    sel = _interior(normal, d)
    assert curvature.curvature_mask(normal, position, threshold=0.4)[sel].all()
    assert not curvature.curvature_mask(normal, position, threshold=0.2)[sel].any()
    # relative to a 0.5-unit length H = 1/6 < 0.2
    assert curvature.curvature_mask(normal, position, threshold=0.2, length_scale=0.5)[sel].all()


# ---------------------------------------------------------------- discontinuities


@pytest.mark.parametrize("camera", ["ortho", "persp"])
def test_sphere_in_front_of_plane_silhouette_is_not_curvature(camera):
    r = 0.5
    c = np.zeros(3)
    wall = (np.array([0.0, 1.0, 0.0]), np.array([0.0, -1.0, 0.2]))  # behind the sphere
    if camera == "ortho":
        o, d = _camera([0, -5, 0], c, SIZE, ortho_width=2.0)
    else:
        o, d = _camera([0.5, -4, 0.5], c, SIZE, focal=220.0)
    normal, position, which = _gbuffer(_sphere(o, d, c, r), _plane(o, d, *wall))
    truth = np.where(which == 0, 1.0 / r, 0.0)
    h, valid = curvature.mean_curvature(normal, position)
    err = np.abs(h - truth)[valid]
    edge = np.zeros_like(valid)  # sphere and wall pixels that touch the other surface
    for ax, s in ((0, 1), (0, -1), (1, 1), (1, -1)):
        edge |= (which >= 0) & (np.roll(which, s, axis=ax) != which)
    edge[[0, -1], :] = edge[:, [0, -1]] = False
    print(
        f"sphere+wall {camera}: max |H - truth| over valid {err.max():.2e}, "
        f"silhouette pixels {edge.sum()} of which valid {valid[edge].sum()}"
    )
    assert err.max() < 0.02 / r
    assert valid[(which == 1) & ~edge].mean() > 0.99  # the wall is kept
    # Without the rules the same pixels are wrong by the order of H itself.
    h_naive, _ = curvature.mean_curvature(
        normal, position, discontinuity=np.inf, max_normal_angle=np.pi
    )
    naive = np.nanmax(np.abs(h_naive - truth)[edge])
    print(f"  without the discontinuity rule: max error {naive:.2f} /unit")
    assert naive > 0.5 / r


def test_nan_only_invalidates_its_own_pixel():
    normal, position, d = _sphere_scene(1.0, "ortho")
    h0, v0 = curvature.mean_curvature(normal, position)
    normal = normal.copy()
    position = position.copy()
    holes = [(80, 100), (70, 90), (71, 90), (90, 111)]
    for i, j in holes[:3]:
        normal[i, j] = np.nan
    position[holes[3]] = [np.nan, 0.0, 0.0]
    h, v = curvature.mean_curvature(normal, position)
    for ij in holes:
        assert not v[ij] and np.isnan(h[ij])
    others = v0.copy()
    for ij in holes:
        others[ij] = False
    assert np.all(v[others])  # neighbours fall back to one-sided differences
    np.testing.assert_allclose(h[others], h0[others], rtol=1e-6)
    assert np.array_equal(np.isnan(h), ~v)


def test_pixel_with_no_usable_neighbour_is_invalid():
    normal, position, _ = _sphere_scene(1.0, "ortho")
    mask = np.zeros(SIZE, dtype=bool)
    mask[50:60, 50:60] = True
    mask[52, 50:60] = False  # cuts row 53 off from above
    mask[54, 50:60] = False  # and from below: row 53 has no v neighbour
    h, v = curvature.mean_curvature(normal, position, mask=mask)
    assert not v[53].any() and not v[~mask].any()
    assert v[56:58, 51:59].all()


def test_single_pixel_object():
    normal = np.zeros(SIZE + (3,))
    position = np.zeros(SIZE + (3,))
    normal[40, 50] = [0.0, 0.0, 1.0]
    position[40, 50] = [1.0, 2.0, 3.0]
    h, v = curvature.mean_curvature(normal, position)
    assert not v.any() and np.isnan(h).all()
    assert not curvature.curvature_mask(normal, position).any()


def test_single_pixel_in_front_of_a_wall():
    o, d = _camera([0, -5, 0], np.zeros(3), SIZE, focal=200.0)
    normal, position, _ = _gbuffer(_plane(o, d, np.zeros(3), [0, -1, 0]))
    normal[40, 50] = [0.6, -0.8, 0.0]
    position[40, 50] = position[40, 50] * 0.5  # halfway to the camera
    h, v = curvature.mean_curvature(normal, position)
    assert not v[40, 50]
    assert v.sum() == v.size - 1 and np.nanmax(np.abs(h)) < 1e-9


def test_background_only_and_empty():
    z = np.zeros((8, 9, 3))
    h, v = curvature.mean_curvature(z, z)
    assert not v.any() and np.isnan(h).all()
    h, v = curvature.mean_curvature(np.zeros((0, 0, 3)), np.zeros((0, 0, 3)))
    assert h.shape == (0, 0) and v.shape == (0, 0)


def test_float32_matches_float64():
    normal, position, d = _sphere_scene(0.5, "persp")
    h64, v64 = curvature.mean_curvature(normal, position)
    h32, v32 = curvature.mean_curvature(normal.astype(np.float32), position.astype(np.float32))
    assert h32.dtype == np.float64
    sel = _interior(normal, d)
    assert v32[sel].all()
    med, p95 = _rel_err(h32, 2.0, sel)
    print(f"float32 sphere R=0.5 persp: median {med:.2e} p95 {p95:.2e}")
    assert p95 < 0.02
    assert np.mean(v32 == v64) > 0.99


def test_input_validation():
    z = np.zeros((4, 5, 3))
    with pytest.raises(ValueError, match="normal"):
        curvature.mean_curvature(np.zeros((4, 5)), z)
    with pytest.raises(ValueError, match="position"):
        curvature.mean_curvature(z, np.zeros((4, 6, 3)))
    with pytest.raises(ValueError, match="mask"):
        curvature.mean_curvature(z, z, mask=np.ones((5, 4), bool))
    with pytest.raises(ValueError, match="length_scale"):
        curvature.mean_curvature(z, z, length_scale=0.0)
    with pytest.raises(ValueError, match="length_scale"):
        curvature.mean_curvature(z, z, length_scale="metre")
    with pytest.raises(ValueError, match="discontinuity"):
        curvature.mean_curvature(z, z, discontinuity=-1.0)
    with pytest.raises(ValueError, match="threshold"):
        curvature.curvature_mask(z, z, threshold=-0.1)


def test_one_megapixel_is_vectorised():
    size = (1000, 1000)
    o, d = _camera([0, -5, 0], np.zeros(3), size, focal=1200.0)
    normal, position, _ = _gbuffer(_sphere(o, d, np.zeros(3), 1.0))
    times = []
    for _ in range(2):  # the first call also pays for fresh memory pages
        t0 = time.perf_counter()
        h, v = curvature.mean_curvature(normal, position)
        times.append(time.perf_counter() - t0)
    print(f"1000 x 1000: first {times[0]:.3f} s, second {times[1]:.3f} s, {v.sum()} valid")
    assert v.sum() > 100_000


# ------------------------------------------------------------------ window medians
def test_median_network_sorts_the_five_lowest_of_nine():
    """0-1 principle: a comparator network that sorts every 0/1 input sorts every input."""
    import itertools

    for bits in itertools.product((0, 1), repeat=9):
        x = list(bits)
        for i, j, min_only in curvature._LOW5_OF_9:
            lo, hi = min(x[i], x[j]), max(x[i], x[j])
            x[i] = lo
            if not min_only:
                x[j] = hi
        assert x[:5] == sorted(bits)[:5]


@pytest.mark.parametrize("shape", [(37, 53), (1, 1), (1, 40), (40, 1), (3, 2), (300, 7)])
def test_window_nanmedian3_matches_nanmedian(shape):
    import warnings

    rng = np.random.default_rng(sum(shape))
    a = rng.random(shape)
    a[rng.random(shape) < 0.3] = np.nan
    a[: shape[0] // 2, : shape[1] // 3] = np.nan
    if a.size > 4:
        a.flat[rng.choice(a.size, a.size // 4)] = 0.25  # ties
    pad = np.pad(a, 1, constant_values=np.nan)
    h, w = shape
    stack = np.stack([pad[dv:dv + h, du:du + w] for dv in range(3) for du in range(3)])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN windows
        ref = np.nanmedian(stack, axis=0)
    got = curvature.window_nanmedian3(a)
    np.testing.assert_array_equal(got, ref)
    rows, cols = np.nonzero(np.ones(shape, dtype=bool))
    np.testing.assert_array_equal(curvature.window_nanmedian3_at(a, rows, cols), ref.ravel())
    assert curvature.window_nanmedian3(a.astype(np.float32)).dtype == np.float32


def test_mean_curvature_is_the_mean_of_curvatures():
    rng = np.random.default_rng(3)
    o, d = _camera([0, -5, 1], np.zeros(3), (60, 70), focal=80.0)
    normal, position, hit = _gbuffer(_sphere(o, d, np.zeros(3), 1.0))
    mask = hit >= 0
    normal[rng.random(normal.shape[:2]) < 0.02] = np.nan
    for scale in (1.0, "pixel"):
        mean, gauss, valid = curvature.curvatures(normal, position, mask, length_scale=scale)
        h, v = curvature.mean_curvature(normal, position, mask, length_scale=scale)
        np.testing.assert_array_equal(h, mean)
        np.testing.assert_array_equal(v, valid)
        assert gauss.shape == mean.shape


@pytest.mark.parametrize("band", [1, 150, 1000])
def test_bands_of_rows_give_the_whole_image_result(monkeypatch, band):
    """curvatures works on bands of rows (plus two halo rows each side): the same
    values, bit for bit, as one pass over the image, also with holes, silhouettes
    and depth jumps crossing the band edges."""
    rng = np.random.default_rng(4)
    o, d = _camera([0, -5, 1], np.zeros(3), (47, 53), focal=60.0)
    normal, position, hit = _gbuffer(_sphere(o, d, np.zeros(3), 1.0),
                                     _sphere(o, d, np.array([0.6, 1.0, 0.3]), 0.5))
    normal[rng.random(normal.shape[:2]) < 0.03] = np.nan
    mask = (hit >= 0) & (rng.random(hit.shape) > 0.02)
    whole = curvature.curvatures(normal, position, mask, length_scale="pixel")
    monkeypatch.setattr(curvature, "_CURVATURE_BAND", band)
    banded = curvature.curvatures(normal, position, mask, length_scale="pixel")
    for a, b in zip(whole, banded, strict=True):
        np.testing.assert_array_equal(a, b)
