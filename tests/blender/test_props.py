"""The settings as the artist meets them (brdf_addon/props.py): every setting has a
one-line tooltip, the UI text is US English, and angles are Blender angles (radians
inside, degrees in the UI and in the job file)."""

import ast
import math
import pathlib
import re

import pytest

bpy = pytest.importorskip("bpy")

from brdf_reconstruct.brdf_addon import job as job_module  # noqa: E402
from brdf_reconstruct.brdf_addon import panel, props  # noqa: E402
from brdf_reconstruct.core.method import reliable  # noqa: E402


@pytest.fixture
def scene(registered):
    return registered


def _properties(cls):
    """(identifier, property) of a registered class's own properties."""
    return [(p.identifier, p) for p in cls.bl_rna.properties
            if p.identifier not in ("rna_type", "name")]


def _operators():
    from brdf_reconstruct import operators

    for cls in operators.CLASSES:
        category, name = cls.bl_idname.split(".")
        yield cls.bl_idname, getattr(getattr(bpy.ops, category), name).get_rna_type()


# --- tooltips --------------------------------------------------------------------------

@pytest.mark.parametrize("cls", props.CLASSES, ids=lambda c: c.__name__)
def test_every_setting_has_a_one_line_tooltip(scene, cls):
    """Each property's description (its tooltip) is there and on one line; so is each
    enum choice's (a wrapped docstring's line break would show in the tooltip)."""
    missing, broken = [], []
    for name, prop in _properties(cls):
        texts = [(name, prop.description)]
        if prop.type == "ENUM":
            texts += [(f"{name}.{item.identifier}", item.description)
                      for item in prop.enum_items]
        for what, text in texts:
            if not text.strip():
                missing.append(what)
            elif "\n" in text or "  " in text:
                broken.append(what)
    assert missing == [] and broken == []
    assert len(_properties(cls)) > 5  # the walk saw the class's properties


def test_every_operator_has_a_one_line_tooltip(scene):
    """An operator's tooltip is its bl_description or docstring: on one line, and so are
    the descriptions of the properties the file browser or redo panel shows."""
    for idname, rna in _operators():
        assert rna.description.strip() and "\n" not in rna.description, idname
        for prop in rna.properties:
            if prop.identifier == "rna_type" or prop.is_hidden:
                continue
            assert prop.description.strip() and "\n" not in prop.description, \
                f"{idname}.{prop.identifier}"


# --- US English in the UI --------------------------------------------------------------

BRITISH = re.compile(r"colour|centre|grey|metre|behaviour|normalis|licence", re.IGNORECASE)


def _ui_texts():
    """Every name, tooltip and choice of the settings and operators."""
    texts = []
    for cls in props.CLASSES:
        for name, prop in _properties(cls):
            texts += [(name, prop.name), (name, prop.description)]
            if prop.type == "ENUM":
                texts += [(f"{name}.{i.identifier}", t) for i in prop.enum_items
                          for t in (i.name, i.description)]
    for idname, rna in _operators():
        texts += [(idname, rna.name), (idname, rna.description)]
        texts += [(f"{idname}.{p.identifier}", t) for p in rna.properties
                  for t in (p.name, p.description)]
    return texts


def _report_texts(module):
    """The constant parts of every ``self.report(...)`` message in an operator module."""
    tree = ast.parse(pathlib.Path(module.__file__).read_text())
    out = []
    for call in ast.walk(tree):
        if (isinstance(call, ast.Call) and isinstance(call.func, ast.Attribute)
                and call.func.attr == "report" and len(call.args) == 2):
            out += [n.value for n in ast.walk(call.args[1])
                    if isinstance(n, ast.Constant) and isinstance(n.value, str)]
    return out


def test_ui_text_is_us_english(scene):
    from brdf_reconstruct import operators
    from brdf_reconstruct.operators import export, import_colmap, light, photos, reconstruct

    british = [(what, text) for what, text in _ui_texts() if BRITISH.search(text)]
    assert british == []
    for module in (export, import_colmap, light, photos, reconstruct):
        assert [t for t in _report_texts(module) if BRITISH.search(t)] == [], module.__name__
    panel_strings = [n.value for n in ast.walk(ast.parse(pathlib.Path(panel.__file__)
                                                         .read_text()))
                     if isinstance(n, ast.Constant) and isinstance(n.value, str)]
    assert [t for t in panel_strings if BRITISH.search(t) and " " in t] == []
    assert len(operators.CLASSES) >= 9


