"""The glTF export's own guarantees (``brdf_addon.gltf_export``): an interrupted
export leaves nothing half-written, and a "whole"-model texture becomes a base
colour file glTF can carry. The exported file itself is read back in
test_texture_run.py and test_workflow.py."""

import types

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from brdf_reconstruct.brdf_addon import gltf_export  # noqa: E402
from brdf_reconstruct.core.capture import photo_io  # noqa: E402
from testkit import blender_scene as BS  # noqa: E402


def test_an_interrupted_export_leaves_the_earlier_file_and_no_temporary(tmp_path, registered,
                                                                         monkeypatch):
    built = BS.build(tmp_path, photo=False)
    scene = built["scene"]
    scene.brdf.target = built["scan"]
    earlier = tmp_path / gltf_export.GLTF_NAME
    earlier.write_bytes(b"an earlier run's file")
    blocks = {k: len(getattr(bpy.data, k)) for k in ("meshes", "objects", "scenes")}

    def stopped(tmp):  # the exporter has written part of the file when Ctrl+C comes
        tmp.write_bytes(b"glTF half")
        raise KeyboardInterrupt

    monkeypatch.setattr(gltf_export, "_run_exporter", stopped)
    with pytest.raises(KeyboardInterrupt):
        gltf_export.export_scan(scene, earlier, {0: bpy.data.materials.new("M")})
    assert earlier.read_bytes() == b"an earlier run's file"
    assert sorted(p.name for p in tmp_path.iterdir() if ".tmp" in p.name) == []
    assert {k: len(getattr(bpy.data, k)) for k in blocks} == blocks


def test_a_whole_model_texture_becomes_a_clipped_base_color_file(tmp_path):
    """The "whole" model's multiplier (mean 1, values past 1, linear) cannot go into
    glTF's sRGB base colour texture as it is: the file holds base colour times the
    multiplier, clipped to [0, 1], and counts the texels clipped."""
    relative = np.array([[[1.0, 1.0, 1.0], [0.5, 0.5, 0.5]],
                         [[2.5, 1.0, 0.2], [1.5, 1.5, 1.5]]])  # (2, 2, 3), rows top-down
    texture = types.SimpleNamespace(relative=lambda: relative.reshape(-1, 3),
                                    map=types.SimpleNamespace(shape=(2, 2)))
    base = (0.5, 0.25, 0.8, 1.0)
    image, clipped = gltf_export.base_color_image(tmp_path / "brdf_0_base_color.png",
                                                  texture, base)
    bpy.data.images.remove(image)
    expected = np.clip(relative * np.array(base[:3]), 0.0, 1.0)
    assert clipped == 2  # (2.5, 1, 0.2) gives red 1.25; (1.5, 1.5, 1.5) gives blue 1.2
    written = photo_io.read_photo_file(tmp_path / "brdf_0_base_color.png").radiance
    np.testing.assert_allclose(written, expected, atol=1e-4)  # 16-bit sRGB codes
