"""Job-file parsing: paths relative to the job, every light form, clear errors."""

import pytest

from brdf_reconstruct.brdf_addon import job as job_file

# the smallest scan load() accepts: one triangle (its header is checked, issue 13)
TRIANGLE_PLY = (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                b"property float y\nproperty float z\nelement face 1\n"
                b"property list uchar int vertex_indices\nend_header\n"
                b"0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")


@pytest.fixture
def folder(tmp_path):
    for name in ("scan.ply", "lit/0012.exr", "lit/0013.exr", "lit/probe.exr",
                 "sparse/0/cameras.bin"):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_bytes(TRIANGLE_PLY if name == "scan.ply" else b"")
    return tmp_path


def _load(folder, text):
    (folder / "job.toml").write_text(text)
    return job_file.load(folder / "job.toml")


def test_architecture_example_parses(folder):
    job = _load(folder, """
mesh = "scan.ply"
colmap = "sparse/0"
out = "out"
[settings]
curvature_threshold = 0.2
samples = 6
trials = 16
seed = 0
[[photo]]
image = "lit/0012.exr"
camera = "0012.jpg"
light = [0.21, -0.54, 0.81]
irradiance = 3.0
""")
    assert job.mesh == folder / "scan.ply" and job.colmap == folder / "sparse/0"
    assert job.out == folder / "out"
    assert job.settings == {"curvature_threshold": 0.2, "samples": 6, "trials": 16, "seed": 0}
    assert job.photos[0]["image"] == folder / "lit/0012.exr"
    assert job.photos[0]["light"] == [0.21, -0.54, 0.81]


def test_sun_and_probe_tables_become_the_light(folder):
    job = _load(folder, """
object = "Scan"
[[photo]]
image = "lit/0012.exr"
camera = "cam"
[photo.sun]
date = "2026-06-21 12:00:00"
latitude = 35.0
longitude = 139.0
[[photo]]
image = "lit/0013.exr"
camera = "cam"
[photo.probe]
image = "lit/probe.exr"
""")
    assert job.photos[0]["light"] == {"sun": {"date": "2026-06-21 12:00:00",
                                              "latitude": 35.0, "longitude": 139.0}}
    assert job.photos[1]["light"]["probe"]["image"] == folder / "lit/probe.exr"


def test_real_capture_keys(folder):
    """A photo without a camera (matched later by image name), EXIF-driven sun, a
    user-drawn probe circle, colour space, exposure, grey card and the scene's up."""
    job = _load(folder, """
mesh = "scan.ply"
mesh_up = "y"
up = "cameras"
[[photo]]
image = "lit/0012.exr"
color_space = "sRGB"
exposure = 0.5
grey_card = "lit/probe.exr"
[photo.sun]
utc_offset = 2.0
[[photo]]
image = "lit/0013.exr"
camera = "cam"
[photo.probe]
image = "lit/probe.exr"
center = [120.5, 80.0]
radius = 33.0
""")
    assert job.mesh_up == "Y" and job.up == "cameras"
    first, second = job.photos
    assert "camera" not in first and first["color_space"] == "SRGB"
    assert first["exposure"] == 0.5 and first["grey_card"] == folder / "lit/probe.exr"
    assert first["light"] == {"sun": {"utc_offset": 2.0}}
    assert second["light"]["probe"]["center"] == [120.5, 80.0]


@pytest.mark.parametrize("text, message", [
    ('object = "S"\n[[photo]]\nimage = "lit/none.exr"\ncamera = "c"', "photo 1 image not found"),
    ('object = "S"', r"no \[\[photo\]\] entries"),
    ('[[photo]]\nimage = "lit/0012.exr"\ncamera = "c"', "needs a mesh file or an object"),
    ('mesh = "scan.ply"\nobject = "S"', "either mesh or object"),
    ('object = "S"\nfoo = 1', "unknown keys: foo"),
    ('object = "S"\n[settings]\nsampels = 3', "unknown settings: sampels"),
    ('object = "S"\n[[photo]]\ncamera = "0013.jpg"', "camera 0013.jpg has no photo"),
    ('object = "S"\n[[photo]]\nlight = [0, 0, 1]', "photo 1 needs an image"),
    ('object = "S"\nmesh_up = "X"', "mesh_up must be"),
    ('object = "S"\nup = "sky"', "up must be"),
    ('object = "S"\n[[photo]]\nimage = "lit/0012.exr"\ncolor_space = "rec709"',
     "color_space must be"),
    ('object = "S"\n[[photo]]\nimage = "lit/0012.exr"\nexposure = -1', "exposure must be"),
    # one photo listed twice (here once through another spelling of its path): it would
    # count twice, and the judge's held-out test would predict it from itself
    ('object = "S"\n[[photo]]\nimage = "lit/0012.exr"\n[[photo]]\nimage = "lit/../lit/0012.exr"',
     r"photo 2 is photo 1 again \(0012.exr\): list each photo once"),
    ('object = "S"\n[[photo]]\nimage = "lit/0012.exr"\n[photo.sun]\ndate = "x"\ntime = 1',
     r"\[photo.sun\] has unknown keys: time"),
    ('object = "S"\n[[photo]]\nimage = "lit/0012.exr"\ngrey_card = "lit/0012.exr"\n'
     'reference_region = "lit/0012.exr"', "both grey_card and reference_region"),
    ('object = "S"\n[[photo]]\nimage = "lit/0012.exr"\n[photo.sun]\nlatitude = 48.1',
     "needs both latitude and longitude"),
    ('object = "S"\n[[photo]]\nimage = "lit/0012.exr"\n[photo.probe]\n'
     'image = "lit/probe.exr"\ncenter = [10, 20]', "needs both center and radius"),
    ('object = "S"\n[[photo]]\nimage = "lit/0012.exr"\n[photo.probe]\n'
     'image = "lit/probe.exr"\ncenter = [10]\nradius = 5', "probe center must be"),
    ('object = [', "not valid TOML"),
    # issue 13: what used to be a traceback or an unclear message
    ('object = "S"\nsettings = 3\n[[photo]]\nimage = "lit/0012.exr"',
     r"\[settings\] must be a table"),
    ('object = "S"\nphoto = ["lit/0012.exr"]', r"photos must be \[\[photo\]\] tables"),
    ('object = "S"\nout = "scan.ply"\n[[photo]]\nimage = "lit/0012.exr"',
     "is a file or lies below the file"),
    ('object = "S"\nout = "scan.ply/out"\n[[photo]]\nimage = "lit/0012.exr"',
     "lies below the file"),
    ('object = "S"\n[[photo]]\nimage = "lit/0012.exr"\nirradiance = 0',
     "irradiance must be positive and finite"),
    ('object = "S"\n[[photo]]\nimage = "lit/0012.exr"\nirradiance = nan',
     "irradiance must be positive and finite"),
    ('object = "S"\n[[photo]]\nimage = "lit/0012.exr"\nirradiance = [1, 2]',
     r"irradiance must be one number or \[r, g, b\]"),
])
def test_mistakes_are_one_sentence(folder, text, message):
    with pytest.raises(job_file.JobError, match=message):
        _load(folder, text)


