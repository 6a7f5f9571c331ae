"""MERL format, angle mapping and lookup, against independent references."""

import math

import numpy as np
import pytest

from brdf_reconstruct.core.brdf import merl

SCALE = (1 / 1500, 1.15 / 1500, 1.66 / 1500)


def _write_raw(path, stored, dims=(90, 90, 180)):
    """Write a MERL file byte by byte, independently of merl.write."""
    with open(path, "wb") as f:
        f.write(np.asarray(dims, dtype="<i4").tobytes())
        f.write(np.asarray(stored, dtype="<f8").tobytes())


def _random_stored(rng):
    stored = rng.uniform(0.0, 5000.0, size=3 * merl.N_CELLS)
    stored[rng.random(stored.size) < 0.05] = -1.0  # unmeasured cells
    return stored


# ---------------------------------------------------------------------------- file I/O
def test_read_uses_reference_layout_and_scales(tmp_path):
    rng = np.random.default_rng(1)
    stored = _random_stored(rng)
    path = tmp_path / "a.binary"
    _write_raw(path, stored)
    table = merl.read(path)
    assert table.shape == (3, 90, 90, 180) and table.dtype == np.float64
    for _ in range(200):
        c, ith, itd, ipd = (int(rng.integers(m)) for m in (3, 90, 90, 180))
        raw = stored[c * 1458000 + ipd + 180 * (itd + 90 * ith)]
        if raw < 0:
            assert math.isnan(table[c, ith, itd, ipd])
        else:
            assert table[c, ith, itd, ipd] == raw * SCALE[c]


def test_write_read_bit_exact(tmp_path):
    """A table on the format's grid (e.g. any table read from a file) survives
    write -> read bit for bit, NaN cells included."""
    path = tmp_path / "src.binary"
    _write_raw(path, _random_stored(np.random.default_rng(2)))
    table = merl.read(path)
    merl.write(tmp_path / "out.binary", table)
    again = merl.read(tmp_path / "out.binary")
    assert np.array_equal(np.isnan(table), np.isnan(again))
    assert np.array_equal(table.view(np.uint64)[~np.isnan(table)],
                          again.view(np.uint64)[~np.isnan(again)])
    # and the file it writes is stable under a second round trip
    merl.write(tmp_path / "out2.binary", again)
    assert (tmp_path / "out.binary").read_bytes() == (tmp_path / "out2.binary").read_bytes()
    assert (tmp_path / "out.binary").stat().st_size == 34_992_012


def test_write_read_arbitrary_table_within_one_ulp(tmp_path):
    table = np.random.default_rng(3).lognormal(0.0, 3.0, size=(3, 90, 90, 180))
    merl.write(tmp_path / "t.binary", table)
    np.testing.assert_array_max_ulp(merl.read(tmp_path / "t.binary"), table, maxulp=1)


def test_unmeasured_written_negative(tmp_path):
    table = np.ones((3, 90, 90, 180))
    table[1, 5, 6, 7] = np.nan
    merl.write(tmp_path / "t.binary", table)
    raw = np.fromfile(tmp_path / "t.binary", dtype="<f8", offset=12)
    assert raw[1458000 + 7 + 180 * (6 + 90 * 5)] < 0
    assert np.isnan(merl.read(tmp_path / "t.binary")[1, 5, 6, 7])


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda p: _write_raw(p, np.zeros(3 * 90 * 90 * 90), dims=(90, 90, 90)), "header"),
        (lambda p: p.write_bytes(np.asarray((90, 90, 180), "<i4").tobytes() + b"\0" * 800),
         "truncated"),
        (lambda p: _write_raw(p, np.zeros(3 * merl.N_CELLS + 1)), "too long"),
        (lambda p: p.write_bytes(b"abc"), "no header"),
    ],
)
def test_bad_files_raise_value_error_naming_file(tmp_path, make, message):
    path = tmp_path / "broken.binary"
    make(path)
    with pytest.raises(ValueError, match=message) as err:
        merl.read(path)
    assert "broken.binary" in str(err.value)