def test_us_names_and_unchanged_identifiers(scene):
    """The UI says Color Space, Sphere Center, Gray Card; the identifiers and job keys
    (color_space, probe_center, CARD, grey_card) stay as they were."""
    photo = props.BRDFPhoto.bl_rna.properties
    assert photo["color_space"].name == "Color Space"
    assert photo["probe_center"].name == "Sphere Center"
    assert photo["reference_kind"].enum_items["CARD"].name == "Gray Card"
    assert "grey_card" in job_module.KNOWN_PHOTO


# --- angles ----------------------------------------------------------------------------

@pytest.mark.parametrize("cls, name, default, low, high", [
    (props.BRDFSettings, "peak_max_angle", math.radians(30.0), 0.0, math.pi),
    (props.BRDFPhoto, "north_offset", 0.0, -math.pi, math.pi),
], ids=["peak_max_angle", "north_offset"])
def test_angles_are_blender_angles_in_radians(scene, cls, name, default, low, high):
    prop = cls.bl_rna.properties[name]
    assert prop.subtype == "ANGLE" and prop.unit == "ROTATION"  # shown in degrees
    assert prop.default == pytest.approx(default, rel=1e-6, abs=1e-7)
    assert (prop.hard_min, prop.hard_max) == pytest.approx((low, high), rel=1e-6)


def test_pipeline_gets_the_same_radians_as_before(scene):
    """The default is the core's own default (30 degrees), no longer converted twice."""
    got = props.pipeline_settings(scene.brdf).reliable.peak_max_angle
    assert got == pytest.approx(reliable.ReliableSettings().peak_max_angle, rel=1e-7)
    assert got == pytest.approx(math.radians(30.0), rel=1e-7)


def _job(scene, settings=None, sun=None):
    mesh = bpy.data.meshes.new("scan")
    mesh.from_pydata([(0, 0, 0), (1, 0, 0), (0, 1, 0)], [], [(0, 1, 2)])
    scene.collection.objects.link(bpy.data.objects.new("scan", mesh))
    cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    scene.collection.objects.link(cam)
    here = pathlib.Path.cwd()
    photo = {"image": here / "view.exr", "camera": "cam", "color_space": "AUTO",
             "light": {"sun": sun or {"date": "2026-06-21 12:00:00", "latitude": 48.1,
                                      "longitude": 11.6}}}
    return job_module.Job(path=here / "job.toml", out=here / "out", object="scan",
                          settings=settings or {}, photos=[photo])


def test_job_angles_are_degrees(scene):
    job_module.apply(_job(scene, {"peak_max_angle": 12.5},
                          {"date": "2026-06-21 12:00:00", "latitude": 48.1, "longitude": 11.6,
                           "north_offset": -90}), scene)
    s = scene.brdf
    assert s.peak_max_angle == pytest.approx(math.radians(12.5), rel=1e-6)
    assert props.pipeline_settings(s).reliable.peak_max_angle == pytest.approx(
        math.radians(12.5), rel=1e-6)
    assert s.photos[0].north_offset == pytest.approx(-math.pi / 2, rel=1e-6)
    assert props.settings_dict(s)["peak_max_angle"] == 12.5  # the job's own degrees back


def test_job_peak_max_angle_30_is_the_default_radians(scene):
    job_module.apply(_job(scene, {"peak_max_angle": 30}), scene)
    assert scene.brdf.peak_max_angle == pytest.approx(math.radians(30), rel=1e-7)
    assert props.pipeline_settings(scene.brdf).reliable.peak_max_angle == pytest.approx(
        reliable.ReliableSettings().peak_max_angle, rel=1e-7)
    assert props.settings_dict(scene.brdf)["peak_max_angle"] == 30.0


@pytest.mark.parametrize("value", [180, 0, 179.5])
def test_job_angle_at_its_limits_is_taken(scene, value):
    job_module.apply(_job(scene, {"peak_max_angle": value}), scene)
    assert scene.brdf.peak_max_angle == pytest.approx(math.radians(value), rel=1e-6, abs=1e-9)


