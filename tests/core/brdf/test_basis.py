"""The PCA basis: mapping, build, cache keyed by data and settings."""

import numpy as np
import pytest

from brdf_reconstruct.core.brdf import basis, merl


def _lambert_table(albedo):
    table = np.full((3, merl.N_CELLS), np.nan)
    table[:, merl.valid_cells()] = np.asarray(albedo, dtype=float)[:, None] / np.pi
    return table.reshape(3, *merl.SHAPE)


def _folder(tmp_path, albedos):
    folder = tmp_path / "merl"
    folder.mkdir(exist_ok=True)
    for i, a in enumerate(albedos):
        merl.write(folder / f"m{i}.binary", _lambert_table(a))
    return folder


def test_mapping_round_trip(default_basis):
    B = default_basis
    rows = np.arange(0, len(B.cells), 997)
    rho = np.random.default_rng(0).lognormal(-1.0, 2.0, size=(len(rows), 3))
    np.testing.assert_allclose(B.from_mapped(B.to_mapped(rho, rows), rows), rho, rtol=1e-9)


def test_table_from_rows_is_the_fill_sources_gather(default_basis):
    B = default_basis
    values = np.random.default_rng(1).normal(size=(len(B.cells), 3))
    table = B.table_from_rows(values)
    expected = np.ascontiguousarray(values.T[:, B.source_rows(np.arange(merl.N_CELLS))])
    np.testing.assert_array_equal(table, expected.reshape(3, *merl.SHAPE))
    assert table.flags.c_contiguous and table.dtype == np.float64


def test_default_basis_shape_and_budget(default_basis, tmp_path):
    B = default_basis
    assert B.Q.dtype == np.float32 and B.Q.shape == (len(B.cells), basis.N_COMPONENTS)
    assert B.info["n_columns"] >= 300  # >= 100 materials x 3 channels
    assert np.all(np.diff(B.singular_values) <= 0)
    # columns of Q are orthogonal with norms = singular values (Q = U S)
    gram = B.Q.astype(np.float64).T @ B.Q.astype(np.float64)
    np.testing.assert_allclose(np.sqrt(np.diag(gram)), B.singular_values, rtol=1e-4)
    off = gram / np.outer(B.singular_values, B.singular_values) - np.eye(B.n_components)
    assert np.abs(off).max() < 1e-3
    basis.save(B, tmp_path / "b.npz")
    assert (tmp_path / "b.npz").stat().st_size < 200e6


def test_merl_folder_basis_cached_and_rebuilt_when_data_change(tmp_path, monkeypatch):
    folder = _folder(tmp_path, [[0.1, 0.2, 0.3], [0.5, 0.4, 0.3], [0.9, 0.9, 0.8]])
    cache = tmp_path / "cache"
    first = basis.load_merl_folder(folder, cache_dir=cache, n_components=4)
    assert first.info["n_columns"] == 9
    assert len(list(cache.glob("basis-*.npz"))) == 1

    calls = []
    real_build = basis.build
    monkeypatch.setattr(basis, "build", lambda *a, **k: calls.append(1) or real_build(*a, **k))
    again = basis.load_merl_folder(folder, cache_dir=cache, n_components=4)
    assert calls == [] and again.fingerprint == first.fingerprint
    np.testing.assert_array_equal(again.Q, first.Q)

    merl.write(folder / "m1.binary", _lambert_table([0.05, 0.6, 0.2]))  # same name and size
    changed = basis.load_merl_folder(folder, cache_dir=cache, n_components=4)
    assert calls == [1] and changed.fingerprint != first.fingerprint
    basis.load_merl_folder(folder, cache_dir=cache, n_components=3)  # settings are keyed too
    assert calls == [1, 1]


def test_damaged_cache_is_rebuilt(tmp_path):
    folder = _folder(tmp_path, [[0.1, 0.2, 0.3], [0.5, 0.4, 0.3]])
    cache = tmp_path / "cache"
    basis.load_merl_folder(folder, cache_dir=cache, n_components=2)
    (path,) = cache.glob("basis-*.npz")
    path.write_bytes(b"garbage")
    rebuilt = basis.load_merl_folder(folder, cache_dir=cache, n_components=2)
    assert rebuilt.n_components == 2


def test_merl_folder_errors(tmp_path):
    with pytest.raises(ValueError, match="does not exist"):
        basis.load_merl_folder(tmp_path / "nope")
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="no MERL"):
        basis.load_merl_folder(tmp_path / "empty")


