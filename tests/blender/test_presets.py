"""The Fast / Balanced / Accurate presets (brdf_addon/presets.py): the panel's
defaults are Balanced, choosing a preset sets its values, and a job file's own
values win over its preset."""

import pathlib

import pytest

bpy = pytest.importorskip("bpy")

from brdf_reconstruct.brdf_addon import job as job_module  # noqa: E402
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


def test_job_unknown_preset_is_one_sentence(scene):
    with pytest.raises(job_module.JobError, match="setting preset = 'QUICK'"):
        job_module.apply(_job(scene, {"preset": "QUICK"}), scene)
