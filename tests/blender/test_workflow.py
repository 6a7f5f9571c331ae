"""The artist's workflow in pip bpy: photos, lights, reconstruct, cancel, undo, and
the user's files; on a tiny scene whose photo Cycles renders with a known
Lambertian material (testkit/blender_scene.py)."""

import datetime as dt
import hashlib
import json
import math
import os

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from image_files import write_image  # noqa: E402

from brdf_reconstruct.brdf_addon import (  # noqa: E402
    gathering,
    light_sources,
    photo_input,
    photo_list,
    runner,
)
from brdf_reconstruct.core.brdf import merl  # noqa: E402
from brdf_reconstruct.core.capture import light_probe, photo_io, sun  # noqa: E402
from brdf_reconstruct.core.method import pipeline  # noqa: E402
from testkit import blender_scene as BS  # noqa: E402


def _add_photo(built):
    added, unmatched = photo_list.add_photos(built["scene"], [str(built["photo"])])
    assert unmatched == [] and len(added) == 1
    p = added[0]
    p.irradiance = (BS.lit_irradiance(),) * 3
    return p


def _digest(path):
    return hashlib.sha256(open(path, "rb").read()).hexdigest()


# --- photos ---------------------------------------------------------------------

def test_photo_matched_by_image_name_stem(tiny):
    p = _add_photo(tiny)
    assert p.camera == tiny["camera"]  # view0.exr <-> COLMAP image "view0.jpg"
    assert p.sun == tiny["sun"]  # the scene's one Sun


def test_unmatched_photos_are_listed_not_guessed(tiny, tmp_path):
    other = tmp_path / "elsewhere.exr"
    other.write_bytes(b"")
    added, unmatched = photo_list.add_photos(tiny["scene"], [str(other)])
    assert added == [] and unmatched == ["photo elsewhere.exr matches no camera by image name"]
    twin = bpy.data.objects.new("twin", bpy.data.cameras.new("twin"))
    twin["brdf_image_name"] = "view0.png"
    tiny["scene"].collection.objects.link(twin)
    added, unmatched = photo_list.add_photos(tiny["scene"], [str(tiny["photo"])])
    assert added == [] and "matches several cameras" in unmatched[0]


def test_a_photo_is_not_added_twice(tiny):
    _add_photo(tiny)
    added, unmatched = photo_list.add_photos(tiny["scene"], [str(tiny["photo"])])
    assert added == [] and "already in the list" in unmatched[0]


# --- each light source ------------------------------------------------------------

def test_light_from_sun_object(tiny):
    p = _add_photo(tiny)
    np.testing.assert_allclose(light_sources.photo_light(tiny["scene"], p), BS.LIGHT, atol=1e-6)


def test_light_from_direction(tiny):
    p = _add_photo(tiny)
    p.light_source, p.direction = "DIRECTION", (0.0, 0.0, 2.0)
    np.testing.assert_allclose(light_sources.photo_light(tiny["scene"], p), [0, 0, 1], atol=1e-7)


def test_a_light_direction_that_is_not_finite_says_so(tiny):
    """Issue 13: NaN typed in the panel was reported as a zero direction; an infinite
    component (which Blender stores as the float32 maximum) is not finite either."""
    p = _add_photo(tiny)
    p.light_source, p.direction = "DIRECTION", (math.nan, 0.0, 1.0)
    with pytest.raises(ValueError, match=r"^photo view0\.exr has a light direction that is "
                                         r"not finite \(nan, 0, 1\): type three numbers$"):
        light_sources.photo_light(tiny["scene"], p)
    p.direction = (0.0, -math.inf, 1.0)
    with pytest.raises(ValueError, match=r"not finite \(0, -inf, 1\)"):
        light_sources.photo_light(tiny["scene"], p)
    p.direction = (0.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="has a zero light direction"):
        light_sources.photo_light(tiny["scene"], p)


