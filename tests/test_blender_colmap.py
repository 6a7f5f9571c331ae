"""brdf.import_colmap in pip ``bpy``: imported cameras reproject COLMAP's observations.

A synthetic COLMAP model (written by pycolmap, binary and text) is imported
through the operator; every 3D point is projected with Blender's own
``world_to_camera_view`` and compared with the 2D observation COLMAP computed
(``Camera.img_from_cam``). Both use image coordinates over [0, W] x [0, H]
(COLMAP pixel (0, 0) has its centre at (0.5, 0.5)), so x = u * W and
y = (1 - v) * H with no half-pixel offset.
"""

import types

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from bpy_extras.object_utils import world_to_camera_view  # noqa: E402
from mathutils import Vector  # noqa: E402

from brdf_reconstruct.core import colmap as cm  # noqa: E402
from brdf_reconstruct.operators import import_colmap as ic  # noqa: E402

pycolmap = pytest.importorskip("pycolmap")

OP = ic.BRDF_OT_import_colmap


def _views():
    """Cameras around the origin: off-centre principal points, fx != fy both ways,
    one portrait image, a square image seen from above, a zero-distortion radial model."""
    return [
        ("a.jpg", "PINHOLE", [800, 860, 300, 260], 640, 480, *cm.look_at([4, 0.5, 1], [0, 0, 0])),
        ("b_portrait.jpg", "PINHOLE", [700, 650, 250, 300], 480, 640,
         *cm.look_at([0.3, 4, 1.5], [0, 0, 0.1])),
        ("c.jpg", "SIMPLE_PINHOLE", [900, 400, 300], 800, 600,
         *cm.look_at([-3, -3, 0.5], [0.1, 0, 0])),
        ("d.jpg", "SIMPLE_RADIAL", [1000, 530, 370, 0.0], 1024, 768,
         *cm.look_at([-4, 1, -1], [0, 0, 0])),
        ("sub/e.jpg", "PINHOLE", [600, 600, 200, 320], 512, 512,
         *cm.look_at([0.5, -0.5, 4.5], [0, 0, 0])),
    ]  # fmt: skip


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    rng = np.random.default_rng(0)
    xyz = rng.uniform(-1, 1, (200, 3))
    rgb = rng.integers(0, 256, (200, 3), dtype=np.uint8)
    rec = cm.synthetic_reconstruction(_views(), xyz, rgb)
    root = tmp_path_factory.mktemp("colmap")
    (root / "bin").mkdir()
    (root / "txt").mkdir()
    rec.write(str(root / "bin"))
    rec.write_text(str(root / "txt"))
    assert {p.suffix for p in (root / "bin").iterdir()} == {".bin"}
    assert {p.suffix for p in (root / "txt").iterdir()} == {".txt"}
    return {"bin": root / "bin", "txt": root / "txt"}


@pytest.fixture(autouse=True)
def operator_registered():
    bpy.ops.wm.read_homefile(use_empty=True)
    registered_here = not OP.is_registered
    if registered_here:
        bpy.utils.register_class(OP)
    try:
        yield
    finally:
        if registered_here:
            bpy.utils.unregister_class(OP)
        bpy.ops.wm.read_homefile(use_empty=True)


def _imported_cameras(collection_name=ic.COLLECTION_NAME):
    return [o for o in bpy.data.collections[collection_name].objects if o.type == "CAMERA"]


def _reprojection_errors(model_dir):
    """Pixel distances between Blender's projection and COLMAP's observations, per camera."""
    rec = pycolmap.Reconstruction(str(model_dir))  # read independently of core.colmap
    by_name = {rec.image(i).name: rec.image(i) for i in rec.reg_image_ids()}
    scene = bpy.context.scene
    errors = {}
    for obj in _imported_cameras():
        image = by_name[obj["brdf_image_name"]]
        camera = rec.camera(image.camera_id)
        ic.set_render_to_camera(scene, obj)
        assert (scene.render.resolution_x, scene.render.resolution_y) == (
            camera.width,
            camera.height,
        )
        obs = image.get_observation_points2D()
        assert len(obs) > 100
        err = []
        for p2d in obs:
            u, v, depth = world_to_camera_view(scene, obj, Vector(rec.point3D(p2d.point3D_id).xyz))
            assert depth > 0
            blender_px = np.array([u * camera.width, (1.0 - v) * camera.height])
            err.append(np.linalg.norm(blender_px - p2d.xy))
        errors[image.name] = np.array(err)
    return errors