def test_lambert_family_reconstructs_from_one_sample(tmp_path):
    """A basis of grey Lambert tables has a one-dimensional span; one sample pins it."""
    folder = _folder(tmp_path, [[a, a, a] for a in (0.05, 0.2, 0.5, 0.8)])
    B = basis.load_merl_folder(folder, cache_dir=tmp_path / "c", n_components=1)
    from brdf_reconstruct.core.method import reconstruct

    truth = _lambert_table([0.3, 0.3, 0.3])
    cell = merl.cells_from_linear(B.cells[[1000]])
    rec = reconstruct.reconstruct(B, cell, truth.reshape(3, -1)[:, B.cells[[1000]]].T)
    # x = ln((rho c + eps)/(m + eps)) is not linear in rho, so a new albedo is not
    # exactly in the span; the level must still be right to a few percent
    got = rec.table.reshape(3, -1)[:, B.cells]
    np.testing.assert_allclose(np.median(got), 0.3 / np.pi, rtol=0.05)


def _block_count(n_cells, n_columns):
    from brdf_reconstruct.core.brdf.basis import _BLOCK_BYTES

    block = int(np.clip(_BLOCK_BYTES // (8 * n_columns), 4096, 1 << 16)) // 1024 * 1024
    return -(-n_cells // block)


def test_build_reports_progress_after_every_table_and_block():
    calls = []
    tables = [_lambert_table(a) for a in ([0.1, 0.2, 0.3], [0.5, 0.4, 0.3], [0.9, 0.9, 0.8])]
    B = basis.build(iter(tables), n_components=2, progress=lambda f, m: calls.append((f, m)),
                    n_tables=len(tables))
    n_blocks = _block_count(B.info["n_cells"], B.info["n_columns"])
    fractions = [f for f, _ in calls]
    # one call per table and one per block in each of the two passes
    assert len(calls) == len(tables) + 2 * n_blocks
    assert fractions == sorted(fractions) and fractions[-1] == 1.0 and fractions[0] > 0
    assert all("\n" not in m and "BRDF basis" in m for _, m in calls)
    assert calls[0][1].endswith("table 1/3")


def _spec_tables():
    from brdf_reconstruct.core.brdf import database

    return [database.training_specs()[i] for i in (0, 40, 80, 120, 149)]


def test_tables_made_in_threads_give_the_basis_of_the_stream():
    """build_from (tables made two at a time, valid cells only) against build (full
    tables, one after the other): the same basis, bit for bit, whatever the threads."""
    import functools

    from brdf_reconstruct.core.brdf import database

    specs = _spec_tables()
    streamed = basis.build((database.make_table(s) for s in specs), n_components=8,
                           n_tables=len(specs), workers=1)
    makers = [functools.partial(database.valid_values, s) for s in specs]
    threaded = basis.build_from(makers, n_components=8, workers=2)
    for name in ("cells", "Q", "mean", "median", "cosine", "singular_values", "x_range"):
        np.testing.assert_array_equal(getattr(threaded, name), getattr(streamed, name), name)


def test_the_build_matches_a_direct_svd_of_the_mapped_data():
    """The Gram route against numpy's SVD of the centred, mapped training matrix
    written out here (float64): the same singular values and, up to sign, the same
    scaled directions Q = U S. The Gram matrix squares the singular values, so its
    (float32 per block, float64 summed) precision is relative to the largest one."""
    from brdf_reconstruct.core.brdf import database

    tables = [database.make_table(s) for s in _spec_tables()]
    B = basis.build(iter(tables), n_components=6, n_tables=len(tables))
    valid = merl.valid_cells()
    cos = basis.cosine_map()[valid]
    X = np.concatenate([t.reshape(3, -1)[:, valid] for t in tables]) * cos  # (15, R)
    m = np.median(X, axis=0)
    x = np.log((X + basis.EPS) / (m + basis.EPS))
    D = (x - x.mean(axis=0)).T  # (R, 15)
    U, s, _ = np.linalg.svd(D, full_matrices=False)
    np.testing.assert_allclose(B.singular_values, s[:6], rtol=0, atol=1e-6 * s[0])
    Q = U[:, :6] * s[:6]
    sign = np.sign(np.sum(Q * B.Q, axis=0))
    np.testing.assert_allclose(B.Q, Q * sign, rtol=0, atol=1e-5 * np.abs(Q).max())
    np.testing.assert_allclose(B.median, m, rtol=1e-6)
    # the clipping range of from_mapped is the mapped data's, not the centred data's
    np.testing.assert_allclose(B.x_range, [x.min(), x.max()], rtol=1e-5)


def test_a_cancel_while_tables_are_made_in_threads_stops_at_the_next_table():
    import functools

    from brdf_reconstruct.core import progress
    from brdf_reconstruct.core.brdf import database

    made, seen = [], []

    def make(spec):
        made.append(spec["name"])
        return database.valid_values(spec)

    makers = [functools.partial(make, s) for s in database.training_specs()[:30]]
    with pytest.raises(progress.Cancelled):
        basis.build_from(makers, n_components=4, progress=lambda f, m: seen.append(m),
                         cancelled=lambda: len(seen) >= 3, workers=2)
    assert len(seen) == 3
    assert len(made) <= 3 + 3  # the ones running or queued when Esc came, no more


def test_a_cancelled_build_raises_and_caches_nothing(tmp_path):
    from brdf_reconstruct.core import progress

    folder = _folder(tmp_path, [[0.1, 0.2, 0.3], [0.5, 0.4, 0.3], [0.9, 0.9, 0.8]])
    seen = []

    def cancelled():  # the user presses Esc after the second table
        return len(seen) >= 2

    cache = tmp_path / "cache"
    with pytest.raises(progress.Cancelled):
        basis.load_merl_folder(folder, cache_dir=cache, n_components=2,
                               progress=lambda f, m: seen.append(m), cancelled=cancelled)
    assert len(seen) == 2  # stopped at the first check after the request
    assert not cache.exists() or list(cache.iterdir()) == []
    # the next run builds it as if nothing had happened
    B = basis.load_merl_folder(folder, cache_dir=cache, n_components=2)
    assert B.n_components == 2 and len(list(cache.glob("basis-*.npz"))) == 1


def test_measured_basis_from_the_pack_is_cached_and_keyed_by_its_materials(tmp_path):
    from brdf_reconstruct.core.brdf import metrics, nbrdf
    from testkit.measured import PACK

    if not PACK.is_file():
        pytest.skip(f"{PACK} not found")
    names = ["green-latex", "pink-fabric2", "gold-metallic-paint"]
    cache = tmp_path / "cache"
    B = basis.load_measured(PACK, names, cache_dir=cache, n_components=9)
    assert B.info["n_columns"] == 9 and B.n_components == 9
    again = basis.load_measured(PACK, names, cache_dir=cache, n_components=9)
    assert again.fingerprint == B.fingerprint and len(list(cache.glob("basis-*.npz"))) == 1
    other = basis.load_measured(PACK, names[:2], cache_dir=cache, n_components=6)
    assert other.fingerprint != B.fingerprint
    # a training material lies in the span of its own basis: projected, it renders
    # as itself (the 9 columns are all kept)
    pack = nbrdf.load(PACK)
    truth = nbrdf.tabulate(pack, pack.index("pink-fabric2"))
    assert metrics.sphere_error(B.project(truth), truth) < 0.02
    with pytest.raises(ValueError, match="no material named velvet"):
        basis.load_measured(PACK, ["velvet"], cache_dir=cache)


def test_a_basis_lists_the_materials_it_was_built_from():
    tables = [_lambert_table(a) for a in ([0.1, 0.2, 0.3], [0.5, 0.4, 0.3])]
    B = basis.build(iter(tables), n_components=2, n_tables=2, names=["dark", "light"])
    assert B.info["materials"] == ["dark", "light"]
    assert "materials" not in basis.build(iter(tables), n_components=2).info
    with pytest.raises(ValueError, match="3 names for 2 training tables"):
        basis.build(iter(tables), n_components=2, names=["a", "b", "c"])
    with pytest.raises(ValueError, match="1 names for 2 training tables"):
        basis.build_from([lambda t=t: t for t in tables], n_components=2, names=["a"])


def test_a_relative_cache_folder_is_taken_from_the_working_folder(tmp_path, monkeypatch):
    """A pipeline run with ``BRDF_RECONSTRUCT_CACHE=.cache`` must not resolve the
    folder later against whatever folder Blender renders in."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("BRDF_RECONSTRUCT_CACHE", "rel/cache")
    folder = basis.default_cache_dir()
    assert folder.is_absolute()
    assert folder == tmp_path / "rel" / "cache"