def test_light_from_date_time_place_creates_a_sun(tiny):
    p = _add_photo(tiny)
    p.when, p.utc_offset, p.latitude, p.longitude = "2026-06-21 15:30:00", 2.0, 48.1, 11.6
    p.north_offset = math.radians(90.0)  # an angle property: radians
    bpy.context.scene.brdf.active_photo = 0
    assert bpy.ops.brdf.light_from_time() == {"FINISHED"}
    when = dt.datetime(2026, 6, 21, 15, 30, tzinfo=dt.timezone(dt.timedelta(hours=2)))
    e, n, u = sun.sun_direction(when, 48.1, 11.6)
    expected = np.array([-n, e, u])  # north turned 90 deg counter-clockwise: +Y -> -X
    np.testing.assert_allclose(light_sources.photo_light(tiny["scene"], p), expected, atol=1e-9)
    shown = light_sources.sun_object_direction(bpy.data.objects[light_sources.SUN_NAME])
    np.testing.assert_allclose(shown, expected, atol=1e-6)
    assert bpy.data.objects[light_sources.SUN_NAME] != tiny["sun"]
    np.testing.assert_allclose(light_sources.sun_object_direction(tiny["sun"]), BS.LIGHT, atol=1e-6)


def test_sun_below_the_horizon_is_one_clear_error(tiny):
    p = _add_photo(tiny)
    p.light_source = "SUN_POSITION"
    p.when, p.latitude, p.longitude = "2026-06-21 02:00:00", 48.1, 11.6
    with pytest.raises(ValueError, match="below the horizon"):
        light_sources.photo_light(tiny["scene"], p)


def _probe_photo(tiny, tmp_path):
    """A chrome sphere rendered by Cycles under the scene's Sun; the photo entry
    set to use it."""
    p = _add_photo(tiny)
    scene = tiny["scene"]
    tiny["scan"].hide_render = True
    bpy.ops.mesh.primitive_uv_sphere_add(segments=96, ring_count=48, radius=1.0)
    probe = bpy.context.active_object
    bpy.ops.object.shade_smooth()
    mat = bpy.data.materials.new("chrome")
    tree = mat.node_tree
    tree.nodes.clear()
    glossy = tree.nodes.new("ShaderNodeBsdfGlossy")
    glossy.inputs["Roughness"].default_value = 0.05
    tree.links.new(glossy.outputs[0], tree.nodes.new("ShaderNodeOutputMaterial").inputs[0])
    probe.data.materials.append(mat)
    tiny["sun"].data.angle = math.radians(1.0)
    world = bpy.data.worlds.new("grey")
    world.color = (0.2, 0.2, 0.2)  # the mirror shows it, so the sphere's outline is seen
    if world.node_tree is not None:
        world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.2, 0.2, 0.2, 1)
    scene.world = world
    BS.render_photo(scene, tmp_path / "probe.exr", size=96)
    p.light_source, p.probe_path = "PROBE", str(tmp_path / "probe.exr")
    return p


def test_light_from_sphere_probe(tiny, tmp_path):
    """A glossy sphere rendered by Cycles under the scene's Sun gives its direction."""
    p = _probe_photo(tiny, tmp_path)
    details = {}
    found = light_sources.photo_light(tiny["scene"], p, details)
    angle = math.degrees(math.acos(np.clip(found @ BS.LIGHT, -1, 1)))
    assert angle < 1.0, angle
    assert details["sphere"] == "found" and angle < 2 * details["uncertainty_deg"]


def test_light_from_a_user_drawn_probe_circle(tiny, tmp_path):
    """A circle drawn 1.5 px off and 1.5 px too large is snapped to the outline: the
    same light as the automatic circle."""
    p = _probe_photo(tiny, tmp_path)
    found = light_sources.photo_light(tiny["scene"], p)
    image = photo_io.read_photo(p.probe_path)
    camera = light_sources.camera_intrinsics(tiny["scene"], p.camera, 96, 96)
    (cx, cy), r = light_probe.locate_sphere(image, camera=camera)
    p.probe_center, p.probe_radius = (cx + 1.5, cy - 1.0), r + 1.5
    details = {}
    drawn = light_sources.photo_light(tiny["scene"], p, details)
    assert details["sphere"] == "given"
    assert math.degrees(math.acos(np.clip(drawn @ found, -1, 1))) < 0.05


# --- reconstruct ----------------------------------------------------------------

