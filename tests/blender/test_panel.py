"""Every panel's draw() in each state, through a stand-in layout that records the
calls (pip bpy has no window system, so a draw error would otherwise ship).

The stand-in checks what Blender would check at draw time: each ``prop``
names a real property of its data, each ``operator`` a registered operator,
each ``template_list`` a registered UIList and real collection properties, and
``label`` / ``prop`` / ``operator`` take only the keywords Blender's own take.
It also records whether each label is translated as it draws
(``("translate", text, bool)``), for the translation rule of panel.py.
"""

import ast
import json
import pathlib

import pytest

bpy = pytest.importorskip("bpy")

from brdf_reconstruct.brdf_addon import panel  # noqa: E402


class Layout:
    """Records layout calls; sub-layouts share the record."""

    def __init__(self, calls):
        self.calls = calls
        self.active = self.enabled = True
        self.scale_y = self.scale_x = 1.0
        self.use_property_split = False

    def _sub(self, kind, **kwargs):
        self.calls.append((kind, kwargs))
        return Layout(self.calls)

    def row(self, **kwargs):
        return self._sub("row", **kwargs)

    def column(self, **kwargs):
        return self._sub("column", **kwargs)

    def box(self):
        return self._sub("box")

    def split(self, **kwargs):
        return self._sub("split", **kwargs)

    def label(self, **kwargs):
        _check_keywords("label", kwargs)
        text = kwargs.get("text", "")
        assert isinstance(text, str)
        _check_icon(kwargs.get("icon", "NONE"))
        self.calls.append(("label", text))
        self.calls.append(("translate", text, kwargs.get("translate", True)))

    def separator(self, **_kwargs):
        self.calls.append(("separator", None))

    def prop(self, data, name, **kwargs):
        _check_keywords("prop", kwargs)
        assert name in data.bl_rna.properties, f"{data} has no property {name}"
        _check_icon(kwargs.get("icon", "NONE"))
        self.calls.append(("prop", name))
        if kwargs.get("text"):
            self.calls.append(("translate", kwargs["text"], kwargs.get("translate", True)))

    def operator(self, idname, **kwargs):
        _check_keywords("operator", kwargs)
        category, name = idname.split(".")
        op = getattr(getattr(bpy.ops, category), name)
        op.get_rna_type()  # raises if the operator is not registered
        _check_icon(kwargs.get("icon", "NONE"))
        self.calls.append(("operator", idname))
        return OperatorProperties(op.get_rna_type())

    def template_list(self, list_type, list_id, data, prop, active_data, active_prop, **_kw):
        assert hasattr(bpy.types, list_type), f"UIList {list_type} not registered"
        assert prop in data.bl_rna.properties and active_prop in active_data.bl_rna.properties
        self.calls.append(("template_list", prop))

    def template_ID_preview(self, data, prop, **_kwargs):  # noqa: N802 - Blender's name
        assert prop in data.bl_rna.properties
        self.calls.append(("template_ID_preview", prop))


class OperatorProperties:
    """What ``layout.operator`` returns: only the operator's own properties can be set."""

    def __init__(self, rna):
        object.__setattr__(self, "_names", set(rna.properties.keys()))

    def __setattr__(self, name, value):
        assert name in self._names, f"operator has no property {name}"
        object.__setattr__(self, name, value)


ICONS = set(bpy.types.UILayout.bl_rna.functions["label"].parameters["icon"].enum_items.keys())


def _check_icon(icon):
    assert icon in ICONS, f"unknown icon {icon}"


def _check_keywords(function, kwargs):
    known = set(bpy.types.UILayout.bl_rna.functions[function].parameters.keys())
    assert set(kwargs) <= known, f"UILayout.{function} takes no {set(kwargs) - known}"


@pytest.fixture
def scene(registered):
    return registered


def _draw_all(context):
    calls = []
    for cls in panel.CLASSES:
        if not issubclass(cls, bpy.types.Panel):
            continue
        assert cls.poll(context)
        fake = type("P", (), {"layout": Layout(calls)})()
        cls.draw(fake, context)
    return calls


def _labels(calls):
    return [c[1] for c in calls if c[0] == "label"]


def _with_photo(scene):
    bpy.ops.mesh.primitive_cube_add()
    scan = bpy.context.active_object
    cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    scene.collection.objects.link(cam)
    s = scene.brdf
    s.target = scan
    p = s.photos.add()
    p.name, p.filepath, p.camera = "view0.exr", "//view0.exr", cam
    return p


def test_nothing_set(scene):
    calls = _draw_all(bpy.context)
    assert "Add the photos taken under one distant light" in _labels(calls)
    assert "Choose the scan first" in _labels(calls)
    assert "No results yet" in _labels(calls)
    assert ("operator", "brdf.import_colmap") in calls