def test_job_sampler_reaches_the_pipeline(scene):
    assert props.pipeline_settings(scene.brdf).sampler == "condition"  # the default
    job_module.apply(_job(scene, {"sampler": "RISK"}), scene)
    assert props.pipeline_settings(scene.brdf).sampler == "risk"
    assert props.settings_dict(scene.brdf)["sampler"] == "RISK"


def test_job_refine_to_photos_reaches_the_pipeline(scene):
    assert props.pipeline_settings(scene.brdf).refine == "energy"  # the default
    job_module.apply(_job(scene, {"refine_to_photos": True}), scene)
    assert props.pipeline_settings(scene.brdf).refine == "photo"
    assert props.settings_dict(scene.brdf)["refine_to_photos"] is True


def test_job_photo_consistent_reaches_the_pipeline(scene):
    from brdf_reconstruct.core.method import refine

    assert props.pipeline_settings(scene.brdf).photo_consistent == pytest.approx(
        refine.PHOTO_CONSISTENT)  # the panel's default is the pipeline's
    job_module.apply(_job(scene, {"photo_consistent": 0.0}), scene)
    assert props.pipeline_settings(scene.brdf).photo_consistent == 0.0
    assert props.settings_dict(scene.brdf)["photo_consistent"] == 0.0
    assert scene.brdf.preset == "BALANCED"  # not a preset's value


def test_job_keep_highlight_energy_reaches_the_pipeline(scene):
    assert scene.brdf.keep_highlight_energy is True  # Balanced's
    job_module.apply(_job(scene, {"keep_highlight_energy": False}), scene)
    assert props.pipeline_settings(scene.brdf).refine == "none"
    assert props.settings_dict(scene.brdf)["keep_highlight_energy"] is False
    assert scene.brdf.preset == "CUSTOM"  # off a preset's value


def test_job_texture_settings_are_applied_and_checked(scene):
    assert scene.brdf.texture is False  # the default: untextured, as the paper
    job_module.apply(_job(scene, {"texture": True, "texture_size": 256, "uv_map": "scan"}),
                     scene)
    s = scene.brdf
    assert (s.texture, s.texture_size, s.uv_map) == (True, 256, "scan")
    assert props.settings_dict(s)["texture"] is True
    with pytest.raises(job_module.JobError, match="texture_size = 9000"):
        job_module.apply(_job(scene, {"texture_size": 9000}), scene)


def test_job_unknown_sampler_is_one_sentence(scene):
    with pytest.raises(job_module.JobError) as error:
        job_module.apply(_job(scene, {"sampler": "paper"}), scene)
    assert str(error.value) == "setting sampler = 'paper': must be one of CONDITION, RISK"
    assert scene.brdf.target is None


@pytest.mark.parametrize("value", [200, -1, 181])
def test_job_angle_out_of_range_names_degrees(scene, value):
    """Checked in degrees before anything is set (the scan is not even chosen)."""
    with pytest.raises(job_module.JobError) as error:
        job_module.apply(_job(scene, {"peak_max_angle": value}), scene)
    assert str(error.value) == (f"setting peak_max_angle = {value}: must be from 0 to "
                                "180 degrees")
    assert scene.brdf.target is None


@pytest.mark.parametrize("key, value, message", [
    ("north_offset", 270, "photo 1: [photo.sun] north_offset = 270: must be from -180 to "
                          "180 degrees"),
    ("latitude", 95.0, "photo 1: [photo.sun] latitude = 95.0: must be from -90 to 90"),
    ("longitude", "east", "photo 1: [photo.sun] longitude = 'east': must be a number"),
    ("utc_offset", 15, "photo 1: [photo.sun] utc_offset = 15: must be from -14 to 14"),
])
def test_job_sun_numbers_out_of_range_are_one_sentence(scene, key, value, message):
    """Blender would clamp them silently; they are checked before anything is set."""
    sun = {"date": "2026-06-21 12:00:00", "latitude": 48.1, "longitude": 11.6, key: value}
    with pytest.raises(job_module.JobError) as error:
        job_module.apply(_job(scene, sun=sun), scene)
    assert str(error.value) == message
    assert scene.brdf.target is None and len(scene.brdf.photos) == 0