def test_reconstruct_makes_material_table_and_report(tiny):
    _add_photo(tiny)
    user_photo = _digest(tiny["photo"])
    materials_before = {m.name for m in bpy.data.materials}
    assert bpy.ops.brdf.reconstruct() == {"FINISHED"}
    s = tiny["scene"].brdf
    assert len(s.results) == 1
    r = s.results[0]
    assert r.status == "ok" and r.winner in (0, 1) and np.isfinite(r.kl)
    assert r.material is not None and r.material.name not in materials_before
    assert r.material.node_tree is not None
    assert 0 <= r.bake_error < 1.0
    table = merl.read(r.table_path)
    # Lambert albedo 0.5 under Cycles: rho = 0.5 / pi where the photo saw it
    seen = table[:, :30, :30]
    assert np.nanmedian(seen) == pytest.approx(BS.ALBEDO / math.pi, rel=0.05)
    report = json.loads((tiny["dir"] / "out" / "report.json").read_text())
    assert report["regions"][0]["kl"] and report["regions"][0]["status"] == "ok"
    assert (tiny["dir"] / "out" / "brdf_0_slice.png").is_file()
    assert (tiny["dir"] / "out" / "brdf_0_reliable_region.png").is_file()
    assert tuple(r.slice_plot.size) == (270, 270) and r.plot.size[1] == BS.SIZE
    assert _digest(tiny["photo"]) == user_photo  # the photo was only read
    known = bpy.data.materials["Known Lambert"]
    assert tiny["scan"].material_slots[0].material == known  # nothing re-assigned
    assert [n.bl_idname for n in known.node_tree.nodes] == [
        "ShaderNodeBsdfDiffuse", "ShaderNodeOutputMaterial"]


def test_no_reliable_pixels_is_one_clear_error(tiny):
    _add_photo(tiny)
    tiny["scene"].brdf.curvature_threshold = 0.0
    tiny["scene"].brdf.use_brightest = False
    with pytest.raises(RuntimeError, match="No reliable pixels"):
        bpy.ops.brdf.reconstruct()


def test_missing_photo_file_is_one_clear_error(tiny):
    p = _add_photo(tiny)
    p.filepath = str(tiny["dir"] / "gone.exr")
    with pytest.raises(RuntimeError, match="Photo file not found"):
        bpy.ops.brdf.reconstruct()


def test_mesh_without_faces_is_one_clear_error(tiny):
    _add_photo(tiny)
    mesh = bpy.data.meshes.new("points")
    mesh.from_pydata([(0, 0, 0), (1, 0, 0)], [], [])
    obj = bpy.data.objects.new("points", mesh)
    tiny["scene"].collection.objects.link(obj)
    tiny["scene"].brdf.target = obj
    with pytest.raises(ValueError, match="mesh without faces"):
        gathering.check_scene(tiny["scene"])


@pytest.mark.parametrize("damage, message", [
    ("nan", "has 1 vertex with NaN or Inf coordinates"),
    ("collapsed", "has no face with an area"),
    ("scale", "transform scales it to nothing"),
])
def test_a_scan_no_photo_can_see_as_a_surface_is_one_clear_error(tiny, damage, message):
    """A vertex at NaN (Cycles drops its faces without a word), every face collapsed
    to a point, or a scale of 0: refused before any work, the mesh unchanged."""
    _add_photo(tiny)
    scan = tiny["scene"].brdf.target
    mesh = scan.data.copy()
    obj = bpy.data.objects.new("damaged", mesh)
    obj.matrix_world = scan.matrix_world
    tiny["scene"].collection.objects.link(obj)
    if damage == "nan":
        mesh.vertices[0].co = (float("nan"), 0.0, 0.0)
    elif damage == "collapsed":
        for v in mesh.vertices:
            v.co = (0.25, 0.5, 0.0)
    else:
        obj.scale = (0.0, 0.0, 0.0)
        bpy.context.view_layer.update()
    before = np.array([tuple(v.co) for v in mesh.vertices])
    tiny["scene"].brdf.target = obj
    with pytest.raises(ValueError, match=message) as error:
        gathering.check_scene(tiny["scene"])
    assert "\n" not in str(error.value)
    np.testing.assert_array_equal(np.array([tuple(v.co) for v in mesh.vertices]), before)
    tiny["scene"].brdf.target = scan
    gathering.check_scene(tiny["scene"])  # the undamaged scan passes


