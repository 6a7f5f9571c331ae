"""A .blend saved by 0.1.0 (angles stored as degrees) opens with the angles it meant;
a file saved by this version is never converted twice."""

import math

import pytest

bpy = pytest.importorskip("bpy")

from brdf_reconstruct.brdf_addon import versioning  # noqa: E402


def _old_style_file(path, scene):
    """Save ``scene`` as 0.1.0 did: the two angles defined as plain degree floats, no
    version mark (0.1.0 had neither the property nor the save handler)."""
    from brdf_reconstruct.brdf_addon import props

    angle = props.BRDFSettings.__annotations__["peak_max_angle"]
    north = props.BRDFPhoto.__annotations__["north_offset"]
    versioning.detach()
    try:  # the 0.1.0 definitions, then values set through them
        props.BRDFSettings.peak_max_angle = bpy.props.FloatProperty(default=30.0, min=0.0,
                                                                   max=180.0)
        props.BRDFPhoto.north_offset = bpy.props.FloatProperty(default=0.0, min=-180.0,
                                                              max=180.0)
        scene.brdf.peak_max_angle = 45.0
        scene.brdf.photos.add().north_offset = -90.0
        scene.brdf.property_unset("settings_version")
        bpy.ops.wm.save_as_mainfile(filepath=str(path))
    finally:
        props.BRDFSettings.peak_max_angle, props.BRDFPhoto.north_offset = angle, north
        versioning.attach()


def test_a_file_of_the_old_version_opens_with_its_angles_in_radians(registered, tmp_path):
    _old_style_file(tmp_path / "old.blend", registered)
    bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "old.blend"))
    brdf = bpy.context.scene.brdf
    assert brdf.peak_max_angle == pytest.approx(math.radians(45.0))
    assert brdf.photos[0].north_offset == pytest.approx(math.radians(-90.0))
    assert brdf.settings_version == versioning.SETTINGS_VERSION
    # the test put today's definitions back
    assert brdf.bl_rna.properties["peak_max_angle"].subtype == "ANGLE"
    assert brdf.photos[0].bl_rna.properties["north_offset"].subtype == "ANGLE"


def test_a_file_saved_now_is_not_converted_again(registered, tmp_path):
    brdf = registered.brdf
    brdf.peak_max_angle = math.radians(12.0)
    brdf.photos.add().north_offset = math.radians(30.0)
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "new.blend"))
    for _ in range(2):  # open, save again, open: the same radians each time
        bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "new.blend"))
        brdf = bpy.context.scene.brdf
        assert brdf.peak_max_angle == pytest.approx(math.radians(12.0))
        assert brdf.photos[0].north_offset == pytest.approx(math.radians(30.0))
        bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "new.blend"))


def test_values_never_set_read_the_defaults_without_a_conversion(registered):
    assert versioning.upgrade_scene(registered) == 0
    assert registered.brdf.peak_max_angle == pytest.approx(math.radians(30.0))