def test_photos_added_each_light_source(scene):
    photo = _with_photo(scene)
    for source in ("SUN_OBJECT", "DIRECTION", "PROBE", "SUN_POSITION"):
        photo.light_source = source
        calls = _draw_all(bpy.context)
        assert ("operator", "brdf.reconstruct") in calls
        assert ("template_list", "photos") in calls
    assert ("prop", "latitude") in calls


def _tuples(calls):
    """The (kind, name) calls, for set comparisons (layout calls carry dicts)."""
    return {c for c in calls if all(isinstance(x, str) for x in c)}


def test_real_capture_fields_show_when_they_apply(scene):
    """The probe circle shows once a radius is given; typed date and place hide when
    they come from EXIF; the reference mask shows with a reference."""
    photo = _with_photo(scene)
    photo.light_source = "PROBE"
    assert ("prop", "probe_center") not in _tuples(_draw_all(bpy.context))
    photo.probe_radius = 40.0
    assert ("prop", "probe_center") in _tuples(_draw_all(bpy.context))
    photo.light_source = "SUN_POSITION"
    calls = _tuples(_draw_all(bpy.context))
    assert {("prop", "when"), ("prop", "latitude"), ("prop", "scene_up"),
            ("operator", "brdf.up_from_cameras")} <= calls
    photo.time_from_exif = photo.place_from_exif = True
    calls = _tuples(_draw_all(bpy.context))
    assert ("prop", "when") not in calls and ("prop", "latitude") not in calls
    assert ("prop", "reference_mask_path") not in calls
    photo.reference_kind = "CARD"
    calls = _tuples(_draw_all(bpy.context))
    assert {("prop", "reference_mask_path"), ("prop", "color_space"),
            ("prop", "exposure"), ("prop", "silhouette_margin")} <= calls


def test_settings_for_each_selection_path(scene):
    for path in ("FAST", "CYCLES"):
        scene.brdf.kl_path = path
        calls = _draw_all(bpy.context)
        assert (("prop", "kl_samples") in calls) == (path == "CYCLES")


def test_a_textured_scan_without_uvs_is_offered_a_copy_with_one(scene):
    _with_photo(scene)
    s = scene.brdf
    assert ("prop", "export_gltf") in _tuples(_draw_all(bpy.context))
    s.texture = True
    assert ("operator", "brdf.uv_copy") not in _tuples(_draw_all(bpy.context))  # the cube's UVs
    layers = s.target.data.uv_layers
    layers.remove(layers[0])
    calls = _draw_all(bpy.context)
    assert "The scan has no UV map" in _labels(calls)
    assert ("operator", "brdf.uv_copy") in _tuples(calls)


def test_running(scene):
    _with_photo(scene)
    scene.brdf.running = True
    scene.brdf.status = "G-buffers 1/3"
    calls = _draw_all(bpy.context)
    assert "Press Esc to cancel" in _labels(calls)
    assert ("operator", "brdf.reconstruct") not in calls


def test_results(scene):
    _with_photo(scene)
    ok = scene.brdf.results.add()
    ok.label, ok.status, ok.winner, ok.kl, ok.bake_error = "Scan", "ok", 3, 0.12, 0.04
    ok.counts = json.dumps({"observed": 900, "removed": {"curvature": 100}, "reliable": 800})
    ok.notes = json.dumps(["the irradiance is likely too low"])
    ok.material = bpy.data.materials.new("BRDF Scan")
    ok.plot = bpy.data.images.new("plot", 4, 4)
    ok.slice_plot = bpy.data.images.new("slice", 4, 4)
    ok.table_path = "/tmp/brdf_0.binary"
    bad = scene.brdf.results.add()
    bad.label, bad.status, bad.reason = "slot 1", "skipped", "region 1: no photo sees it"
    scene.brdf.capture_notes = json.dumps(["a.png: 12 saturated pixels excluded"])
    calls = _draw_all(bpy.context)
    labels = _labels(calls)
    assert "a.png: 12 saturated pixels excluded" in labels
    assert "Trial 3, KL 0.1200" in labels
    assert "Samples: 900 observed, -100 curvature, 800 reliable" in labels
    assert "region 1: no photo sees it" in labels
    assert "the irradiance is likely too low" in labels
    assert ("template_ID_preview", "plot") in calls
    assert ("template_ID_preview", "slice_plot") in calls
    assert ("operator", "brdf.export") in calls


def test_photo_list_item_draws(scene):
    photo = _with_photo(scene)
    calls = []
    panel.BRDF_UL_photos.draw_item(None, bpy.context, Layout(calls), scene.brdf, photo,
                                   0, scene.brdf, "active_photo")
    assert ("label", "view0.exr") in calls