def test_write_rejects_inf_and_wrong_shape(tmp_path):
    with pytest.raises(ValueError, match="shape"):
        merl.write(tmp_path / "x.binary", np.ones((3, 90, 90, 90)))
    bad = np.ones((3, 90, 90, 180))
    bad[0, 0, 0, 0] = np.inf
    with pytest.raises(ValueError, match="Inf"):
        merl.write(tmp_path / "x.binary", bad)


# ------------------------------------------------------------------------ angle mapping
def _rot_z(a):
    return np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])


def _rot_y(a):
    return np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])


def _reference_angles(wi, wo):
    """Rusinkiewicz angles by explicit rotation matrices, one pair at a time."""
    h = (wi + wo) / np.linalg.norm(wi + wo)
    theta_h = math.acos(min(1.0, h[2]))
    phi_h = math.atan2(h[1], h[0])
    d = _rot_y(-theta_h) @ _rot_z(-phi_h) @ wi
    theta_d = math.acos(max(-1.0, min(1.0, d[2])))
    phi_d = math.atan2(d[1], d[0])
    if phi_d < 0:
        phi_d += math.pi
    return theta_h, theta_d, phi_d


def _random_hemisphere(rng, n):
    w = rng.normal(size=(n, 3))
    w[:, 2] = np.abs(w[:, 2])
    return w / np.linalg.norm(w, axis=1, keepdims=True)


def test_angles_match_rotation_reference():
    rng = np.random.default_rng(4)
    wi, wo = _random_hemisphere(rng, 500), _random_hemisphere(rng, 500)
    got = np.stack(merl.half_diff_from_dirs(wi, wo), axis=1)
    ref = np.array([_reference_angles(a, b) for a, b in zip(wi, wo, strict=True)])
    np.testing.assert_allclose(got, ref, atol=1e-12)
    # bins against the reference reader's formulas
    ref_cells = np.stack([
        np.minimum(np.floor(90 * np.sqrt(ref[:, 0] / (np.pi / 2))), 89),
        np.minimum(np.floor(ref[:, 1] / (np.pi / 2) * 90), 89),
        np.minimum(np.floor(ref[:, 2] / np.pi * 180), 179),
    ], axis=1)
    np.testing.assert_array_equal(merl.cells_from_dirs(wi, wo), ref_cells)


def test_directions_from_angles_round_trip_and_reciprocity():
    rng = np.random.default_rng(5)
    wi, wo = _random_hemisphere(rng, 1000), _random_hemisphere(rng, 1000)
    angles = merl.half_diff_from_dirs(wi, wo)
    wi2, wo2 = merl.dirs_from_half_diff(*angles)
    # the rebuilt pair is the original rotated about z (phi_h dropped): same angles
    np.testing.assert_allclose(np.stack(merl.half_diff_from_dirs(wi2, wo2)),
                               np.stack(angles), atol=1e-10)
    # the phi_d fold may swap light and view, so compare the elevations unordered
    np.testing.assert_allclose(np.sort(np.stack([wi2[:, 2], wo2[:, 2]]), axis=0),
                               np.sort(np.stack([wi[:, 2], wo[:, 2]]), axis=0), atol=1e-12)
    np.testing.assert_allclose(np.sum(wi2 * wo2, axis=1), np.sum(wi * wo, axis=1), atol=1e-12)
    # reciprocity: swapping light and view gives the same cell
    np.testing.assert_array_equal(merl.cells_from_dirs(wi, wo), merl.cells_from_dirs(wo, wi))


def test_every_cell_centre_maps_back_to_its_cell():
    grid = np.indices(merl.SHAPE).reshape(3, -1).T
    wi, wo = merl.cell_directions()
    np.testing.assert_array_equal(merl.cells_from_dirs(wi, wo), grid)
    np.testing.assert_array_equal(merl.cells_from_linear(merl.linear_index(grid)), grid)


def test_phi_d_zero_falls_in_bin_zero():
    # wi and wo in the x-z plane, mirror images about a tilted half vector
    cells = merl.cells_from_angles(np.array([0.3]), np.array([0.4]), np.array([0.0]))
    assert cells[0, 2] == 0
    wi, wo = merl.dirs_from_half_diff(0.3, 0.4, 0.0)
    assert merl.cells_from_dirs(wi[None], wo[None])[0, 2] == 0