def test_a_photo_holding_part_of_its_frame_is_used_where_it_holds_pixels(tiny):
    """An EXR of the photo's middle (its data window, as a render cropped to a
    region) is placed in its camera's frame: its radiance and G-buffers are the whole
    photo's there, and only those pixels are used (a note says so). Before, the crop
    was taken for a scaled photo and the camera scaled to it: every pixel misplaced."""
    import OpenImageIO as oiio

    entry = _add_photo(tiny)
    full = photo_input.gather_photo(tiny["scene"], entry).input
    inp = oiio.ImageInput.open(str(tiny["photo"]))
    pixels = np.asarray(inp.read_image(0, 0, 0, inp.spec().nchannels, oiio.FLOAT))
    h, w = inp.spec().height, inp.spec().width
    inp.close()
    pixels = pixels.reshape(h, w, -1)
    top, left = h // 4, w // 4
    crop_path = write_image(tiny["photo"].with_name("view0_crop.exr"),
                            pixels[top:h - top, left:w - left], oiio.FLOAT,
                            origin=(left, top), frame=(0, 0, w, h))
    entry.filepath = str(crop_path)
    gathered = photo_input.gather_photo(tiny["scene"], entry)
    crop = gathered.input
    window = np.zeros((h, w), bool)
    window[top:h - top, left:w - left] = True
    np.testing.assert_array_equal(crop.normal, full.normal)
    np.testing.assert_array_equal(crop.photo[window], full.photo[window])
    used_full = full.region >= 0 if full.mask is None else (full.region >= 0) & full.mask
    np.testing.assert_array_equal(crop.mask & (crop.region >= 0), used_full & window)
    assert "holds" in gathered.report["partial"] and "scaled" not in gathered.report


def test_a_float_photo_clipped_at_an_unstated_white_level_is_one_note(tiny):
    """The photo's highlight clipped at a level the EXR does not state (as a RAW
    converter writes a clipped camera photo) is found by its plateau and said in a
    note that counts its pixels on the scan and gives the level; they are used at
    their value, not removed (docs/results.md measures why), and the photo's values
    are not changed; they never set an irradiance reference. With the user's
    Saturation Level the plateau is not looked for: the user's level rules, and those
    pixels are left out."""
    import OpenImageIO as oiio

    entry = _add_photo(tiny)
    full = photo_input.gather_photo(tiny["scene"], entry)
    inp = oiio.ImageInput.open(str(tiny["photo"]))
    spec = inp.spec()
    pixels = np.asarray(inp.read_image(0, 0, 0, spec.nchannels, oiio.FLOAT))
    inp.close()
    pixels = pixels.reshape(spec.height, spec.width, -1).copy()
    on_scan = full.input.photo[full.input.region >= 0]
    # a tenth of the scan clipped, at a level the float32 file holds exactly
    level = float(np.float32(np.quantile(on_scan.max(axis=-1), 0.9)))
    pixels[..., :3] = np.minimum(pixels[..., :3], level)
    entry.filepath = str(write_image(tiny["photo"].with_name("view0_clipped.exr"), pixels,
                                     oiio.FLOAT))
    gathered = photo_input.gather_photo(tiny["scene"], entry)
    clipped = np.any(full.input.photo >= level, axis=-1)
    on_scan = int(np.count_nonzero(clipped & (full.input.region >= 0)))
    assert gathered.report["clipped_pixels"] == on_scan > 0
    assert f"{level:.6g}" in gathered.report["white_level"]
    note = f"view0_clipped.exr: {on_scan} pixels on the scan are at the file's largest value"
    assert any(line.startswith(note) for line in gathering.capture_notes(
        {"photos": [gathered.report | {"name": "view0_clipped.exr"}]}))
    assert not gathered.input.saturated.any() and gathered.report["saturated_pixels"] == 0
    np.testing.assert_array_equal(gathered.input.photo, np.minimum(full.input.photo, level))
    assert not full.input.saturated.any() and full.report["clipped_pixels"] == 0
    everywhere = write_image(tiny["photo"].with_name("all.png"),
                             np.full(clipped.shape + (1,), 255, np.uint8), oiio.UINT8)
    entry.reference_kind, entry.reference_mask_path = "SCAN", str(everywhere)
    reference = photo_input.gather_photo(tiny["scene"], entry).reference
    assert int(np.count_nonzero(reference.saturated)) == on_scan  # never a reference
    entry.reference_kind = "NONE"
    tiny["scene"].brdf.clip_level = level  # the user's level: those pixels left out
    told = photo_input.gather_photo(tiny["scene"], entry)
    assert told.report["clipped_pixels"] == 0 and told.report["saturated_pixels"] == on_scan
    np.testing.assert_array_equal(told.input.saturated, clipped)


