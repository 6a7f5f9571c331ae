"""Every panel's draw() in each state, through a stand-in layout that records the
calls (pip bpy has no window system, so a draw error would otherwise ship).

The stand-in checks what Blender would check at draw time: each ``prop``
names a real property of its data, each ``operator`` a registered operator,
each ``template_list`` a registered UIList and real collection properties.
"""

import json

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

    def label(self, text="", icon="NONE"):
        assert isinstance(text, str)
        _check_icon(icon)
        self.calls.append(("label", text))

    def separator(self, **_kwargs):
        self.calls.append(("separator", None))

    def prop(self, data, name, **kwargs):
        assert name in data.bl_rna.properties, f"{data} has no property {name}"
        _check_icon(kwargs.get("icon", "NONE"))
        self.calls.append(("prop", name))

    def operator(self, idname, **kwargs):
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
    assert ("template_ID_preview", "plot") in calls
    assert ("template_ID_preview", "slice_plot") in calls
    assert ("operator", "brdf.export") in calls


def test_photo_list_item_draws(scene):
    photo = _with_photo(scene)
    calls = []
    panel.BRDF_UL_photos.draw_item(None, bpy.context, Layout(calls), scene.brdf, photo,
                                   0, scene.brdf, "active_photo")
    assert ("label", "view0.exr") in calls