def test_valid_cells_about_three_quarters():
    assert 1_000_000 < merl.valid_cells().sum() < 1_200_000


def test_cell_directions_are_the_grid_through_dirs_from_half_diff_bit_for_bit():
    """cell_directions broadcasts per-bin sines and cosines: the same numbers as
    dirs_from_half_diff on every cell of the grid."""
    grid = np.indices(merl.SHAPE).reshape(3, -1).T
    wi_ref, wo_ref = merl.dirs_from_half_diff(*merl.angles_from_cells(grid))
    wi, wo = merl.cell_directions()
    np.testing.assert_array_equal(wi, wi_ref)
    np.testing.assert_array_equal(wo, wo_ref)
    assert wi.flags.c_contiguous and not wi.flags.writeable and not wo.flags.writeable


# ----------------------------------------------------------------------------- lookup
def _random_rotation(rng):
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def test_evaluate_is_frame_independent_and_matches_bins():
    rng = np.random.default_rng(6)
    table = rng.uniform(0.1, 2.0, size=(3, 90, 90, 180))
    wi, wo = _random_hemisphere(rng, 300), _random_hemisphere(rng, 300)
    n = np.tile([0.0, 0.0, 1.0], (300, 1))
    R = _random_rotation(rng)
    local = merl.evaluate(table, n, wi, wo)
    world = merl.evaluate(table, n @ R.T, wi @ R.T, wo @ R.T)
    np.testing.assert_allclose(world, local, rtol=0, atol=0)
    idx = merl.linear_index(merl.cells_from_dirs(wi, wo))
    np.testing.assert_array_equal(local, table.reshape(3, -1)[:, idx].T)


def test_trilinear_reproduces_centres_and_linear_fields():
    rng = np.random.default_rng(7)
    cells = np.stack([rng.integers(1, 89, 200), rng.integers(1, 89, 200),
                      rng.integers(0, 180, 200)], axis=1)
    table = rng.uniform(0.1, 2.0, size=(3, 90, 90, 180))
    wi, wo = merl.dirs_from_half_diff(*merl.angles_from_cells(cells))
    n = np.tile([0.0, 0.0, 1.0], (200, 1))
    ok = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    got = merl.evaluate(table, n[ok], wi[ok], wo[ok], interpolation="trilinear")
    want = table.reshape(3, -1)[:, merl.linear_index(cells[ok])].T
    np.testing.assert_allclose(got, want, rtol=1e-9)
    # a field linear in theta_d: trilinear is exact between interior centres
    lin = np.broadcast_to((np.arange(90) + 0.5)[None, None, :, None] / 90 * np.pi / 2,
                          (3, 90, 90, 180)).copy()
    th = rng.uniform(0.05, 1.0, 200)
    td = rng.uniform(np.pi / 2 / 90, np.pi / 2 * 88.5 / 90, 200)
    pd = rng.uniform(0, np.pi, 200)
    wi, wo = merl.dirs_from_half_diff(th, td, pd)
    ok = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    got = merl.evaluate(lin, n[ok], wi[ok], wo[ok], interpolation="trilinear")
    np.testing.assert_allclose(got[:, 0], td[ok], atol=1e-9)


def test_evaluate_zero_below_horizon_and_fills_unmeasured():
    table = np.full((3, 90, 90, 180), np.nan)
    table.reshape(3, -1)[:, merl.valid_cells()] = 1.0
    n = np.array([[0.0, 0.0, 1.0]] * 3)
    l = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [1.0, 0.0, 1e-9]])  # noqa: E741
    v = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 1e-9]])
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    l /= np.linalg.norm(l, axis=1, keepdims=True)
    for mode in ("nearest", "trilinear"):
        rho = merl.evaluate(table, n, l, v, interpolation=mode)
        assert np.all(np.isfinite(rho))
        np.testing.assert_array_equal(rho[1], 0.0)  # light below the surface
        np.testing.assert_allclose(rho[[0, 2]], 1.0)  # grazing pair in an unmeasured cell


def test_fill_unmeasured_keeps_measured_cells():
    rng = np.random.default_rng(8)
    table = rng.uniform(size=(3, 90, 90, 180))
    holes = rng.random(table.shape) < 0.3
    filled = merl.fill_unmeasured(np.where(holes, np.nan, table))
    assert np.all(np.isfinite(filled))
    np.testing.assert_array_equal(filled[~holes], table[~holes])


