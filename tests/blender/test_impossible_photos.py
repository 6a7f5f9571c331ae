"""Photos that cannot be right, through the add-on (pip bpy): each is refused before
any science with one sentence naming the photo, nothing is written to the output
folder and the photo's file is left as it was; a photo only partly at odds with
its light runs, with a note in report.json, in the panel's notes and on the batch
terminal (issue 13). On the tiny Cycles scene of testkit/blender_scene.py, and on
it with a ground plane joined to the scan, so the scan casts a shadow."""

import hashlib
import json
import math
import subprocess
import sys

import numpy as np
import OpenImageIO as oiio
import pytest

bpy = pytest.importorskip("bpy")

from image_files import write_image  # noqa: E402
from mathutils import Vector  # noqa: E402

from brdf_reconstruct.brdf_addon import gathering, runner  # noqa: E402
from brdf_reconstruct.core.capture import photo_io  # noqa: E402
from testkit import blender_scene as BS  # noqa: E402

# the cast-shadow scene's sun: from the right and above, so the ball's shadow falls
# on the ground plane in view of the camera
CAST_LIGHT = np.array([0.6, 0.3, 0.74]) / np.linalg.norm([0.6, 0.3, 0.74])


def _digest(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _entry(built, path):
    """A photo entry for ``path`` seen by the tiny scene's camera, lit by its Sun."""
    p = built["scene"].brdf.photos.add()
    p.name, p.filepath, p.camera = path.name, str(path), built["camera"]
    p.light_source, p.sun = "SUN_OBJECT", built["sun"]
    p.irradiance = (BS.lit_irradiance(),) * 3
    return p


def _aim(sun, direction):
    sun.rotation_mode = "QUATERNION"
    sun.rotation_quaternion = Vector((0, 0, 1)).rotation_difference(Vector(tuple(direction)))


def _photo_under(built, name, direction):
    """The scene rendered with its Sun towards ``direction``, the Sun then put back."""
    sun = built["sun"]
    kept = sun.rotation_quaternion.copy()
    _aim(sun, direction)
    path = built["dir"] / name
    BS.render_photo(built["scene"], path)
    sun.rotation_quaternion = kept
    bpy.context.view_layer.update()  # matrix_world, which the photo's light reads
    return path


def _refused(built, photos, match):
    """The run refused with one sentence matching ``match``; nothing was written to
    the output folder and no photo file changed."""
    before = {p: _digest(p) for p in photos}
    with pytest.raises(RuntimeError, match=match) as err:
        bpy.ops.brdf.reconstruct()
    lines = [ln for ln in str(err.value).splitlines() if ln.strip()]
    assert len(lines) == 1 and ". " not in lines[0], lines  # one sentence
    assert not (built["dir"] / "out").exists()
    assert len(built["scene"].brdf.results) == 0
    assert {p: _digest(p) for p in photos} == before


def _with_cast_shadows(built):
    """The tiny scene's ball shrunk onto a ground plane joined to the scan (one mesh,
    so the scan shadows itself), a camera looking down at both, the Sun at
    CAST_LIGHT."""
    scan = built["scan"]
    scan.scale, scan.location = (0.5, 0.5, 0.5), (0.0, 0.0, 0.55)
    bpy.ops.mesh.primitive_plane_add(size=3.0, location=(0.0, 0.0, 0.0))
    plane = bpy.context.active_object
    bpy.ops.object.select_all(action="DESELECT")
    plane.select_set(True)
    scan.select_set(True)
    bpy.context.view_layer.objects.active = scan
    bpy.ops.object.join()
    bpy.ops.object.transform_apply(location=True, rotation=True, scale=True)
    camera = built["camera"]
    camera.location = (0.3, -4.0, 2.6)
    camera.rotation_quaternion = (Vector((0.0, 0.0, 0.3)) - camera.location).to_track_quat(
        "-Z", "Y")
    _aim(built["sun"], CAST_LIGHT)
    bpy.context.view_layer.update()


# --- refused ---------------------------------------------------------------------

def test_an_all_black_photo_is_refused_before_any_work(tiny):
    path = write_image(tiny["dir"] / "black.exr", np.zeros((48, 48, 3), np.float32),
                       oiio.FLOAT)
    _entry(tiny, path)
    _refused(tiny, [path], r"^Error: Photo black\.exr is black \(no pixel above 0\): check "
                           "the file, its exposure and that it is the lit photo")


def test_a_photo_black_over_the_scan_is_refused(tiny):
    """Light in the photo's corner only, none where the camera sees the sphere: the
    photo is not of this camera (or was exposed for something else)."""
    photo = np.zeros((48, 48, 3), np.float32)
    photo[:4, :4] = 0.5
    path = write_image(tiny["dir"] / "corner.exr", photo, oiio.FLOAT)
    _entry(tiny, path)
    _refused(tiny, [path], r"Photo corner\.exr is black over the scan \(all \d+ of its pixels "
                           r"are 0\): check the photo's camera and its exposure")


def test_one_black_photo_among_three_is_refused_by_name(tiny):
    good = tiny["photo"]
    second = tiny["dir"] / "view0_copy.exr"
    second.write_bytes(good.read_bytes())
    black = write_image(tiny["dir"] / "dark.exr", np.zeros((48, 48, 3), np.float32),
                        oiio.FLOAT)
    for path in (good, black, second):
        _entry(tiny, path)
    _refused(tiny, [good, black, second], r"^Error: Photo dark\.exr is black")
    # the two good ones alone are gathered without a word about them
    tiny["scene"].brdf.photos.remove(1)
    _, capture = gathering.gather_capture(tiny["scene"])
    assert [p.get("notes") for p in capture["photos"]] == [None, None]


def test_pixels_of_1e30_are_refused_with_their_count(tiny):
    photo = photo_io.read_photo(tiny["photo"]).astype(np.float32)
    photo[20, 20:24] = 1e30  # four pixels on the sphere
    path = write_image(tiny["dir"] / "hot.exr", photo, oiio.FLOAT)
    _entry(tiny, path)
    _refused(tiny, [path], r"^Error: Photo hot\.exr has 4 pixels on the scan more than 2\^32 "
                           r"times its median value .* \(up to 1e\+30\), which no camera "
                           r"records: fix the file or mask them out")


def test_a_photo_lit_from_the_opposite_side_is_refused(tiny):
    """Rendered under the Sun turned round, given the Sun as it is: the photo's light
    falls where the G-buffer puts the sphere in shadow."""
    path = _photo_under(tiny, "opposite.exr", -BS.LIGHT)
    _entry(tiny, path)
    _refused(tiny, [path], r"^Error: Photo opposite\.exr is brighter where its G-buffer puts "
                           r"the scan in shadow than where it lights it \(\d+ of those \d+ "
                           r"shadowed pixels .*: check the photo's light \(direction, Sun "
                           r"object or sun position\) and its camera$")


# --- passed, or run with a note ---------------------------------------------------

def test_photos_under_their_own_light_pass_without_a_note(tiny):
    """No false alarm: the tiny sphere's photo, and a scan that casts a real shadow
    photographed under the light it is given."""
    _entry(tiny, tiny["photo"])
    _, capture = gathering.gather_capture(tiny["scene"])
    check = capture["photos"][0]["light_check"]
    assert "notes" not in capture["photos"][0] and gathering.capture_notes(capture) == [
        "no gray card or reference region: irradiance assumed equal across photos"]
    assert check["shadow_pixels"] >= 16 and check["shadow_to_lit"] < 0.01  # no sky: 0
    _with_cast_shadows(tiny)
    tiny["scene"].brdf.photos.clear()
    _entry(tiny, _photo_under(tiny, "cast.exr", CAST_LIGHT))
    inputs, capture = gathering.gather_capture(tiny["scene"])
    cast = (inputs[0].visibility < 0.5) & (inputs[0].normal @ CAST_LIGHT > 0.1)
    assert cast.sum() > 50  # the ball's shadow on the plane is in view
    check = capture["photos"][0]["light_check"]
    assert "notes" not in capture["photos"][0]
    assert check["shadow_pixels"] > 50 and check["shadow_to_lit"] < 0.01


def test_a_sun_on_the_wrong_side_runs_with_a_note_in_the_report(tiny):
    """The cast-shadow scene photographed with the sun mirrored to the other side of
    the ball, given the sun as it is: the ground is lit the same, but where the
    G-buffer puts the ball's shadow the photo is lit. A run, and a note that reaches
    report.json and the panel."""
    _with_cast_shadows(tiny)
    mirrored = np.array([-CAST_LIGHT[0], -CAST_LIGHT[1], CAST_LIGHT[2]])
    path = _photo_under(tiny, "mirrored.exr", mirrored)
    _entry(tiny, path)
    user_photo = _digest(path)
    runner.Run(tiny["scene"], threaded=False, bake=False).run()  # the bake is not the point
    report = json.loads((tiny["dir"] / "out" / "report.json").read_text())
    photo = report["capture"]["photos"][0]
    assert 0.5 < photo["light_check"]["shadow_to_lit"] <= 1.0
    assert len(photo["notes"]) == 1
    assert photo["notes"][0].startswith("the brightest of the ")
    assert "check its light and camera" in photo["notes"][0]
    shown = json.loads(tiny["scene"].brdf.capture_notes)
    assert f"mirrored.exr: {photo['notes'][0]}" in shown
    assert _digest(path) == user_photo


# --- the batch entry: one error line, or a note line ------------------------------

JOB = f"""
blend = "scene.blend"
object = "Scan"
out = "out_{{name}}"

[settings]
curvature_threshold = 1.5
samples = 12
trials = 2

[[photo]]
image = "{{name}}.exr"
camera = "{BS.IMAGE_NAME}"
light = "Sun"
irradiance = {math.pi}
"""


def _batch(folder, name):
    job = folder / f"{name}.toml"
    job.write_text(JOB.format(name=name))
    return subprocess.run([sys.executable, "-m", "brdf_reconstruct.brdf_addon.batch",
                           str(job)], capture_output=True, text=True, timeout=600)


def test_the_batch_prints_one_error_line_or_the_note(tiny):
    _with_cast_shadows(tiny)
    _photo_under(tiny, "mirrored.exr", np.array([-CAST_LIGHT[0], -CAST_LIGHT[1],
                                                 CAST_LIGHT[2]]))
    black = write_image(tiny["dir"] / "black.exr", np.zeros((48, 48, 3), np.float32),
                        oiio.FLOAT)
    bpy.ops.wm.save_as_mainfile(filepath=str(tiny["dir"] / "scene.blend"))
    digest = _digest(black)
    result = _batch(tiny["dir"], "black")
    assert result.returncode == 1, result.stderr
    errors = [ln for ln in result.stderr.splitlines() if ln.startswith("error:")]
    assert errors == ["error: Photo black.exr is black (no pixel above 0): check the file, "
                      "its exposure and that it is the lit photo"], result.stderr
    assert "Traceback" not in result.stderr
    assert not (tiny["dir"] / "out_black").exists()  # a refused job creates no folder
    assert _digest(black) == digest
    result = _batch(tiny["dir"], "mirrored")
    assert result.returncode == 0, result.stderr
    notes = [ln for ln in result.stdout.splitlines() if ln.startswith("note: mirrored.exr: ")]
    assert len(notes) == 1 and "G-buffer puts in shadow" in notes[0], result.stdout
    report = json.loads((tiny["dir"] / "out_mirrored" / "report.json").read_text())
    assert notes[0] == f"note: mirrored.exr: {report['capture']['photos'][0]['notes'][0]}"