@pytest.mark.parametrize("kind", ["bin", "txt"])
def test_reprojection_through_blender(models, kind):
    assert bpy.ops.brdf.import_colmap(directory=str(models[kind])) == {"FINISHED"}
    errors = _reprojection_errors(models[kind])
    assert sorted(errors) == sorted(v[0] for v in _views())
    every = np.concatenate(list(errors.values()))
    print(
        f"\n{kind}: mean {every.mean():.2e} px, max {every.max():.2e} px over {every.size} "
        "observations; per camera max: "
        + ", ".join(f"{name} {e.max():.1e}" for name, e in sorted(errors.items()))
    )
    assert every.mean() < 0.5  # the brief's bound
    assert every.max() < 0.01  # float32 storage in Blender is ~1e-4 px; a convention slip is >= 0.5


def test_intrinsics_and_properties(models):
    bpy.ops.brdf.import_colmap(directory=str(models["bin"]))
    cams = {o["brdf_image_name"]: o for o in _imported_cameras()}
    assert set(cams) == {v[0] for v in _views()}
    a, b, e = cams["a.jpg"], cams["b_portrait.jpg"], cams["sub/e.jpg"]
    assert e.name == "sub/e.jpg"
    assert (a["brdf_width"], a["brdf_height"]) == (640, 480)
    assert (b["brdf_width"], b["brdf_height"]) == (480, 640)
    assert a.data.sensor_fit == "HORIZONTAL" and b.data.sensor_fit == "VERTICAL"
    assert e.data.sensor_fit == "HORIZONTAL"
    # fx < fy: pixels wider than tall; fx > fy: taller than wide
    assert (a["brdf_pixel_aspect_x"], a["brdf_pixel_aspect_y"]) == pytest.approx((860 / 800, 1))
    assert (b["brdf_pixel_aspect_x"], b["brdf_pixel_aspect_y"]) == pytest.approx((1, 700 / 650))
    assert a.data.shift_x == pytest.approx((320 - 300) / 640)
    assert not any(o["brdf_colmap_distorted"] for o in cams.values())
    assert all(o.data.type == "PERSP" for o in cams.values())


def test_first_camera_becomes_active_in_an_empty_scene(models):
    scene = bpy.context.scene
    assert scene.camera is None
    bpy.ops.brdf.import_colmap(directory=str(models["txt"]))
    assert scene.camera["brdf_image_name"] == "a.jpg"  # sorted by image name
    assert (scene.render.resolution_x, scene.render.resolution_y) == (640, 480)
    assert scene.render.resolution_percentage == 100
    assert scene.render.pixel_aspect_x == pytest.approx(860 / 800)


def test_existing_scene_camera_and_render_settings_are_kept(models):
    scene = bpy.context.scene
    mine = bpy.data.objects.new("Mine", bpy.data.cameras.new("Mine"))
    scene.collection.objects.link(mine)
    scene.camera = mine
    scene.render.resolution_x, scene.render.resolution_y = 1234, 567
    bpy.ops.brdf.import_colmap(directory=str(models["bin"]))
    assert scene.camera == mine
    assert (scene.render.resolution_x, scene.render.resolution_y) == (1234, 567)


def _snapshot(objects):
    def data(o):
        d = o.data
        return None if d is None else (d.name, d.lens, d.sensor_width, d.shift_x, d.shift_y)

    return {
        o.name: (
            [list(row) for row in o.matrix_world],
            dict(o.items()),
            data(o),
            [c.name for c in o.users_collection],
        )
        for o in objects
    }


def test_importing_twice_leaves_the_first_import_alone(models):
    scan = bpy.data.objects.new("Scan", None)
    bpy.context.scene.collection.objects.link(scan)
    bpy.ops.brdf.import_colmap(directory=str(models["bin"]))
    first = _imported_cameras()
    before = _snapshot(first + [scan])
    render_before = (bpy.context.scene.render.resolution_x, bpy.context.scene.camera.name)

    bpy.ops.brdf.import_colmap(directory=str(models["txt"]), point_cloud=True)
    assert _snapshot(first + [scan]) == before
    assert (bpy.context.scene.render.resolution_x, bpy.context.scene.camera.name) == render_before
    second = _imported_cameras(ic.COLLECTION_NAME + ".001")
    assert not set(first) & set(second)
    assert sorted(o["brdf_image_name"] for o in second) == sorted(v[0] for v in _views())
    assert all(o.name.endswith(".001") for o in second)  # Blender's suffix; the property is exact


