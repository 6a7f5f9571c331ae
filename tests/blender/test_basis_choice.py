"""Which PCA basis a run stands on: the preferences' choice, a scene's (or a job's)
own, refused before any work when its source is missing, and recorded in the
report (``brdf_addon/prefs.py``, issue 14)."""

import types

import pytest

bpy = pytest.importorskip("bpy")

from brdf_reconstruct.brdf_addon import job as job_mod  # noqa: E402
from brdf_reconstruct.brdf_addon import prefs, runner  # noqa: E402
from brdf_reconstruct.core.brdf import basis, merl  # noqa: E402
from testkit import blender_scene as BS  # noqa: E402
from testkit.measured import PACK  # noqa: E402


def _preferences(monkeypatch, **values):
    fields = {"basis": "MEASURED", "measured_pack": "", "database_folder": "",
              "cache_folder": "", "device": "CPU"} | values
    chosen = set(values)
    p = types.SimpleNamespace(**fields, is_property_set=lambda name: name in chosen)
    monkeypatch.setattr(prefs, "get", lambda: p)


def test_the_default_is_the_measured_basis_from_the_shipped_pack(registered, monkeypatch):
    from brdf_reconstruct.core.brdf import nbrdf

    monkeypatch.delenv(prefs.MEASURED_PACK_VARIABLE, raising=False)
    shipped = ("MEASURED", str(nbrdf.BUNDLED_PACK))
    assert prefs.basis_choice(registered) == shipped
    assert prefs.basis_choice(None) == shipped
    # the shipped pack is the pack of the data folder, byte for byte
    if PACK.is_file():
        assert nbrdf.BUNDLED_PACK.read_bytes() == PACK.read_bytes()


def test_a_measured_pack_that_is_not_there_is_one_sentence(registered, monkeypatch, tmp_path):
    missing = tmp_path / "nowhere.npz"
    monkeypatch.setenv(prefs.MEASURED_PACK_VARIABLE, str(missing))
    registered.brdf.basis = "MEASURED"
    with pytest.raises(ValueError, match=r"^the measured basis needs a pack like "
                       r"merl_nbrdf\.npz, and .*nowhere\.npz is not a file: correct "
                       "Measured Pack in the preferences") as caught:
        prefs.basis_choice(registered)
    assert "\n" not in str(caught.value)
    if PACK.is_file():
        monkeypatch.setenv(prefs.MEASURED_PACK_VARIABLE, str(PACK))
        assert prefs.basis_choice(registered) == ("MEASURED", str(PACK))


def test_the_scene_overrides_the_preferences(registered, monkeypatch, tmp_path):
    _preferences(monkeypatch, basis="FOLDER", database_folder=str(tmp_path))
    assert prefs.basis_choice(registered) == ("FOLDER", str(tmp_path))
    registered.brdf.basis = "ANALYTIC"
    assert prefs.basis_choice(registered) == ("ANALYTIC", "")
    registered.brdf.basis = "FOLDER"
    with pytest.raises(ValueError, match="needs a folder of .binary files"):
        prefs.basis_choice(registered)


def test_preferences_of_0_1_0_that_set_a_folder_keep_meaning_it(monkeypatch, tmp_path):
    _preferences(monkeypatch, database_folder=str(tmp_path))  # basis never set
    assert prefs.basis_choice() == ("FOLDER", str(tmp_path))
    _preferences(monkeypatch, basis="ANALYTIC", database_folder=str(tmp_path))  # chosen
    assert prefs.basis_choice() == ("ANALYTIC", "")
    _preferences(monkeypatch, basis="MEASURED", database_folder=str(tmp_path))  # chosen
    assert prefs.basis_choice()[0] == "MEASURED"


def test_a_run_refuses_a_missing_basis_before_any_work(tiny, monkeypatch):
    from brdf_reconstruct.brdf_addon import photo_list

    monkeypatch.setenv(prefs.MEASURED_PACK_VARIABLE, str(tiny["dir"] / "nowhere.npz"))
    scene = tiny["scene"]
    photo_list.add_photos(scene, [str(tiny["photo"])])
    scene.brdf.basis = "MEASURED"
    with pytest.raises(ValueError, match="the measured basis needs a pack"):
        runner.Run(scene, threaded=False)
    assert not (tiny["dir"] / "out").exists()


def test_the_report_says_which_basis_was_used(tiny):
    from brdf_reconstruct.brdf_addon import photo_list

    scene = tiny["scene"]
    added, _ = photo_list.add_photos(scene, [str(tiny["photo"])])
    added[0].irradiance = (BS.lit_irradiance(),) * 3
    report = runner.Run(scene, threaded=False, bake=False).run()
    from brdf_reconstruct.core.brdf import nbrdf

    expected = basis.load_measured(cache_dir=prefs.cache_dir())
    assert report["basis"] == {"kind": "measured", "source": str(nbrdf.BUNDLED_PACK),
                               "fingerprint": expected.fingerprint,
                               "n_columns": expected.info["n_columns"],
                               "n_components": expected.n_components}


@pytest.mark.parametrize("value, words", [
    (3, 'basis must be "analytic", "measured" or a folder'),
    ("nowhere", 'basis nowhere: not "analytic" or "measured", and no such folder'),
    ("empty", "holds no MERL .binary files"),
])
def test_a_jobs_bad_basis_is_one_sentence(tmp_path, value, words):
    (tmp_path / "empty").mkdir()
    with pytest.raises(job_mod.JobError, match=words):
        job_mod._basis(tmp_path, value)


def test_a_jobs_basis_is_the_scenes(registered, tmp_path):
    folder = tmp_path / "merl"
    folder.mkdir()
    import numpy as np

    table = np.full((3, merl.N_CELLS), np.nan)
    table[:, merl.valid_cells()] = 0.1
    merl.write(folder / "grey.binary", table.reshape(3, *merl.SHAPE))
    assert job_mod._basis(tmp_path, "measured") == ("MEASURED", None)
    assert job_mod._basis(tmp_path, "analytic") == ("ANALYTIC", None)
    assert job_mod._basis(tmp_path, "merl") == ("FOLDER", folder)