def _fill_unmeasured_whole(table):
    """fill_unmeasured as it was written before it worked in slabs of phi_d."""
    out = np.array(table, dtype=np.float64)
    for axis in (2, 1):
        if not np.isnan(out).any():
            break
        out = merl._fill_along(out, axis, reverse=False)
        out = merl._fill_along(out, axis, reverse=True)
    return np.nan_to_num(out, nan=0.0)


def _holed_tables(rng):
    """Tables with unmeasured cells of every kind: below the horizon, scattered,
    whole theta_d columns and theta_h lines, Inf, and none at all."""
    below = rng.uniform(size=(3, 90, 90, 180))
    below.reshape(3, -1)[:, ~merl.valid_cells()] = np.nan
    scattered = np.where(rng.random(below.shape) < 0.3, np.nan, below)
    sparse = np.where(rng.random(below.shape) < 0.97, np.nan, below)
    sparse[1, 5, :, 7] = np.nan  # a whole column: needs the theta_h pass
    sparse[0, :, :, 3] = np.inf
    return [below, scattered, sparse, rng.uniform(size=(3, 90, 90, 180)),
            np.full((3, 90, 90, 180), np.nan)]


def test_fill_unmeasured_in_slabs_equals_the_whole_table_at_once():
    rng = np.random.default_rng(9)
    for table in _holed_tables(rng):
        np.testing.assert_array_equal(merl.fill_unmeasured(table),
                                      _fill_unmeasured_whole(table))


def test_fill_unmeasured_at_equals_fill_unmeasured_there():
    rng = np.random.default_rng(10)
    for table in _holed_tables(rng):
        index = rng.integers(0, merl.N_CELLS, 20_000)
        index[:3] = np.ravel_multi_index((5, 3, 7), merl.SHAPE)  # in the empty column
        np.testing.assert_array_equal(merl.fill_unmeasured_at(table, index),
                                      merl.fill_unmeasured(table).reshape(3, -1)[:, index])


# ------------------------------------------------------------ fused per-sample binning
def _unit(x):
    return x / np.linalg.norm(x, axis=-1, keepdims=True)


def test_einsum_dot_rounding_is_reproduced():
    """cells_about_normals relies on np.einsum rounding a 3-term dot product as
    (a0 b0 + a2 b2) + a1 b1; if numpy changes that, this flags it."""
    rng = np.random.default_rng(11)
    a, b = rng.normal(size=(2, 50_000, 3))
    ref = np.einsum("...i,...i->...", a, b)
    np.testing.assert_array_equal(merl._dot_einsum(a.T, b.T), ref)
    np.testing.assert_array_equal(merl._dot_einsum(a[0], b.T), np.einsum("i,...i->...", a[0], b))


def test_degenerate_phi_d_bins_do_not_hang_on_rounding():
    """Where phi_d is undefined (l = v: a flash on the camera) or on the wrap (l, v
    and the normal coplanar: phi_d = 0 and pi are one direction pair), its bin is
    0 on both paths, and the same whatever the arrays' layout: numpy's vectorised
    arctan2 rounds an element differently with its place in the array (on this
    project's AVX-512 hosts the step-by-step and the one-pass bins differed there
    in 1 run of 4)."""
    rng = np.random.default_rng(5)
    count = 2 * merl._CHUNK + 101
    n = _unit(rng.normal(size=(count, 3)))
    n[:, 2] = np.abs(n[:, 2])
    w = _unit(n + 0.6 * _unit(rng.normal(size=(count, 3))))  # above the horizon mostly
    flash = merl.cells_about_normals(n, w, w)  # l = v
    assert np.all(flash[:, 2] == 0) and np.all(flash[:, 1] == 0)
    np.testing.assert_array_equal(merl.cells_from_dirs(merl.to_local(n, w),
                                                       merl.to_local(n, w)), flash)
    light = _unit(np.array([0.3, -0.4, 0.87]))
    coplanar = merl.cells_about_normals(n, light, n)  # v = n: l, v, n in one plane
    assert np.all(coplanar[:, 2] == 0)
    for offset in (1, 2, 3, 5, 8):  # another layout: the same bins, bit for bit
        np.testing.assert_array_equal(merl.cells_about_normals(n[offset:], w[offset:],
                                                               w[offset:]), flash[offset:])
        np.testing.assert_array_equal(merl.cells_about_normals(n[offset:], light, n[offset:]),
                                      coplanar[offset:])
        part = n[offset:]
        np.testing.assert_array_equal(
            merl.cells_from_dirs(merl.to_local(part, np.broadcast_to(light, part.shape)),
                                 merl.to_local(part, part)), coplanar[offset:])