def test_point_cloud(models):
    bpy.ops.brdf.import_colmap(directory=str(models["bin"]), point_cloud=True)
    points = bpy.data.collections[ic.COLLECTION_NAME].objects[ic.POINTS_NAME]
    rec = pycolmap.Reconstruction(str(models["bin"]))
    ids = sorted(rec.point3D_ids())
    xyz = np.array([rec.point3D(i).xyz for i in ids])
    rgb = np.array([rec.point3D(i).color for i in ids])
    co = np.array([v.co[:] for v in points.data.vertices])
    order = np.lexsort(co.T)
    np.testing.assert_allclose(co[order], xyz[np.lexsort(xyz.T)], atol=1e-6)
    srgb = np.array([c.color_srgb[:3] for c in points.data.color_attributes["Col"].data])
    np.testing.assert_allclose(srgb[order] * 255, rgb[np.lexsort(xyz.T)], atol=0.51)


def test_no_point_cloud_by_default(models):
    bpy.ops.brdf.import_colmap(directory=str(models["bin"]))
    assert all(o.type == "CAMERA" for o in bpy.data.collections[ic.COLLECTION_NAME].objects)


def test_plain_function_for_the_batch_runner(models):
    cams = ic.import_cameras(bpy.context.scene, models["txt"])
    assert [o["brdf_image_name"] for o in cams] == sorted(v[0] for v in _views())
    assert all(o.name in bpy.context.scene.objects for o in cams)
    more = ic.import_cameras(bpy.context, models["bin"])
    assert len(more) == len(cams)


def test_distortion_is_flagged(tmp_path):
    view = ("w.jpg", "OPENCV", [700, 700, 250, 200, 0.05, 0, 0, 0], 500, 400)
    cm.synthetic_reconstruction(
        [(*view, *cm.look_at([3, 0, 0], [0, 0, 0]))], np.zeros((0, 3))
    ).write(str(tmp_path))
    assert bpy.ops.brdf.import_colmap(directory=str(tmp_path)) == {"FINISHED"}
    (cam,) = _imported_cameras()
    assert cam["brdf_colmap_distorted"] and cam["brdf_colmap_camera_model"] == "OPENCV"


class _FakeOperator(types.SimpleNamespace):
    def report(self, kind, message):
        self.reports.append((kind, message))


@pytest.mark.parametrize("directory", ["missing", ""])
def test_bad_folder_cancels_with_one_line(tmp_path, directory):
    path = str(tmp_path / directory) if directory else ""
    fake = _FakeOperator(directory=path, point_cloud=False, reports=[])
    assert OP.execute(fake, bpy.context) == {"CANCELLED"}
    ((kind, message),) = fake.reports
    assert kind == {"ERROR"} and "\n" not in message and message
    with pytest.raises(RuntimeError, match="COLMAP model") as err:
        bpy.ops.brdf.import_colmap(directory=path)
    assert len(str(err.value).strip().splitlines()) == 1
    assert len(bpy.data.objects) == 0 and len(bpy.data.collections) == 0


def test_folder_without_model_cancels(tmp_path):
    with pytest.raises(RuntimeError, match="No COLMAP model"):
        bpy.ops.brdf.import_colmap(directory=str(tmp_path))
    assert len(bpy.data.collections) == 0


def test_set_render_to_camera_needs_an_imported_camera():
    plain = bpy.data.objects.new("Plain", bpy.data.cameras.new("Plain"))
    with pytest.raises(ValueError, match="brdf_width"):
        ic.set_render_to_camera(bpy.context.scene, plain)


def test_operator_declares_undo_and_a_folder_browser():
    assert {"REGISTER", "UNDO"} <= OP.bl_options
    assert OP.bl_idname == "brdf.import_colmap"
    directory = bpy.ops.brdf.import_colmap.get_rna_type().properties["directory"]
    assert directory.subtype == "DIR_PATH"
    assert "invoke" in OP.__dict__  # opens the file browser (fileselect_add)
