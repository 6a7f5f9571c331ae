"""Job-file parsing: paths relative to the job, every light form, clear errors."""

import pytest

from brdf_reconstruct.brdf_addon import job as job_file


@pytest.fixture
def folder(tmp_path):
    for name in ("scan.ply", "lit/0012.exr", "lit/probe.exr", "sparse/0/cameras.bin"):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_bytes(b"")
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
image = "lit/0012.exr"
camera = "cam"
[photo.probe]
image = "lit/probe.exr"
""")
    assert job.photos[0]["light"] == {"sun": {"date": "2026-06-21 12:00:00",
                                              "latitude": 35.0, "longitude": 139.0}}
    assert job.photos[1]["light"]["probe"]["image"] == folder / "lit/probe.exr"


@pytest.mark.parametrize("text, message", [
    ('object = "S"\n[[photo]]\nimage = "lit/none.exr"\ncamera = "c"', "photo 1 image not found"),
    ('object = "S"', r"no \[\[photo\]\] entries"),
    ('[[photo]]\nimage = "lit/0012.exr"\ncamera = "c"', "needs a mesh file or an object"),
    ('mesh = "scan.ply"\nobject = "S"', "either mesh or object"),
    ('object = "S"\nfoo = 1', "unknown keys: foo"),
    ('object = "S"\n[settings]\nsampels = 3', "unknown settings: sampels"),
    ('object = "S"\n[[photo]]\nimage = "lit/0012.exr"', "needs image and camera"),
    ('object = [', "not valid TOML"),
])
def test_mistakes_are_one_sentence(folder, text, message):
    with pytest.raises(job_file.JobError, match=message):
        _load(folder, text)


def test_missing_job_file(tmp_path):
    with pytest.raises(job_file.JobError, match="job file not found"):
        job_file.load(tmp_path / "nope.toml")