def test_cancel_leaves_the_scene_unchanged(tiny):
    _add_photo(tiny)
    before = {k: len(getattr(bpy.data, k)) for k in ("materials", "images", "node_groups",
                                                     "objects", "scenes", "lights")}
    run = runner.Run(tiny["scene"], threaded=True)
    assert run.step() is False  # the photo's G-buffers
    run.cancel()
    with pytest.raises(pipeline.Cancelled):
        run.step()
    after = {k: len(getattr(bpy.data, k)) for k in before}
    assert after == before
    assert len(tiny["scene"].brdf.results) == 0
    assert not (tiny["dir"] / "out").exists()


def test_worker_thread_run_matches_synchronous_run(tiny):
    _add_photo(tiny)
    a = runner.Run(tiny["scene"], threaded=True, bake=False)
    while not a.step():
        pass
    kl_threaded = a.report["regions"][0]["kl"]
    b = runner.Run(tiny["scene"], threaded=False, bake=False).run()
    assert b["regions"][0]["kl"] == kl_threaded  # same seed, same result


def test_undo_after_reconstruct(tiny):
    """Ctrl+Z after a run: Blender's global (memfile) undo restores the scene.

    Headless, Blender keeps a window but pushes no undo step for operators called
    from Python, so the test pushes the step the window manager pushes after an
    operator with UNDO in its options (asserted here), then undoes and redoes."""
    assert "UNDO" in bpy.types.BRDF_OT_reconstruct.bl_options
    _add_photo(tiny)
    window = bpy.context.window_manager.windows[0]
    blocks = ("materials", "images", "node_groups", "objects", "meshes", "lights", "scenes")
    before = {k: sorted(getattr(bpy.data, k).keys()) for k in blocks}
    with bpy.context.temp_override(window=window, screen=window.screen):
        bpy.ops.ed.undo_push(message="before")
        assert bpy.ops.brdf.reconstruct() == {"FINISHED"}
        bpy.ops.ed.undo_push(message=bpy.types.BRDF_OT_reconstruct.bl_label)
        after = {k: sorted(getattr(bpy.data, k).keys()) for k in blocks}
        assert after["materials"] != before["materials"]
        assert len(bpy.context.scene.brdf.results) == 1
        assert bpy.ops.ed.undo() == {"FINISHED"}
        assert {k: sorted(getattr(bpy.data, k).keys()) for k in blocks} == before
        assert len(bpy.context.scene.brdf.results) == 0
        assert len(bpy.context.scene.brdf.photos) == 1  # the user's list is kept
        assert bpy.ops.ed.redo() == {"FINISHED"}
        assert {k: sorted(getattr(bpy.data, k).keys()) for k in blocks} == after
        assert bpy.context.scene.brdf.results[0].status == "ok"


def test_output_folder_only_gets_new_files(tiny):
    _add_photo(tiny)
    out = tiny["dir"] / "out"
    out.mkdir()
    mine = out / "notes.txt"
    mine.write_text("the user's file")
    bpy.ops.brdf.reconstruct()
    assert mine.read_text() == "the user's file"
    assert {"brdf_0.binary", "report.json"} <= set(os.listdir(out))