# --- translation: constant labels translate as they draw, labels with values do not ----

def _constants(*modules):
    """Every string constant in the source of ``modules`` (the texts a translator sees)."""
    out = set()
    for module in modules:
        tree = ast.parse(pathlib.Path(module.__file__).read_text())
        out |= {n.value for n in ast.walk(tree) if isinstance(n, ast.Constant)
                and isinstance(n.value, str)}
    return out


def _every_state(scene):
    """The layout calls of every panel in each state, and of the photo list's item."""
    from brdf_reconstruct.brdf_addon import props

    calls = _draw_all(bpy.context)
    photo = _with_photo(scene)
    for source in ("SUN_OBJECT", "DIRECTION", "PROBE", "SUN_POSITION"):
        photo.light_source = source
        calls += _draw_all(bpy.context)
        panel.BRDF_UL_photos.draw_item(None, bpy.context, Layout(calls), scene.brdf, photo,
                                       0, scene.brdf, "active_photo")
    scene.brdf.running, scene.brdf.status = True, "G-buffers 1/3"
    calls += _draw_all(bpy.context)
    scene.brdf.running = False
    _add_results(scene)
    calls += _draw_all(bpy.context)
    return calls, _constants(panel, props, panel.presets)


def _add_results(scene):
    ok = scene.brdf.results.add()
    ok.label, ok.status, ok.winner, ok.kl, ok.bake_error = "Bronze", "ok", 3, 0.12, 0.04
    ok.counts = json.dumps({"observed": 900, "removed": {"curvature": 100}, "reliable": 800})
    ok.notes = json.dumps(["Bronze: the irradiance is likely too low"])
    ok.table_path = "/tmp/brdf_0.binary"
    bad = scene.brdf.results.add()
    bad.label, bad.status, bad.reason = "slot 1", "skipped", "region 1: no photo sees it"
    scene.brdf.capture_notes = json.dumps(["a.png: 12 saturated pixels excluded"])


def test_only_constant_labels_are_translated_as_they_draw(scene):
    """A label Blender translates as it draws must be a constant of the source (else no
    translator could have it, and a name such as a region's could be "translated");
    names, reasons, notes and filled-in format strings are drawn with translate=False."""
    calls, constants = _every_state(scene)
    flags = [(text, flag) for kind, *rest in calls if kind == "translate"
             for text, flag in [rest]]
    translated = {text for text, flag in flags if flag}
    assert translated - constants == set()
    kept = {text for text, flag in flags if not flag}
    assert {"view0.exr", "cam", "Bronze", "region 1: no photo sees it",
            "a.png: 12 saturated pixels excluded", "Trial 3, KL 0.1200", "Bake error 0.040",
            "Bronze: the irradiance is likely too low",
            "Samples: 900 observed, -100 curvature, 800 reliable", "brdf_0.binary",
            "G-buffers 1/3", "1 region(s)", "1 camera(s) in the scene"} <= kept
    assert {"No results yet", "Choose the scan first", "Press Esc to cancel"} <= translated


def test_labels_with_values_are_translated_before_they_are_filled(scene, monkeypatch):
    """The format string (a constant) goes through pgettext_iface, then the values go in."""
    monkeypatch.setattr(panel, "iface_", lambda text: f"<{text}>")
    _with_photo(scene)
    _add_results(scene)
    labels = _labels(_draw_all(bpy.context))
    assert {"<1 region(s)>", "<1 camera(s) in the scene>", "<Trial 3, KL 0.1200>",
            "<Bake error 0.040>",
            "<Samples: 900 observed<, -100 curvature>, 800 reliable>"} <= set(labels)
    scene.brdf.running, scene.brdf.status = True, ""
    assert ("translate", "<Running>", False) in _draw_all(bpy.context)


def test_samples_line_without_removals(scene):
    _with_photo(scene)
    ok = scene.brdf.results.add()
    ok.label, ok.status, ok.winner, ok.bake_error = "Scan", "ok", 0, -1.0
    ok.counts = json.dumps({"observed": 50, "removed": {}, "reliable": 50})
    labels = _labels(_draw_all(bpy.context))
    assert "Samples: 50 observed, 50 reliable" in labels
    assert not any(label.startswith("Bake error") for label in labels)  # -1: not measured


@pytest.mark.parametrize("source, shown", [("SUN_OBJECT", "Sun Object"),
                                           ("PROBE", "Sphere Probe"),
                                           ("SUN_POSITION", "Date, Time, Place")])
def test_photo_list_shows_the_light_sources_own_name(scene, source, shown):
    photo = _with_photo(scene)
    photo.light_source = source
    calls = []
    panel.BRDF_UL_photos.draw_item(None, bpy.context, Layout(calls), scene.brdf, photo,
                                   0, scene.brdf, "active_photo")
    assert ("label", shown) in calls
    assert ("translate", "view0.exr", False) in calls and ("translate", "cam", False) in calls