def test_a_byte_order_mark_is_not_an_error(folder):
    text = 'object = "S"\n[[photo]]\nimage = "lit/0012.exr"\n'
    (folder / "job.toml").write_bytes(b"\xef\xbb\xbf" + text.encode())
    assert job_file.load(folder / "job.toml").object == "S"


def test_missing_job_file(tmp_path):
    with pytest.raises(job_file.JobError, match="job file not found"):
        job_file.load(tmp_path / "nope.toml")


PHOTO = '\n[[photo]]\nimage = "lit/0012.exr"\ncamera = "c"\nlight = [0, 0, 1]\n'


@pytest.mark.parametrize("name, data, key, message", [
    ("notes.blend", b"my notes about the scene\n", "blend",
     "blend notes.blend is not a Blender file"),
    ("empty.blend", b"", "blend", "blend empty.blend is empty (0 bytes)"),
    ("empty.ply", b"", "mesh", "mesh empty.ply is empty (0 bytes)"),
    ("notes.ply", b"my notes about the scan\n", "mesh",
     'mesh notes.ply is not a PLY file (it does not start with "ply")'),
    ("points.ply", TRIANGLE_PLY.replace(b"element face 1", b"element face 0"), "mesh",
     "mesh points.ply has no faces"),
    ("points.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\n", "mesh", "mesh points.obj has no faces"),
    ("empty.stl", b"", "mesh", "mesh empty.stl is empty (0 bytes)"),
    ("notes.stl", b"my notes about the scan\n", "mesh", "mesh notes.stl is not an STL file"),
])
def test_a_bad_blend_or_mesh_file_is_one_sentence(folder, name, data, key, message):
    """Checked in load(), before any work: Blender would stop with a traceback or
    import nothing (issue 13). The file is left as it was."""
    (folder / name).write_bytes(data)
    target = 'object = "S"' if key == "blend" else ""
    with pytest.raises(job_file.JobError) as error:
        _load(folder, f'{key} = "{name}"\n{target}\n{PHOTO}')
    assert message in str(error.value) and "\n" not in str(error.value), str(error.value)
    assert (folder / name).read_bytes() == data


def test_files_blender_writes_pass_the_checks(folder):
    """The independent side of the header checks: every mesh format as Blender's own
    exporters write it (binary and ASCII PLY and STL, OBJ) and .blend files saved
    plain and compressed load without a word."""
    bpy = pytest.importorskip("bpy")
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=1)
    files = {"bin.ply": (bpy.ops.wm.ply_export, {"ascii_format": False}),
             "text.ply": (bpy.ops.wm.ply_export, {"ascii_format": True}),
             "bin.stl": (bpy.ops.wm.stl_export, {"ascii_format": False}),
             "text.stl": (bpy.ops.wm.stl_export, {"ascii_format": True}),
             "mesh.obj": (bpy.ops.wm.obj_export, {})}
    for name, (export, options) in files.items():
        export(filepath=str(folder / name), export_selected_objects=True, **options)
        job = _load(folder, f'mesh = "{name}"\n{PHOTO}')
        assert job.mesh == folder / name
    for name, compress in (("plain.blend", False), ("packed.blend", True)):
        bpy.ops.wm.save_as_mainfile(filepath=str(folder / name), copy=True, compress=compress)
        job = _load(folder, f'blend = "{name}"\nobject = "S"\n{PHOTO}')
        assert job.blend == folder / name
    heads = {(folder / n).read_bytes()[:4] for n in ("plain.blend", "packed.blend")}
    assert heads == {b"BLEN", b"\x28\xb5\x2f\xfd"}  # both kinds were really written
