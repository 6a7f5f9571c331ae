"""The synthetic capture's geometry (testkit/capture.py): ground truth, the degraded
"photogrammetry" mesh, the camera ring and its COLMAP model through the real
import path."""

import sys
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from brdf_reconstruct.brdf_addon import colmap_import  # noqa: E402
from testkit import capture  # noqa: E402

BUNNY = capture.DATA / "stanford-bunny.obj"


@pytest.fixture(scope="module")
def bunny(shared_scene):
    """The bunny and its scan, loaded once into the module's shared scene (the tests
    that use it see each other's cameras); they skip without ../shared/data."""
    if not BUNNY.is_file():
        pytest.skip(f"{BUNNY} not found")
    truth = capture.load_ground_truth(BUNNY)
    scan = capture.photogrammetry_mesh(truth, seed=3)
    return truth, scan


def _co(obj):
    co = np.zeros(len(obj.data.vertices) * 3)
    obj.data.vertices.foreach_get("co", co)
    return co.reshape(-1, 3)


def test_ground_truth_is_unit_sized_at_the_origin(bunny):
    truth, _ = bunny
    co = _co(truth)
    assert len(truth.data.polygons) == 69451  # the whole bunny
    np.testing.assert_allclose(0.5 * (co.min(0) + co.max(0)), 0.0, atol=1e-6)
    assert np.max(np.linalg.norm(co, axis=1)) == pytest.approx(1.0, abs=1e-6)


def test_scan_is_decimated_blunted_and_seeded(bunny):
    truth, scan = bunny
    assert 0.15 < len(scan.data.polygons) / len(truth.data.polygons) < 0.25
    assert truth.data is not scan.data and len(truth.data.polygons) == 69451
    again = capture.photogrammetry_mesh(truth, seed=3, name="again")
    np.testing.assert_array_equal(_co(again), _co(scan))  # same seed, same scan
    other = capture.photogrammetry_mesh(truth, seed=4, name="other")
    assert not np.array_equal(_co(other), _co(scan))


def test_normal_error_is_like_a_photogrammetry_mesh(bunny, tmp_path):
    truth, scan = bunny
    poses = capture.camera_ring(3)
    folder = capture.write_colmap(tmp_path / "sparse", poses, 96, 72, 120.0, _co(truth)[::50])
    cameras = colmap_import.import_cameras(bpy.context.scene, folder)
    angles = np.degrees(capture.normal_angle_error(truth, scan, cameras[0], (96, 72)))
    # blunted, not destroyed: most normals within a few degrees, some far off
    median, p90 = np.median(angles), np.percentile(angles, 90)
    print(f"normal-angle error: median {median:.1f} deg, 90th percentile {p90:.1f} deg")
    assert 1.0 < median < 15.0 and p90 > median


def test_colmap_model_of_the_ring_imports_with_its_poses(bunny, tmp_path):
    truth, _ = bunny
    poses = capture.camera_ring(7)
    folder = capture.write_colmap(tmp_path / "sparse", poses, 64, 48, 80.0, _co(truth)[::100])
    cameras = colmap_import.import_cameras(bpy.context.scene, folder)
    assert [c["brdf_image_name"] for c in cameras] == [f"view{i:03d}.png" for i in range(7)]
    for cam, (R, t) in zip(cameras, poses, strict=True):
        np.testing.assert_allclose(np.array(cam.matrix_world.translation), -R.T @ t, atol=1e-5)
        forward = -np.array(cam.matrix_world.to_3x3().col[2])
        np.testing.assert_allclose(forward, R[2], atol=1e-6)  # looks at the origin


def test_fallback_ground_truth_without_the_data(monkeypatch):
    """Without ../shared/data the capture falls back to a subdivided Suzanne: unit
    radius at the origin, smooth, many faces (CI may run without the data)."""
    monkeypatch.setattr(capture, "DATA", Path("/nonexistent"))
    truth = capture.default_ground_truth()
    co = _co(truth)
    assert len(truth.data.polygons) > 5000 and all(p.use_smooth for p in truth.data.polygons)
    np.testing.assert_allclose(0.5 * (co.min(0) + co.max(0)), 0.0, atol=1e-6)
    assert np.max(np.linalg.norm(co, axis=1)) == pytest.approx(1.0, abs=1e-6)


