"""The temporary scene that every render of the extension goes through: where its
renders land and what it leaves behind."""

import glob
import os
import tempfile

import pytest

bpy = pytest.importorskip("bpy")

from brdf_reconstruct.brdf_addon.scratch_scene import (  # noqa: E402
    ScratchScene,
    configure_cycles,
    float_exr_output,
)


def _tiny_render_setup(scratch):
    cam = scratch.new(bpy.data.objects, "cam", scratch.new(bpy.data.cameras, "cam"))
    scratch.scene.collection.objects.link(cam)
    scratch.scene.camera = cam
    configure_cycles(scratch.scene, 1)
    r = scratch.scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = 8, 6, 100
    float_exr_output(scratch.scene)


def test_a_render_to_a_relative_path_lands_there_and_no_scratch_is_left(tmp_path,
                                                                          monkeypatch):
    """A path relative to the working folder (a pipeline run's ``.cache/...``) is
    written where it points, not inside the scratch folder; a bare name goes in the
    scratch folder; the scratch folder goes away whole, subfolders and all."""
    monkeypatch.chdir(tmp_path)
    before = set(glob.glob(os.path.join(tempfile.gettempdir(), "brdf_scratch_*")))
    with ScratchScene("BRDF_TEST") as scratch:
        _tiny_render_setup(scratch)
        kept = scratch.render(os.path.join("rel", "photo.exr"))
        bare = scratch.render("kl.exr")
        os.makedirs(os.path.join(scratch.folder, "sub"))  # anything a render might add
        folder = scratch.folder
    assert kept == str(tmp_path / "rel" / "photo.exr")
    assert (tmp_path / "rel" / "photo.exr").is_file()
    assert os.path.dirname(bare) == folder
    assert not os.path.exists(folder)
    assert set(glob.glob(os.path.join(tempfile.gettempdir(), "brdf_scratch_*"))) == before
    assert "BRDF_TEST" not in bpy.data.scenes
