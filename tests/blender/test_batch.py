"""The batch entry's exit codes and outputs, run as a pipeline user runs it:
``python -m brdf_reconstruct.brdf_addon.batch job.toml`` in a fresh process."""

import hashlib
import json
import math
import subprocess
import sys

import pytest

bpy = pytest.importorskip("bpy")

from testkit import blender_scene as BS  # noqa: E402

GOOD = f"""
blend = "scene.blend"
object = "Scan"
out = "out"

[settings]
curvature_threshold = 1.5   # a 48-pixel photo (see test_workflow.py)
samples = 12
trials = 2
seed = 4

[[photo]]
image = "view0.exr"
camera = "{BS.IMAGE_NAME}"
light = "Sun"
irradiance = {math.pi}
"""


@pytest.fixture(scope="module")
def job_dir(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("batch")
    BS.build(tmp)
    (tmp / "other.exr").write_bytes((tmp / "view0.exr").read_bytes())  # matches no camera
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp / "scene.blend"))
    return tmp  # each test then starts in an empty file (empty_scene): never saved over


def _run(job_dir, text, name="job.toml"):
    (job_dir / name).write_text(text)
    return subprocess.run([sys.executable, "-m", "brdf_reconstruct.brdf_addon.batch",
                           str(job_dir / name)], capture_output=True, text=True, timeout=600)


