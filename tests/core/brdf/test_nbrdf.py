"""The measured pack: neural BRDFs tabulated on the MERL grid, checked against the
network formula written out here, with the directions built from scratch."""

import pathlib

import numpy as np
import pytest

from brdf_reconstruct.core.brdf import merl, nbrdf
from testkit.measured import PACK

needs_pack = pytest.mark.skipif(not PACK.is_file(), reason=f"{PACK} not found")


def _rot_y(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rot_z(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _by_hand(W1, b1, W2, b2, W3, b3, x):
    a = np.maximum(x @ W1.astype(float) + b1, 0)
    a = np.maximum(a @ W2.astype(float) + b2, 0)
    return np.maximum(np.exp(a @ W3.astype(float) + b3) - 1, 0)


@needs_pack
@pytest.mark.parametrize("name", ["aluminium", "pink-fabric2", "green-latex"])
def test_tabulation_matches_the_network_at_random_cells(name):
    pack = nbrdf.load(PACK)
    m = pack.index(name)
    table = nbrdf.tabulate(pack, m)
    assert table.shape == (3, 90, 90, 180) and table.dtype == np.float64
    rng = np.random.default_rng(7)
    i, j, k = rng.integers(0, 90, 400), rng.integers(0, 90, 400), rng.integers(0, 180, 400)
    # the cell centre as a light/view pair: d in the half-vector frame, rotated out
    th = ((i + 0.5) / 90) ** 2 * np.pi / 2
    td, pd = (j + 0.5) / 90 * np.pi / 2, (k + 0.5) / 180 * np.pi
    phi_h = rng.uniform(0, 2 * np.pi, 400)  # isotropic: any phi_h gives the same cell
    expected = np.full((400, 3), np.nan)
    for n in range(400):
        d = np.array([np.sin(td[n]) * np.cos(pd[n]), np.sin(td[n]) * np.sin(pd[n]),
                      np.cos(td[n])])
        to_world = _rot_z(phi_h[n]) @ _rot_y(th[n])
        wi = to_world @ d
        wo = to_world @ (2 * np.dot(d, [0, 0, 1]) * np.array([0, 0, 1]) - d)
        if wi[2] <= 0 or wo[2] <= 0:
            continue  # below the horizon: unmeasured (NaN) in the table
        h = (wi + wo) / np.linalg.norm(wi + wo)
        theta_h = np.arccos(np.clip(h[2], -1, 1))
        d_back = _rot_y(-theta_h) @ _rot_z(-np.arctan2(h[1], h[0])) @ wi
        x = np.concatenate([[np.sin(theta_h), 0.0, np.cos(theta_h)], d_back])
        expected[n] = _by_hand(pack.W1[m], pack.b1[m], pack.W2[m], pack.b2[m], pack.W3[m],
                               pack.b3[m], x)
    got = table[:, i, j, k].T
    below = np.isnan(expected[:, 0])
    assert np.all(np.isnan(got[below])) and not np.any(np.isnan(got[~below]))
    # float32 inside the network against float64 here
    np.testing.assert_allclose(got[~below], expected[~below], rtol=2e-4, atol=1e-7)
    assert np.all(np.isfinite(table[np.isfinite(table)])) and np.nanmin(table) >= 0


@needs_pack
def test_the_table_enters_the_basis_like_a_merl_file(tmp_path):
    """A tabulated material written as .binary reads back as the same table (to the
    format's storage rounding), NaN where the pack is unmeasured."""
    pack = nbrdf.load(PACK)
    table = nbrdf.tabulate(pack, pack.index("green-latex"))
    merl.write(tmp_path / "green-latex.binary", table)
    back = merl.read(tmp_path / "green-latex.binary")
    assert np.array_equal(np.isnan(back), np.isnan(table))
    np.testing.assert_allclose(back[np.isfinite(back)], table[np.isfinite(table)], rtol=1e-12)
    assert np.array_equal(np.isnan(table[0]).ravel(), ~merl.valid_cells())


def test_a_damaged_pack_is_refused_in_one_sentence(tmp_path):
    good = {"names": np.array(["a"]), "W1": np.zeros((1, 6, 21), np.float32),
            "b1": np.zeros((1, 21), np.float32), "W2": np.zeros((1, 21, 21), np.float32),
            "b2": np.zeros((1, 21), np.float32), "W3": np.zeros((1, 21, 3), np.float32),
            "b3": np.zeros((1, 3), np.float32)}
    np.savez(tmp_path / "ok.npz", **good)
    assert nbrdf.load(tmp_path / "ok.npz").names == ("a",)
    cases = {"short.npz": {**good, "W2": np.zeros((1, 21, 20), np.float32)},
             "nan.npz": {**good, "b3": np.full((1, 3), np.nan, np.float32)},
             "lacking.npz": {k: v for k, v in good.items() if k != "W3"}}
    words = {"short.npz": "W2 has shape", "nan.npz": "b3 holds NaN", "lacking.npz": "lacks W3"}
    for name, arrays in cases.items():
        np.savez(tmp_path / name, **arrays)
        with pytest.raises(ValueError, match=words[name]):
            nbrdf.load(tmp_path / name)
    (tmp_path / "text.npz").write_text("not a zip")
    with pytest.raises(ValueError, match="not a neural-BRDF pack"):
        nbrdf.load(tmp_path / "text.npz")
    with pytest.raises(FileNotFoundError):
        nbrdf.load(pathlib.Path(tmp_path / "missing.npz"))
    with pytest.raises(ValueError, match="no material named zz"):
        nbrdf.load(tmp_path / "ok.npz").index("zz")


@needs_pack
def test_folds_cover_the_pack_once_and_spread_each_class():
    from testkit import measured

    names = nbrdf.load(PACK).names
    folds = measured.folds(names, k=5)
    flat = [n for f in folds for n in f]
    assert sorted(flat) == sorted(names) and len(flat) == len(set(flat))
    assert [len(f) for f in folds] == [16] * 5
    for kind in measured.CLASSES:
        counts = [sum(measured.material_class(n) == kind for n in f) for f in folds]
        assert max(counts) - min(counts) <= 1, (kind, counts)


@needs_pack
def test_a_material_is_refused_as_a_test_case_of_a_basis_built_with_it(tmp_path):
    """The bench's guard: a basis lists the materials it was built from, and scoring
    one of them with it is refused; a held-out one passes; a basis that cannot say
    what it saw is refused too."""
    import dataclasses

    from brdf_reconstruct.core.brdf import basis
    from testkit import measured

    train = ["green-latex", "pink-fabric2", "gold-metallic-paint"]
    B = basis.load_measured(PACK, train, cache_dir=tmp_path, n_components=6)
    assert B.info["materials"] == train
    again = basis.load_measured(PACK, train, cache_dir=tmp_path, n_components=6)  # cached
    assert again.info["materials"] == train
    with pytest.raises(ValueError, match="pink-fabric2 is one of the basis' 3 training "
                       "materials"):
        measured.held_out(B, "pink-fabric2")
    assert measured.held_out(B, "aluminium") == "aluminium"
    anonymous = dataclasses.replace(B, info={k: v for k, v in B.info.items()
                                             if k != "materials"})
    with pytest.raises(ValueError, match="does not list its training materials"):
        measured.held_out(anonymous, "aluminium")
    # the cross-validation folds never pair a material with a basis that saw it
    pack = nbrdf.load(PACK)
    for held in measured.folds(pack.names, k=5):
        names = [n for n in pack.names if n not in held]
        fake = dataclasses.replace(B, info={**B.info, "materials": names})
        assert all(measured.held_out(fake, n) == n for n in held)


@needs_pack
def test_a_fold_training_set_never_holds_its_material_and_one_per_class_is_seeded():
    from testkit import measured

    names = nbrdf.load(PACK).names
    for name in ("aluminium", "pink-fabric2", "green-latex", "two-layer-gold"):
        train = measured.fold_training(names, name)
        assert name not in train and len(train) == 64
        assert set(train) | next(set(f) for f in measured.folds(names) if name in f) \
            == set(names)
    with pytest.raises(ValueError, match="not one of the 80"):
        measured.fold_training(names, "unobtainium")
    drawn = measured.one_per_class(names)
    assert [measured.material_class(n) for n in drawn] == list(measured.CLASSES)
    assert drawn == measured.one_per_class(names, seed=0)
    assert drawn != measured.one_per_class(names, seed=1)