def test_photo_list_item_without_image_or_camera(scene):
    photo = scene.brdf.photos.add()
    calls = []
    panel.BRDF_UL_photos.draw_item(None, bpy.context, Layout(calls), scene.brdf, photo,
                                   0, scene.brdf, "active_photo")
    assert ("translate", "(no image)", True) in calls
    assert ("translate", "no camera", True) in calls


# --- the Results panel's Export button: brdf.export ------------------------------------

def _exportable(scene, tmp_path):
    """A result whose run wrote brdf_0.binary and report.json in tmp_path/run."""
    run = tmp_path / "run"
    run.mkdir()
    (run / "brdf_0.binary").write_bytes(b"table bytes")
    (run / "report.json").write_text('{"regions": []}')
    ok = scene.brdf.results.add()
    ok.label, ok.status, ok.table_path = "Bronze", "ok", str(run / "brdf_0.binary")
    return run


def _export(**kwargs):
    """bpy.ops.brdf.export; the one-line error of a cancelled export as RuntimeError."""
    return bpy.ops.brdf.export(**kwargs)


def test_export_declares_the_file_browser_overwrite_check(scene):
    from bpy_extras.io_utils import ExportHelper

    from brdf_reconstruct.operators import export

    rna = bpy.ops.brdf.export.get_rna_type()
    assert issubclass(export.BRDF_OT_export, ExportHelper)
    assert rna.properties["check_existing"].default is True  # the browser warns in red
    assert rna.properties["filepath"].subtype == "FILE_PATH"
    assert rna.properties["overwrite"].default is False
    assert export.BRDF_OT_export.filename_ext == ".binary"


def test_export_copies_the_table_and_its_report(scene, tmp_path):
    run = _exportable(scene, tmp_path)
    assert _export(filepath=str(tmp_path / "bronze"), index=0) == {"FINISHED"}
    assert (tmp_path / "bronze.binary").read_bytes() == b"table bytes"
    assert (tmp_path / "bronze_report.json").read_text() == (run / "report.json").read_text()
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "bronze.binary", "bronze_report.json", "run"]  # no temporary file left


@pytest.mark.parametrize("existing", ["bronze.binary", "bronze_report.json"])
def test_export_never_replaces_a_file_unless_overwrite(scene, tmp_path, existing):
    _exportable(scene, tmp_path)
    (tmp_path / existing).write_bytes(b"the user's own")
    with pytest.raises(RuntimeError, match="exists; choose another name") as error:
        _export(filepath=str(tmp_path / "bronze.binary"), index=0)
    assert len(str(error.value).strip().splitlines()) == 1
    assert (tmp_path / existing).read_bytes() == b"the user's own"
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([existing, "run"])
    assert _export(filepath=str(tmp_path / "bronze.binary"), index=0,
                   overwrite=True) == {"FINISHED"}
    assert (tmp_path / "bronze.binary").read_bytes() == b"table bytes"


def test_export_onto_the_runs_own_table_or_into_a_missing_folder_is_refused(scene, tmp_path):
    run = _exportable(scene, tmp_path)
    with pytest.raises(RuntimeError, match="the run's own table"):
        _export(filepath=str(run / "brdf_0.binary"), index=0, overwrite=True)
    with pytest.raises(RuntimeError, match="does not exist; choose an existing folder"):
        _export(filepath=str(tmp_path / "nowhere" / "bronze.binary"), index=0)
    assert (run / "brdf_0.binary").read_bytes() == b"table bytes"


def test_export_failing_midway_leaves_the_old_file(scene, tmp_path, monkeypatch):
    """Written through core.files.replacing: a copy that fails halfway leaves the file
    that was there (the user chose Overwrite) and no temporary file."""
    import shutil

    from brdf_reconstruct.operators import export

    _exportable(scene, tmp_path)
    (tmp_path / "bronze.binary").write_bytes(b"previous export")

    def half_copy(source, target):
        pathlib.Path(target).write_bytes(pathlib.Path(source).read_bytes()[:3])
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(shutil, "copyfile", half_copy)
    reports = []
    fake = type("Op", (), {"index": 0, "filepath": str(tmp_path / "bronze.binary"),
                           "overwrite": True, "filename_ext": ".binary",
                           "report": lambda _self, kind, text: reports.append((kind, text))})()
    assert export.BRDF_OT_export.execute(fake, bpy.context) == {"CANCELLED"}
    ((kind, text),) = reports
    assert kind == {"ERROR"} and "No space left on device" in text and "\n" not in text
    assert (tmp_path / "bronze.binary").read_bytes() == b"previous export"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bronze.binary", "run"]