def test_an_unsaved_blend_refuses_a_relative_output_folder(tiny, tmp_path, monkeypatch):
    """Issue 13: the default output folder //brdf_out of a .blend never saved resolved
    against the folder Blender was started from. Refused before any work, nothing
    written there; an absolute folder, or // once the .blend is saved, is used."""
    _add_photo(tiny)
    started = tmp_path / "started_here"
    started.mkdir()
    monkeypatch.chdir(started)
    s = tiny["scene"].brdf
    photo = _digest(tiny["photo"])
    assert bpy.data.filepath == ""
    for value in ("//brdf_out", ""):  # "" is the default's stand-in
        s.output_dir = value
        with pytest.raises(RuntimeError, match=r"^Error: The output folder //brdf_out is "
                                               r"relative to the \.blend, which is not saved: "
                                               r"save the \.blend first or set an absolute "
                                               r"output folder$"):
            bpy.ops.brdf.reconstruct()
    s.output_dir = "brdf_out"  # relative without //: the starting folder too, saved or not
    with pytest.raises(RuntimeError, match="relative to the folder Blender was started from: "
                                           "start it with // for the .blend's folder"):
        bpy.ops.brdf.reconstruct()
    assert list(started.iterdir()) == [] and _digest(tiny["photo"]) == photo
    bpy.ops.wm.save_as_mainfile(filepath=str(tiny["dir"] / "saved.blend"))
    s.output_dir = "//brdf_out"
    from brdf_reconstruct.brdf_addon import outputs

    assert outputs.output_path(tiny["scene"]) == tiny["dir"] / "brdf_out"
    s.output_dir = str(tiny["dir"] / "out")  # absolute: as the batch sets it
    assert outputs.output_path(tiny["scene"]) == tiny["dir"] / "out"


def _two_face_sets(tiny) -> np.ndarray:
    """The tiny scene with its photo and two face sets, 4 at x < 0 and 9 at x >= 0
    (by face centre); returns (F,) the ids."""
    _add_photo(tiny)
    mesh = tiny["scan"].data
    centres = np.zeros(len(mesh.polygons) * 3)
    mesh.polygons.foreach_get("center", centres)
    ids = np.where(centres.reshape(-1, 3)[:, 0] < 0, 4, 9).astype(np.int32)
    mesh.attributes.new(".sculpt_face_set", "INT", "FACE").data.foreach_set("value", ids)
    return ids


def test_face_sets_are_regions(tiny):
    _two_face_sets(tiny)
    tiny["scene"].brdf.region_mode = "FACE_SET"
    report = runner.Run(tiny["scene"], threaded=False, bake=False).run()
    assert [(r["region"], r["label"], r["status"]) for r in report["regions"]] == [
        (4, "face set 4", "ok"), (9, "face set 9", "ok")]


def test_the_gltf_export_gives_each_face_set_its_region_material(tiny):
    """Two regions (face sets on either side of x = 0): the .glb holds one
    primitive per region, each wearing its region's Principled version, and the
    primitive of the x < 0 set lies at x < 0 (Y-up glTF keeps x)."""
    ids = _two_face_sets(tiny)
    mesh = tiny["scan"].data
    s = tiny["scene"].brdf
    s.region_mode, s.export_gltf = "FACE_SET", True
    report = runner.Run(tiny["scene"], threaded=False, bake=False).run()
    names = {r["region"]: r["gltf"]["material"] for r in report["regions"]}
    assert report["gltf"]["faces"] == {names[4]: int((ids == 4).sum()),
                                       names[9]: int((ids == 9).sum())}
    from testkit import glb

    doc, _ = glb.read_glb(tiny["dir"] / "out" / "brdf_scan.glb")
    (gl_mesh,) = doc["meshes"]
    by_name = {doc["materials"][p["material"]]["name"]: p for p in gl_mesh["primitives"]}
    assert set(by_name) == set(names.values())
    west = doc["accessors"][by_name[names[4]]["attributes"]["POSITION"]]
    east = doc["accessors"][by_name[names[9]]["attributes"]["POSITION"]]
    # a face whose centre is at x < 0 reaches at most one edge (0.08 here) past 0
    assert west["max"][0] <= 0.1 and east["min"][0] >= -0.1
    assert west["min"][0] < -0.9 and east["max"][0] > 0.9
    assert mesh.attributes.get(".sculpt_face_set") is not None  # the user's face sets kept
    assert [m.name for m in mesh.materials] == ["Known Lambert"]