def test_cells_about_normals_equals_to_local_then_cells_from_dirs():
    """Bit for bit the same bins as the step-by-step path, including the poles,
    z = -0, wi = -wo (degenerate half vector), wi = wo, a constant light and a
    length that is not a multiple of the block size."""
    rng = np.random.default_rng(12)
    count = 3 * merl._CHUNK + 17
    n = _unit(rng.normal(size=(count, 3)))
    n[:50] = [0.0, 0.0, 1.0]
    n[50:100] = [0.0, 0.0, -1.0]
    n[100:150, 2] = -0.0
    n[100:150] = _unit(n[100:150])
    wi = _unit(rng.normal(size=(count, 3)))
    wo = _unit(rng.normal(size=(count, 3)))
    wo[200:300] = -wi[200:300]
    wo[300:400] = wi[300:400]
    wo[400:450] = n[400:450]
    ref = merl.cells_from_dirs(merl.to_local(n, wi), merl.to_local(n, wo))
    np.testing.assert_array_equal(merl.cells_about_normals(n, wi, wo), ref)
    light = _unit(np.array([0.5, 0.3, 0.81]))
    ref = merl.cells_from_dirs(merl.to_local(n, np.broadcast_to(light, n.shape)),
                               merl.to_local(n, wo))
    got = merl.cells_about_normals(n, light, wo)
    assert got.dtype == np.int64 and got.shape == (count, 3)
    np.testing.assert_array_equal(got, ref)
    assert merl.cells_about_normals(n[:0], light, wo[:0]).shape == (0, 3)


def test_cells_about_normals_at_bin_edges_and_poles():
    """The fast rotation is guarded: pairs built at (and within 1e-15 .. 1e-9 of)
    theta_h / theta_d / phi_d bin edges, in-plane pairs (phi_d at 0 or pi), l ~ v
    and n ~ h, in random frames, bin exactly as the trigonometric path does."""
    rng = np.random.default_rng(13)
    k = 60_000
    idx = [rng.integers(0, m + 1, k) for m in (90, 90, 180)]
    jitter = [rng.choice([0.0, 1e-15, -1e-15, 1e-12, -1e-9, 0.5], size=k) for _ in range(3)]
    th = np.clip(((idx[0] + jitter[0]) / 90) ** 2 * (np.pi / 2), 0.0, np.pi / 2)
    td = np.clip((idx[1] + jitter[1]) / 90 * (np.pi / 2), 0.0, np.pi)
    pd = (idx[2] + jitter[2]) / 180 * np.pi
    wi, wo = merl.dirs_from_half_diff(th, td, pd)
    q = _unit(rng.normal(size=(k, 4)))  # random rotations (unit quaternions)
    w, x, y, z = q.T
    R = np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], axis=1)
    cases = [(np.tile([0.0, 0.0, 1.0], (k, 1)), wi, wo),
             (R[:, :, 2].copy(), np.einsum("kij,kj->ki", R, wi), np.einsum("kij,kj->ki", R, wo))]
    n = _unit(rng.normal(size=(k, 3)))
    a = _unit(rng.normal(size=(k, 3)))
    eps = 10.0 ** rng.uniform(-12, -2, (k, 1))
    b = _unit(a + eps * rng.normal(size=(k, 3)))
    cases += [(n, a, b), (_unit(_unit(a + b) + eps * rng.normal(size=(k, 3))), a, b)]
    for n, wi, wo in cases:
        ref = merl.cells_from_dirs(merl.to_local(n, wi), merl.to_local(n, wo))
        np.testing.assert_array_equal(merl.cells_about_normals(n, wi, wo), ref)
