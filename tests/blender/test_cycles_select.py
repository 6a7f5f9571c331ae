"""The accurate (Cycles) selection path against the fast (numpy) one, on the tiny
scene whose photo Cycles rendered with a known Lambertian material."""

import dataclasses
import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from brdf_reconstruct.brdf_addon import (  # noqa: E402
    cycles_select,
    gathering,
    photo_list,
    runner,
)
from brdf_reconstruct.core.brdf import database, merl  # noqa: E402
from brdf_reconstruct.core.method import pipeline, selection  # noqa: E402
from testkit import blender_scene as BS  # noqa: E402


def _lambert(albedo):
    t = np.full((3, merl.N_CELLS), np.nan)
    t[:, merl.valid_cells()] = albedo / np.pi
    return t.reshape(3, *merl.SHAPE)


@pytest.fixture
def tiny(tiny):
    """The tiny scene with its photo added, lit at the known irradiance."""
    (p,), _ = photo_list.add_photos(tiny["scene"], [str(tiny["photo"])])
    p.irradiance = (BS.lit_irradiance(),) * 3
    return tiny


def test_both_paths_pick_the_true_material(tiny):
    scene = tiny["scene"]
    inputs = gathering.gather(scene)
    gold = next(s for s in database.heldout_specs() if s["name"] == "heldout_gold_medium")
    tables = [_lambert(0.25), _lambert(BS.ALBEDO), database.make_table(gold),
              _lambert(0.9)]
    fast = selection.select_by_kl(tables, pipeline.region_views(inputs, 0))
    blocks = {k: len(getattr(bpy.data, k)) for k in ("materials", "node_groups", "objects",
                                                     "scenes", "meshes", "lights", "images")}
    kl, winner = cycles_select.select_by_cycles(scene, inputs, 0, tables, render_samples=16)
    assert fast.winner == winner == 1
    # the same ranking, and a clear margin on both paths
    assert list(np.argsort(fast.kl)) == list(np.argsort(kl))
    print("fast KL", np.round(fast.kl, 4), "Cycles KL", np.round(kl, 4))
    for score in (fast.kl, kl):
        assert score[1] < 0.5 * np.sort(score)[1]
    assert {k: len(getattr(bpy.data, k)) for k in blocks} == blocks  # nothing left behind


def test_reconstruct_with_the_cycles_path_records_both(tiny):
    scene = tiny["scene"]
    scene.brdf.kl_path = "CYCLES"
    scene.brdf.kl_samples = 16
    report = runner.Run(scene, threaded=False, bake=False).run()
    sel = report["regions"][0]["selection"]
    assert sel["path"] == "cycles" and sel["cycles_samples"] == 16
    assert len(sel["fast_kl"]) == len(report["regions"][0]["kl"]) == 2
    assert isinstance(sel["agree"], bool)
    table = merl.read(scene.brdf.results[0].table_path)
    assert np.nanmedian(table[:, :30, :30]) == pytest.approx(BS.ALBEDO / math.pi, rel=0.05)


def test_the_cycles_path_keeps_the_photos_check(tiny, monkeypatch):
    """A trial the photos' check excluded (selection.photo_eligible) is not chosen by the
    Cycles KL either, even where it scores best; the report keeps the check and names
    the Cycles KL's own winner. The fast selection is edited so that trial 0 misses
    the photos 10 times more than trial 1, and the Cycles scores so that it wins."""
    real = selection.select_by_kl

    def trial_0_far(*args, **kwargs):
        result = real(*args, **kwargs)
        return dataclasses.replace(result, rmse=np.array([1.0, 0.1]))

    monkeypatch.setattr(selection, "select_by_kl", trial_0_far)
    scores = iter([0.01, 0.5])  # trial 0, then trial 1
    monkeypatch.setattr(cycles_select, "score_candidate",
                        lambda *args, **kwargs: np.array([next(scores)]))
    scene = tiny["scene"]
    scene.brdf.kl_path = "CYCLES"
    report = runner.Run(scene, threaded=False, bake=False).run()
    region = report["regions"][0]
    sel = region["selection"]
    assert sel["path"] == "cycles" and sel["photo_excluded"] == [0]
    assert sel["kl_winner"] == 0 and region["winner"] == 1
    assert region["refinement"]["trial"] == 1