@pytest.mark.parametrize("basis", ["measured", "analytic"])
def test_capture_then_batch_end_to_end(tmp_path, basis):
    """A small synthetic capture (the bunny, or Suzanne where ../shared/data is
    missing; 6 cameras, 3 photos under one light) through the batch entry, as a user
    runs it: the reconstruction is nearer the true material than any other held-out
    one. CI's end-to-end test, with each shipped basis on the materials it is for:
    the default measured basis on a measured metal (two-layer-gold, the metal of
    ``measured.one_per_class``) through a pack without its cross-validation fold
    (``$BRDF_MEASURED_PACK``, so the basis never saw it), against the 12 analytic
    held-out materials and the other classes' drawn materials; the analytic basis
    on the held-out analytic gold against the other 11."""
    import json
    import os
    import subprocess

    from brdf_reconstruct.core.brdf import database, merl, metrics, nbrdf, render
    from testkit import measured

    tables = {s["name"]: database.make_table(s) for s in database.heldout_specs()}
    env = dict(os.environ)
    if basis == "measured":
        pack = nbrdf.load(measured.PACK)
        drawn = measured.one_per_class(pack.names)
        tables.update({n: nbrdf.tabulate(pack, pack.index(n)) for n in drawn})
        true_name = drawn[0]
        env["BRDF_MEASURED_PACK"] = str(measured.pack_without(
            true_name, Path(os.environ["BRDF_RECONSTRUCT_CACHE"]) / "packs"))
    else:
        true_name = "heldout_gold_medium"
    if BUNNY.is_file():
        job = capture.generate(tmp_path, tables[true_name], n_views=6, lit_views=(0, 2, 4),
                               resolution=(160, 120))
    else:  # Suzanne is smaller in the frame: at 160 x 120 with 3 photos its highlights
        # are too few to tell the gold from others (measured), so more pixels and photos
        job = capture.generate(tmp_path, tables[true_name], n_views=8,
                               lit_views=(0, 2, 4, 6), resolution=(240, 180))
    if basis == "analytic":
        job.write_text(job.read_text().replace("[settings]", 'basis = "analytic"\n\n[settings]'))
    result = subprocess.run([sys.executable, "-m", "brdf_reconstruct.brdf_addon.batch",
                             str(job)], capture_output=True, text=True, timeout=600, env=env)
    assert result.returncode == 0, result.stderr
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["regions"][0]["status"] == "ok"
    if basis == "measured":
        assert report["basis"]["source"] == env["BRDF_MEASURED_PACK"]
    table = merl.read(tmp_path / "out" / "brdf_0.binary")
    assert np.all(np.isfinite(table))
    sphere = render.render_sphere(table, render.REFERENCE_LIGHT)
    errors = {name: metrics.relative_rmse(sphere, render.render_sphere(t, render.REFERENCE_LIGHT))
              for name, t in tables.items()}
    print("sphere error against each held-out material:",
          {k: round(v, 3) for k, v in sorted(errors.items(), key=lambda kv: kv[1])[:3]})
    assert min(errors, key=errors.get) == true_name


SCAN_KEEP = 0.7


def _suzanne_with_uvs(path):
    """Blender's Suzanne (with its own UV map), subdivided twice, as an .obj: the
    textured capture's second ground truth (it needs no ../shared/data)."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    bpy.ops.mesh.primitive_monkey_add(calc_uvs=True)
    obj = bpy.context.active_object
    obj.modifiers.new("subdivide", "SUBSURF").levels = 2
    bpy.ops.wm.obj_export(filepath=str(path), export_selected_objects=True, export_uv=True,
                          export_normals=True, export_materials=False, apply_modifiers=True)
    return path


@pytest.mark.parametrize("subject", ["spot", "suzanne"])
def test_a_textured_capture_through_the_batch_entry(tmp_path, subject):
    """Issue 16's textured synthetic capture as files: Spot (it ships with UVs) and
    Blender's Suzanne (its own UVs; runs without ../shared/data) under a
    64 x 64 patch texture of 10:1 or more that multiplies a Lambert's whole table,
    photos rendered by Cycles, the degraded scan exported with its UV map; the batch
    entry on it with texture on writes an albedo whose pattern follows the truth's
    over the texels a photo saw."""
    import json
    import os
    import subprocess

    from brdf_reconstruct.core.brdf import database
    from brdf_reconstruct.core.capture import photo_io
    from testkit import measured, synthetic

    if subject == "spot":
        mesh = measured.DATA / "spot.obj"
        if not mesh.is_file():
            pytest.skip(f"{mesh} not found")
    else:
        mesh = _suzanne_with_uvs(tmp_path / "suzanne.obj")
    truth_texture = synthetic.patch_texture((64, 64), patch=8, seed=0).reshape(64, 64, 3)
    assert truth_texture.max() / truth_texture.min() >= 10.0
    lambert = next(s for s in database.heldout_specs() if s["name"] == "heldout_lambert_grey")
    # a milder scan than the default's (20 % of the faces, 8 smoothing passes), whose
    # normals leave the texture's pattern nearly unmeasurable (texture_bench: albedo
    # error 0.35 on the degraded Spot, its floor)
    job = capture.generate(tmp_path, database.make_table(lambert), mesh=mesh,
                           resolution=(240, 180), texture=truth_texture,
                           scan_options=dict(decimate_ratio=SCAN_KEEP, smooth_iterations=1,
                                             noise=0.0005))
    assert "texture = true" in job.read_text()
    result = subprocess.run([sys.executable, "-m", "brdf_reconstruct.brdf_addon.batch",
                             str(job)], capture_output=True, text=True, timeout=600,
                            env=dict(os.environ))
    assert result.returncode == 0, result.stderr
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    region = report["regions"][0]
    assert region["status"] == "ok" and not region["texture"]["constant"]
    colour = photo_io.read_photo_file(tmp_path / "out" / region["texture"]["albedo"]).radiance
    coverage = photo_io.read_photo_file(tmp_path / "out" / region["texture"]["coverage"])
    measured_texels = coverage.radiance[..., 0] > 0.99
    assert measured_texels.sum() >= 200
    est = np.log(colour.mean(axis=2)[measured_texels])
    true = np.log(truth_texture.mean(axis=2)[measured_texels])
    r = np.corrcoef(est, true)[0, 1]
    ratio = np.exp(est - est.mean()) / np.exp(true - true.mean())
    print(f"albedo pattern: correlation {r:.3f}, median relative error "
          f"{np.median(np.abs(ratio - 1)):.3f} over {measured_texels.sum()} texels")
    # measured 2026-12-04: correlation 0.80 over 1289 texels on Spot (0.13 on the default
    # scan), 0.75 over 1367 on Suzanne
    assert r > 0.6, r
