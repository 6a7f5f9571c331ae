"""The Fast / Balanced / Accurate / Paper presets (brdf_addon/presets.py): the panel's
defaults are Balanced, choosing a preset sets its values, editing one of them to
another value makes the preset Custom, and a job file's own values win over its
preset by the same rule. Paper is the paper's own mode (6 samples, KL of Cycles
renders)."""

import pathlib

import pytest

bpy = pytest.importorskip("bpy")

from brdf_reconstruct.brdf_addon import job as job_module  # noqa: E402
from brdf_reconstruct.brdf_addon import props as props_module  # noqa: E402
from brdf_reconstruct.brdf_addon.presets import PRESETS  # noqa: E402


@pytest.fixture
def scene(registered):
    return registered


def _values(settings, keys):
    return {k: getattr(settings, k) for k in keys}


def test_defaults_are_the_balanced_preset(scene):
    s = scene.brdf
    assert s.preset == "BALANCED"
    assert _values(s, PRESETS["BALANCED"]) == pytest.approx(PRESETS["BALANCED"])


@pytest.mark.parametrize("name", list(PRESETS))
def test_choosing_a_preset_sets_its_values(scene, name):
    s = scene.brdf
    s.preset = "CUSTOM"
    s.samples, s.trials = 3, 2
    s.preset = name
    assert _values(s, PRESETS[name]) == pytest.approx(PRESETS[name])


# a value other than every preset's, for each setting a preset names
OFF_PRESET = {"samples": 33, "trials": 7, "subset_fraction": 0.25, "kl_path": "CYCLES",
              "kl_samples": 64, "keep_highlight_energy": False, "pixel_footprint": True}
# the values no single setting can be off for every preset (kl_path: Fast's is FAST,
# Accurate's CYCLES; keep_highlight_energy: Paper's is off, the others' on;
# pixel_footprint: on in Accurate only)
SHARED_VALUES = ("kl_path", "keep_highlight_energy", "pixel_footprint")


def test_every_setting_a_preset_names_has_an_off_preset_value():
    keys = {k for values in PRESETS.values() for k in values}
    assert set(OFF_PRESET) == keys
    for values in PRESETS.values():
        assert all(values[k] != v for k, v in OFF_PRESET.items() if k not in SHARED_VALUES)
    for key in SHARED_VALUES:
        assert OFF_PRESET[key] != PRESETS["FAST"][key]
        assert OFF_PRESET[key] != PRESETS["BALANCED"][key]


def test_editing_a_preset_value_makes_it_custom_and_choosing_again_restores(scene):
    s = scene.brdf
    s.preset = "FAST"
    assert _values(s, PRESETS["FAST"]) == pytest.approx(PRESETS["FAST"])
    assert s.preset == "FAST"  # its own assignments did not make it Custom
    s.trials = 7
    assert s.preset == "CUSTOM" and s.trials == 7
    s.preset = "BALANCED"
    assert s.preset == "BALANCED"
    assert _values(s, PRESETS["BALANCED"]) == pytest.approx(PRESETS["BALANCED"])


@pytest.mark.parametrize("key", list(OFF_PRESET))
@pytest.mark.parametrize("name", ["FAST", "BALANCED"])
def test_each_preset_setting_edited_makes_it_custom(scene, key, name):
    s = scene.brdf
    s.preset = name
    setattr(s, key, OFF_PRESET[key])
    assert s.preset == "CUSTOM"
    assert getattr(s, key) == pytest.approx(OFF_PRESET[key])  # the edit itself is kept


def test_setting_the_presets_own_value_keeps_it(scene):
    s = scene.brdf
    s.preset = "FAST"
    s.trials = PRESETS["FAST"]["trials"]
    s.subset_fraction = PRESETS["FAST"]["subset_fraction"]
    assert s.preset == "FAST"


def test_settings_no_preset_names_keep_it(scene):
    s = scene.brdf
    s.preset = "ACCURATE"
    s.seed, s.min_reliable_samples, s.kl_bins, s.curvature_threshold = 5, 40, 32, 0.3
    assert s.preset == "ACCURATE"


def test_paper_preset_is_the_papers_mode(scene):
    """6 samples per trial (Ono et al. 2017, Sec. 4.1), 16 trials of half the reliable
    pixels, and the KL of Cycles renders of each candidate (Sec. 3.2), at Accurate's
    Cycles samples; no step after the selection (the energy refit off) and each pixel
    read at its centre (no pixel footprint)."""
    assert PRESETS["PAPER"] == dict(samples=6, trials=16, subset_fraction=0.5,
                                    kl_path="CYCLES",
                                    kl_samples=PRESETS["ACCURATE"]["kl_samples"],
                                    keep_highlight_energy=False, pixel_footprint=False)
    s = scene.brdf
    s.preset = "PAPER"
    assert s.preset == "PAPER"  # its own assignments did not make it Custom
    assert (s.samples, s.trials, s.kl_path) == (6, 16, "CYCLES")
    assert s.subset_fraction == pytest.approx(0.5)
    assert s.kl_samples == PRESETS["ACCURATE"]["kl_samples"]
    assert props_module.pipeline_settings(s).refine == "none"