def _digest(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def bpy_file_header(path) -> bool:
    """A complete .blend starts with Blender's header (zstd-compressed ones with
    the zstd magic)."""
    head = path.read_bytes()[:7]
    return head == b"BLENDER" or head[:4] == b"\x28\xb5\x2f\xfd"


def test_good_job_exits_0_with_outputs(job_dir):
    blend, photo = _digest(job_dir / "scene.blend"), _digest(job_dir / "view0.exr")
    result = _run(job_dir, GOOD)
    assert result.returncode == 0, result.stderr
    out = job_dir / "out"
    assert {"brdf_0.binary", "report.json", "scene.blend", "brdf_0_slice.png"} <= {
        p.name for p in out.iterdir()}
    # every output went through a temporary name (core.files) and none is left over
    assert [p.name for p in out.iterdir() if ".tmp" in p.name] == []
    assert bpy_file_header(out / "scene.blend")
    report = json.loads((out / "report.json").read_text())
    assert report["settings"]["trials"] == 2 and report["regions"][0]["status"] == "ok"
    # progress on the terminal: one "[ pp%] step" line per step, rising to 100 %
    steps = [ln for ln in result.stdout.splitlines() if ln.startswith("[") and "%]" in ln]
    assert any("G-buffers 1/" in ln for ln in steps) and steps[-1].endswith("done")
    percents = [int(ln[1:ln.index("%")]) for ln in steps]
    assert percents == sorted(percents) and percents[-1] == 100
    assert _digest(job_dir / "scene.blend") == blend  # the job's .blend is never written
    assert _digest(job_dir / "view0.exr") == photo


def test_same_seed_same_table(job_dir):
    a = _run(job_dir, GOOD.replace('out = "out"', 'out = "a"'), "a.toml")
    b = _run(job_dir, GOOD.replace('out = "out"', 'out = "b"'), "b.toml")
    assert a.returncode == b.returncode == 0
    assert _digest(job_dir / "a" / "brdf_0.binary") == _digest(job_dir / "b" / "brdf_0.binary")


@pytest.mark.parametrize("change, message", [
    (('image = "view0.exr"', 'image = "missing.exr"'), "photo 1 image not found"),
    ((f'camera = "{BS.IMAGE_NAME}"', 'camera = "nope.jpg"'), "unknown camera name nope.jpg"),
    (('light = "Sun"', 'light = {sun = {date = "2026-06-21 02:00:00", latitude = 48.1, '
                       'longitude = 11.6}}'), "below the horizon"),
    (("curvature_threshold = 1.5", "curvature_threshold = 0.0\nuse_brightest = false"),
     "No reliable pixels"),
    (('object = "Scan"', 'object = "Nothing"'), "no mesh object named Nothing"),
    (("seed = 4", "sede = 4"), "unknown settings: sede"),
    # a photo with no camera: none given, and its own name matches none
    ((f'image = "view0.exr"\ncamera = "{BS.IMAGE_NAME}"', 'image = "other.exr"'),
     "photo other.exr matches no camera by image name; give its camera"),
    # a camera with no photo
    (('image = "view0.exr"\n', ""), f"camera {BS.IMAGE_NAME} has no photo"),
    # the job's own folder as out: its scene.blend would be replaced
    (('out = "out"', 'out = "."'), "would replace the job's own scene.blend"),
    (('out = "out"', 'out = "out"\noverwrite = "yes"'), "overwrite must be true or false"),
    # out-of-range settings are refused, never clamped quietly
    (("samples = 12", "samples = -3"), "setting samples = -3: must be at least 1"),
    (("samples = 12", "samples = 0"), "setting samples = 0: must be at least 1"),
    (("trials = 2", "trials = 0"), "setting trials = 0: must be at least 1"),
    (("seed = 4", "seed = -1"), "setting seed = -1: must be at least 0"),
    (("seed = 4", "seed = 4\nsubset_fraction = 2.0"),
     "setting subset_fraction = 2.0: must be from 0.01 to 1"),
    (("seed = 4", "seed = 4\nphoto_consistent = -0.1"),
     "setting photo_consistent = -0.1: must be from 0 to 1"),
    (("curvature_threshold = 1.5", "curvature_threshold = nan"),
     "setting curvature_threshold = nan: must be finite"),
    (("samples = 12", 'samples = "twelve"'), "setting samples = 'twelve': must be a whole"),
    # an irradiance that cannot be right
    ((f"irradiance = {math.pi}", "irradiance = 0"), "irradiance must be positive and finite"),
    ((f"irradiance = {math.pi}", "irradiance = -1.0"), "irradiance must be positive and finite"),
    ((f"irradiance = {math.pi}", "irradiance = inf"), "irradiance must be positive and finite"),
    ((f"irradiance = {math.pi}", "irradiance = [1, 2]"),
     "irradiance must be one number or [r, g, b]"),
    # a light that cannot be a direction, said as such
    (('light = "Sun"', "light = [0.0, nan, 1.0]"), "must be finite and not all zero"),
    (('light = "Sun"', 'light = ["a", "b", "c"]'), "light must be three numbers [x, y, z]"),
    # a camera that is not a name (a traceback from bpy before), an empty one
    ((f'camera = "{BS.IMAGE_NAME}"', "camera = 3"),
     "photo 1: camera must be a camera's name or its image name, got 3"),
    ((f'camera = "{BS.IMAGE_NAME}"', 'camera = ""'),
     "photo 1: camera must be a camera's name or its image name, got ''"),
    # an exposure scale that cannot be right
    ((f"irradiance = {math.pi}", f"irradiance = {math.pi}\nexposure = inf"),
     "photo 1: exposure must be a positive finite number, got inf"),
])
def test_bad_job_exits_1_with_one_line(job_dir, change, message):
    result = _run(job_dir, GOOD.replace(*change), "bad.toml")
    assert result.returncode == 1, result.stderr
    errors = [ln for ln in result.stderr.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1 and message in errors[0], result.stderr


PLY_HEADER = (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
              b"property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
              b"end_header\n")


@pytest.mark.parametrize("name, data, message", [
    ("notes.blend", b"notes about the scene, not a scene\n",
     "blend notes.blend is not a Blender file"),
    ("empty.blend", b"", "blend empty.blend is empty (0 bytes)"),
    # Blender's header, then nothing Blender can read: open_mainfile's error, one line
    ("damaged.blend", b"BLENDER-v300" + b"junk" * 100,
     "blend damaged.blend could not be opened"),
    ("empty.ply", b"", "mesh empty.ply is empty (0 bytes)"),
    ("notes.ply", b"notes about the scan, not a scan\n",
     'mesh notes.ply is not a PLY file (it does not start with "ply")'),
    ("points.ply", PLY_HEADER.replace(b"face 1", b"face 0") + b"0 0 0\n1 0 0\n0 1 0\n",
     "mesh points.ply has no faces"),
    # a good header over rows that are not numbers: the importer's error, one line
    ("garbled.ply", PLY_HEADER + b"a b c\nd e f\n", "mesh garbled.ply could not be imported"),
])
def test_a_bad_blend_or_mesh_file_exits_1_with_one_line(job_dir, name, data, message):
    """Issue 13: these used to end in a traceback. The file is left as it was."""
    (job_dir / name).write_bytes(data)
    scene = f'blend = "{name}"\nobject = "Scan"' if name.endswith(".blend") else \
        f'mesh = "{name}"'
    result = _run(job_dir, GOOD.replace('blend = "scene.blend"\nobject = "Scan"', scene),
                  "bad_file.toml")
    assert result.returncode == 1, result.stderr
    errors = [ln for ln in result.stderr.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1 and message in errors[0], result.stderr
    assert "Traceback" not in result.stderr
    assert (job_dir / name).read_bytes() == data


def test_a_faceless_scan_object_exits_1_with_one_line(job_dir):
    """A mesh object without faces in the job's .blend: the run's own scene check
    (gathering.check_scene) refuses it before any work, one line."""
    bpy.ops.wm.open_mainfile(filepath=str(job_dir / "scene.blend"))
    mesh = bpy.data.meshes.new("points")
    mesh.from_pydata([(0, 0, 0), (1, 0, 0), (0, 1, 0)], [], [])
    bpy.context.scene.collection.objects.link(bpy.data.objects.new("Points", mesh))
    bpy.ops.wm.save_as_mainfile(filepath=str(job_dir / "points.blend"), copy=True)
    job = GOOD.replace('blend = "scene.blend"\nobject = "Scan"',
                       'blend = "points.blend"\nobject = "Points"')
    result = _run(job_dir, job.replace('out = "out"', 'out = "points_out"'), "points.toml")
    assert result.returncode == 1, result.stderr
    errors = [ln for ln in result.stderr.splitlines() if ln.startswith("error:")]
    # the operator's report starts with a capital, as Blender's reports do
    assert len(errors) == 1 and "The scan Points is a mesh without faces" in errors[0], \
        result.stderr
    assert "Traceback" not in result.stderr


def test_an_installed_but_disabled_extension_is_one_sentence():
    """batch.py run by Blender from an extension repository's folder while that
    extension is not enabled: one sentence saying how to enable it, instead of
    importing a second, unregistered copy (the enabled case runs in
    tests/test_extension.py)."""
    from pathlib import Path

    from brdf_reconstruct.brdf_addon import batch

    repo = next(r for r in bpy.context.preferences.extensions.repos
                if r.module == "user_default")
    name = f"bl_ext.user_default.{batch.PACKAGE_ID}"
    assert name not in bpy.context.preferences.addons  # not installed in this process
    with pytest.raises(ValueError) as error:
        batch._enabled_extension(Path(repo.directory).resolve() / batch.PACKAGE_ID)
    text = str(error.value)
    assert text.startswith(f"the extension {name} is installed but not enabled")
    assert f"--addons {name}" in text and "\n" not in text
    # a folder outside every repository (a checkout): no extension, no error
    assert batch._enabled_extension(Path(__file__).resolve().parents[2]) is None


def test_a_users_table_in_out_is_kept_unless_overwrite(job_dir):
    """A file of the run's names that no run wrote is never replaced silently: the
    run stops before any work with one line naming it; overwrite = true replaces
    it; a folder a run wrote is replaced without asking."""
    from brdf_reconstruct.core.brdf import merl

    out = job_dir / "users"
    out.mkdir()
    mine = out / "brdf_0.binary"
    mine.write_bytes(b"my own table")
    job = GOOD.replace('out = "out"', 'out = "users"')
    refused = _run(job_dir, job, "users.toml")
    assert refused.returncode == 1, refused.stderr
    errors = [ln for ln in refused.stderr.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1 and "brdf_0.binary" in errors[0] and "Overwrite" in errors[0]
    assert "Traceback" not in refused.stderr
    assert mine.read_bytes() == b"my own table"
    assert sorted(p.name for p in out.iterdir()) == ["brdf_0.binary"]

    asked = _run(job_dir, job.replace('out = "users"', 'out = "users"\noverwrite = true'),
                 "users_overwrite.toml")
    assert asked.returncode == 0, asked.stderr
    assert merl.read(mine).shape == (3, *merl.SHAPE)  # the run's table, whole

    again = _run(job_dir, job, "users_again.toml")  # the folder is now a run's
    assert again.returncode == 0, again.stderr


def test_camera_found_by_the_photo_name_when_left_out(job_dir):
    result = _run(job_dir, GOOD.replace(f'camera = "{BS.IMAGE_NAME}"\n', "")
                  .replace('out = "out"', 'out = "named"'), "named.toml")
    assert result.returncode == 0, result.stderr
    report = json.loads((job_dir / "named" / "report.json").read_text())
    assert report["capture"]["photos"][0]["name"] == "view0.exr"
    assert any(ln.startswith("note: ") and "assumed equal" in ln
               for ln in result.stdout.splitlines())


def test_an_irradiance_too_low_is_named_per_region_and_the_run_goes_on(job_dir, registered):
    """The scene's Lambert reflects 0.5 of its light (``BS.ALBEDO``); given a quarter
    of the true irradiance, the photo reads as a surface reflecting 2.0, which no
    table bounded at ``refine.ALBEDO_BOUND`` (1) can meet: the run still exits 0 with
    its outputs, and prints one note naming the region and the likely cause (once:
    not again as Blender's report), the sentence ``report.json`` and the saved
    scene's results keep. With the true irradiance (``GOOD``) no such note."""
    from brdf_reconstruct.core.method import refine

    assert 4 * BS.ALBEDO > refine.ALBEDO_BOUND > BS.ALBEDO
    job = GOOD.replace(f"irradiance = {math.pi}", f"irradiance = {math.pi / 4}") \
        .replace('out = "out"', 'out = "dim"')
    result = _run(job_dir, job, "dim.toml")
    assert result.returncode == 0, result.stderr
    report = json.loads((job_dir / "dim" / "report.json").read_text())
    region = report["regions"][0]
    refused = region["refinement"]["every_pixel"]["bound_refused"]
    assert "irradiance is likely too low" in refused and "\n" not in refused
    notes = [ln for ln in result.stdout.splitlines() if "likely too low" in ln]
    assert notes == [f"note: {region['label']}: {refused}"]
    assert region["label"] == "Known Lambert"  # the scan's material names the region
    # the panel's results list shows it too: the run's saved scene keeps it per region
    bpy.ops.wm.open_mainfile(filepath=str(job_dir / "dim" / "scene.blend"))
    assert json.loads(bpy.context.scene.brdf.results[0].notes) == [refused]

    good = _run(job_dir, GOOD.replace('out = "out"', 'out = "bright"'), "bright.toml")
    assert good.returncode == 0, good.stderr
    assert "likely too low" not in good.stdout


def test_an_unknown_flag_exits_2_with_the_usage():
    result = subprocess.run([sys.executable, "-m", "brdf_reconstruct.brdf_addon.batch",
                             "--frobnicate"], capture_output=True, text=True, timeout=120)
    assert result.returncode == 2 and "usage" in result.stderr


def test_ctrl_c_exits_130_with_one_line(monkeypatch, capsys):
    from brdf_reconstruct.brdf_addon import batch

    def interrupted(path):
        raise KeyboardInterrupt

    monkeypatch.setattr(batch, "run_job", interrupted)
    assert batch.main(["job.toml"]) == 130
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: interrupted")


# Ctrl+C delivered while Cycles frees its render engine: Python runs the SIGINT
# handler inside that destructor (engine.py's free), where an exception is printed and
# swallowed. The stand-in below calls the handler installed at that moment the same way.
_SWALLOWED_CTRL_C = """
import signal, sys
from brdf_reconstruct.brdf_addon import batch, photo_input

real = photo_input.gather_photo

class Engine:
    def __del__(self):
        signal.getsignal(signal.SIGINT)(signal.SIGINT, None)

def gather_photo(*args, **kwargs):
    Engine()  # freed at once
    return real(*args, **kwargs)

photo_input.gather_photo = gather_photo
sys.exit(batch.main([sys.argv[1]]))
"""


def test_a_ctrl_c_swallowed_in_a_destructor_still_interrupts_the_run(job_dir):
    """The interrupt is recorded, not only raised: the run stops at its next check,
    exits 130 with one line, and the output folder gets nothing. With Python's own
    handler this run went on to exit 0 (the bad-input sweep's ctrl-c-gbuffers case)."""
    out = job_dir / "swallowed"
    (job_dir / "swallowed.toml").write_text(GOOD.replace('out = "out"', 'out = "swallowed"'))
    result = subprocess.run([sys.executable, "-c", _SWALLOWED_CTRL_C,
                             str(job_dir / "swallowed.toml")],
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 130, result.stdout + result.stderr
    errors = [ln for ln in result.stderr.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1 and errors[0].startswith("error: interrupted")
    assert "Exception ignored" in result.stderr  # the stand-in did swallow it
    assert not out.exists() or not any(out.iterdir())
    assert "writing results" not in result.stdout


def test_wrong_command_line_exits_2():
    result = subprocess.run([sys.executable, "-m", "brdf_reconstruct.brdf_addon.batch"],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 2 and "usage" in result.stderr


def test_a_jobs_basis_folder_is_used_and_reported(job_dir):
    """basis = "<folder>": the run stands on the PCA basis of those MERL files
    (three Lambertian tables here, so the basis is built in seconds), and the report
    names it."""
    import numpy as np

    from brdf_reconstruct.core.brdf import basis, merl

    folder = job_dir / "my_merl"
    folder.mkdir(exist_ok=True)
    for i, albedo in enumerate(([0.2, 0.3, 0.4], [0.6, 0.5, 0.4], [0.9, 0.9, 0.8])):
        table = np.full((3, merl.N_CELLS), np.nan)
        table[:, merl.valid_cells()] = np.asarray(albedo)[:, None] / np.pi
        merl.write(folder / f"m{i}.binary", table.reshape(3, *merl.SHAPE))
    result = _run(job_dir, GOOD.replace('out = "out"', 'out = "basis_out"\nbasis = "my_merl"'),
                  "basis.toml")
    assert result.returncode == 0, result.stderr
    report = json.loads((job_dir / "basis_out" / "report.json").read_text())
    expected = basis.load_merl_folder(folder, cache_dir=job_dir / "cache_check")
    assert report["basis"]["kind"] == "folder" and report["basis"]["source"] == str(folder)
    assert report["basis"]["fingerprint"] == expected.fingerprint
    assert report["basis"]["n_columns"] == 9
