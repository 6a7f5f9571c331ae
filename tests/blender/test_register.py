"""The add-on registers and unregisters cleanly in pip ``bpy`` (headless)."""

import pytest

bpy = pytest.importorskip("bpy")

import brdf_reconstruct  # noqa: E402


def _panel_class():
    return getattr(bpy.types, "BRDF_PT_main", None)


def _assert_unregistered():
    assert _panel_class() is None
    assert not hasattr(bpy.types.Scene, "brdf")
    with pytest.raises(AttributeError):
        bpy.context.scene.brdf  # noqa: B018


def test_panel_in_sidebar(registered):
    panel = _panel_class()
    assert panel is not None
    assert issubclass(panel, bpy.types.Panel)
    assert panel.bl_category == "BRDF"
    assert panel.bl_space_type == "VIEW_3D"
    assert panel.bl_region_type == "UI"


def test_scene_settings(registered):
    settings = bpy.context.scene.brdf
    assert settings.bl_rna.properties["seed"].default == 0
    settings.seed = 7
    assert bpy.context.scene.brdf.seed == 7


def test_unregister_removes_everything():
    brdf_reconstruct.register()
    brdf_reconstruct.unregister()
    _assert_unregistered()


def test_register_unregister_twice():
    for _ in range(2):
        brdf_reconstruct.register()
        assert _panel_class() is not None
        bpy.context.scene.brdf.seed = 3
        assert bpy.context.scene.brdf.seed == 3
        brdf_reconstruct.unregister()
        _assert_unregistered()
