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
])
def test_bad_job_exits_1_with_one_line(job_dir, change, message):
    result = _run(job_dir, GOOD.replace(*change), "bad.toml")
    assert result.returncode == 1, result.stderr
    errors = [ln for ln in result.stderr.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1 and message in errors[0], result.stderr


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


def test_wrong_command_line_exits_2():
    result = subprocess.run([sys.executable, "-m", "brdf_reconstruct.brdf_addon.batch"],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 2 and "usage" in result.stderr