def test_paper_preset_with_the_fast_selection_is_custom(scene):
    """The paper's mode is not silently changed: the numpy selection is another mode."""
    s = scene.brdf
    s.preset = "PAPER"
    s.kl_path = "FAST"
    assert s.preset == "CUSTOM" and s.samples == 6


def test_custom_stays_custom_and_keeps_the_values(scene):
    s = scene.brdf
    s.preset = "CUSTOM"
    s.samples, s.trials = 3, 2
    s.trials = 16  # Balanced's value, but the preset is Custom: nothing is set back
    assert s.preset == "CUSTOM" and (s.samples, s.trials) == (3, 16)


def _job(scene, settings):
    mesh = bpy.data.meshes.new("scan")
    mesh.from_pydata([(0, 0, 0), (1, 0, 0), (0, 1, 0)], [], [(0, 1, 2)])
    scene.collection.objects.link(bpy.data.objects.new("scan", mesh))
    here = pathlib.Path.cwd()
    return job_module.Job(path=here / "job.toml", out=here / "out", object="scan",
                          settings=settings)


def test_job_values_win_over_its_preset(scene):
    job_module.apply(_job(scene, {"trials": 5, "preset": "FAST"}), scene)
    s = scene.brdf
    assert s.trials == 5 and s.preset == "CUSTOM"  # the user's own value, said so
    assert s.samples == PRESETS["FAST"]["samples"]  # the rest from the preset


def test_job_preset_alone_is_that_preset(scene):
    job_module.apply(_job(scene, {"preset": "ACCURATE"}), scene)
    s = scene.brdf
    assert s.preset == "ACCURATE"
    assert _values(s, PRESETS["ACCURATE"]) == pytest.approx(PRESETS["ACCURATE"])


def test_job_paper_preset_is_accepted(scene):
    job_module.apply(_job(scene, {"preset": "PAPER"}), scene)
    s = scene.brdf
    assert s.preset == "PAPER"
    assert _values(s, PRESETS["PAPER"]) == pytest.approx(PRESETS["PAPER"])


def test_job_unknown_preset_is_one_sentence(scene):
    """One sentence that names every allowed value, Paper included."""
    with pytest.raises(job_module.JobError) as error:
        job_module.apply(_job(scene, {"preset": "QUICK"}), scene)
    assert str(error.value) == ("setting preset = 'QUICK': must be one of FAST, BALANCED, "
                                "ACCURATE, PAPER, CUSTOM")


def test_job_preset_with_its_own_value_stays_that_preset(scene):
    """The update rule in a job: a value equal to the preset's keeps the preset."""
    job_module.apply(_job(scene, {"preset": "FAST", "trials": PRESETS["FAST"]["trials"]}),
                     scene)
    assert scene.brdf.preset == "FAST"


def test_job_value_without_a_preset_is_judged_against_the_default(scene):
    """trials = 16 alone is the default Balanced's own value, so Balanced stays;
    trials = 5 alone is not, so the preset is Custom."""
    job_module.apply(_job(scene, {"trials": 16}), scene)
    assert scene.brdf.preset == "BALANCED"
    bpy.data.objects.remove(bpy.data.objects["scan"])
    job_module.apply(_job(scene, {"trials": 5}), scene)
    assert scene.brdf.preset == "CUSTOM" and scene.brdf.trials == 5


def test_a_file_saved_before_paper_keeps_its_preset(registered, tmp_path):
    """Blender stores an enum's number, not its name: a file saved with the three
    presets of 0.1.0 (Custom the fourth item) opens with the preset it had, not
    Paper; each preset keeps the number it was saved with."""
    from brdf_reconstruct.brdf_addon import props

    preset = props.BRDFSettings.__annotations__["preset"]
    old = [("FAST", "Fast", ""), ("BALANCED", "Balanced", ""), ("ACCURATE", "Accurate", ""),
           ("CUSTOM", "Custom", "")]  # 0.1.0's items, numbered by position
    saved = {}
    try:
        props.BRDFSettings.preset = bpy.props.EnumProperty(items=old, default="BALANCED")
        for identifier, _name, _description in old:
            registered.brdf.preset = identifier
            saved[identifier] = tmp_path / f"{identifier.lower()}.blend"
            bpy.ops.wm.save_as_mainfile(filepath=str(saved[identifier]))
    finally:
        props.BRDFSettings.preset = preset
    bpy.context.scene.brdf.preset = "PAPER"  # and Paper, saved now, opens as Paper
    saved["PAPER"] = tmp_path / "paper.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(saved["PAPER"]))
    for identifier, path in saved.items():
        bpy.ops.wm.open_mainfile(filepath=str(path))
        assert bpy.context.scene.brdf.preset == identifier
