"""The bad-input sweep of the batch entry (issue 13): wrong job files, paths, photos,
lights, cameras, output folders, settings, command lines and Ctrl+C, each run as a
user runs it, ``python -m brdf_reconstruct.brdf_addon.batch job.toml`` in a fresh
process, and judged on whether it was handled cleanly.

    .venv/bin/python bench/bad_inputs.py            # every case, 2 at a time
    .venv/bin/python bench/bad_inputs.py --quick    # a few cases of every class
    .venv/bin/python bench/bad_inputs.py --list     # the cases, without running them

The shared inputs are built once (``testkit.blender_scene``'s tiny scene: a sphere scan,
camera ``view0`` with COLMAP image name ``view0.jpg``, Sun ``Sun``, a 48 x 48 linear EXR
photo of it, and the files derived from them, see :func:`build_inputs`), then copied
into a folder of each case's own, so no case can disturb another.

A case is **handled cleanly** when all of these hold (:func:`judge`):

- the exit status is the expected one: 1 for a bad job, 2 for a bad command line, 130
  for Ctrl+C, 0 for a case that should run (some with a ``note:`` line naming the file);
  a few cases accept either 1 or 0 with a note, where refusing and warning are both
  right (the table's "expected" column says which);
- exit 1 or 130: exactly one stderr line starting with ``error:``, naming the field or
  file (one of the case's names, matched as a whole word, case-insensitive); exit 2:
  a usage line;
- no ``Traceback`` anywhere in stdout or stderr;
- every input file (the job file included) keeps its sha256, and nothing new appears
  outside the output folder;
- nothing half-written: no file with ``.tmp`` in its name anywhere in the case folder,
  no new or changed file of 0 bytes; for a refused or interrupted run, the output
  folder holds exactly the files it held before, unchanged;
- exit 0: ``out/brdf_0.binary`` reads with ``core.brdf.merl.read`` and is finite (no
  Inf; NaN, the format's mark of an unmeasured cell, only in cells whose light or view
  is below the horizon, ``merl.valid_cells``), and ``report.json`` parses; files in the
  output folder that a run does not own (``core.files.OUTPUT_NAMES``) stay unchanged.

Writes ``bench/results/bad_inputs.json`` (``--out``; ``bad_inputs_quick.json`` for
``--quick``) through ``common.write_json``: per case its class, what it feeds, the
expected and actual outcome, the error line, every problem found and its wall seconds;
the machine; the invocation; and prints the table and ``N/N handled cleanly``. Exits 1
unless every case run was handled cleanly.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import dataclasses
import hashlib
import json
import math
import os
import pathlib
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable

import common
import numpy as np

# the classes of bad input, in the order the table shows them
GROUPS = ("job file", "paths", "photos", "light", "camera", "output folder", "settings",
          "command line", "interruption")
BATCH = ("-m", "brdf_reconstruct.brdf_addon.batch")
TIMEOUT_S = 300.0  # a case still running after this is killed and counted as a hang
# BLAS/OpenMP threads per case: two cases run at once on a 2-core machine
CHILD_THREADS = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}

# --------------------------------------------------------------------------- the job file

DROP = object()
"""A value in a job change that removes the key."""

# the good job, as tests/blender/test_batch.py runs it on the tiny scene: the
# curvature threshold suits a 48-pixel photo (testkit.blender_scene.settings_for_tiny_runs)
GOOD_TOP = {"blend": "scene.blend", "object": "Scan", "out": "out"}
GOOD_SETTINGS = {"curvature_threshold": 1.5, "samples": 12, "trials": 2, "seed": 4}
GOOD_PHOTO = {"image": "view0.exr", "camera": "view0.jpg", "light": "Sun",
              "irradiance": math.pi}
# a sun position under the horizon: 02:00 UTC on 21 June in Munich
NIGHT = {"date": "2026-06-21 02:00:00", "latitude": 48.1, "longitude": 11.6}


def toml_value(value) -> str:
    """``value`` (bool, int, float incl. NaN/Inf, str, list, dict) as a TOML value."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)  # a JSON string is a TOML basic string
    if isinstance(value, list | tuple):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {toml_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(f"no TOML form for {value!r}")


def render_job(doc: dict) -> str:
    """A job document as TOML text: plain keys first, then tables, then arrays of tables
    (``[[photo]]``). A key whose value is not a table (``settings = 3``) stays a plain
    key, as a user would have written it."""
    plain, tables, arrays = [], [], []
    for key, value in doc.items():
        if isinstance(value, dict):
            tables.append((key, value))
        elif isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            arrays.append((key, value))
        else:
            plain.append(f"{key} = {toml_value(value)}")
    lines = plain
    for key, table in tables:
        lines += ["", f"[{key}]", *(f"{k} = {toml_value(v)}" for k, v in table.items())]
    for key, entries in arrays:
        for entry in entries:
            lines += ["", f"[[{key}]]", *(f"{k} = {toml_value(v)}" for k, v in entry.items())]
    return "\n".join(lines) + "\n"


def _merge(base: dict, changes: dict | None) -> dict:
    out = dict(base)
    for key, value in (changes or {}).items():
        if value is DROP:
            out.pop(key, None)
        else:
            out[key] = value
    return out


def job_text(top: dict | None = None, settings: dict | None = None,
             photo: dict | None = None, photos: list | None = None) -> str:
    """The good job with changes: ``top`` replaces or drops (:data:`DROP`) top-level keys
    (``settings`` and ``photo`` included), ``settings`` and ``photo`` merge into the
    ``[settings]`` table and the first ``[[photo]]``, ``photos`` lists every photo
    (each merged into the good photo)."""
    doc = {**GOOD_TOP, "settings": dict(GOOD_SETTINGS), "photo": [dict(GOOD_PHOTO)]}
    if photos is not None:
        doc["photo"] = [_merge(GOOD_PHOTO, p) for p in photos]
    doc = _merge(doc, top)
    if settings is not None:
        doc["settings"] = _merge(doc["settings"], settings)
    if photo is not None:
        doc["photo"][0] = _merge(doc["photo"][0], photo)
    return render_job(doc)


# --------------------------------------------------------------------------- cases


@dataclasses.dataclass(frozen=True)
class Case:
    """One bad input and what handling it cleanly means.

    name: short identifier (unique); group: its class (one of :data:`GROUPS`);
    what: the input in words; expect: the exit statuses accepted (0 only when
    ``names`` also finds a ``note:`` line, or when ``names`` is empty);
    names: the field or file names one of which the error line (exit 1 or 130) or a
    note line (exit 0) must hold; job: the job file's text (str, written as UTF-8),
    its bytes, or None for no job file; setup: makes the case's own files in its
    folder; argv: the batch entry's arguments given the case folder (default: the job
    file); interrupt: send SIGINT after the first stdout line holding this text;
    out: the job's output folder, relative to the case folder; quick: in ``--quick``;
    needs_non_root: skipped when running as root (permissions do not bind root).
    """

    name: str
    group: str
    what: str
    expect: tuple[int, ...] = (1,)
    names: tuple[str, ...] = ()
    job: str | bytes | None = dataclasses.field(default_factory=job_text)
    setup: Callable[[pathlib.Path], None] | None = None
    argv: Callable[[pathlib.Path], list[str]] | None = None
    interrupt: str | None = None
    out: str = "out"
    quick: bool = False
    needs_non_root: bool = False

    def expected_text(self) -> str:
        """The expectation in a few words, for the table."""
        named = f" naming {' / '.join(self.names)}" if self.names else ""
        parts = []
        for status in self.expect:
            if status == 0:
                parts.append("0 + note" + named if self.names else "0 (runs)")
            elif status == 2:
                parts.append("2 + usage")
            else:
                parts.append(f"{status} + error{named}")
        return " or ".join(parts)


def bad(name: str, group: str, what: str, names, quick: bool = False, **changes) -> Case:
    """A job refused with exit 1 and an error naming one of ``names``; ``changes`` go to
    :func:`job_text` (``setup`` to the case)."""
    setup = changes.pop("setup", None)
    out = changes.pop("out", "out")
    return Case(name, group, what, (1,), tuple([names] if isinstance(names, str) else names),
                job_text(**changes), setup=setup, out=out, quick=quick)


def _write(relative: str, data: bytes | str = b""):
    """A setup writing ``data`` (bytes or text) to ``relative`` in the case folder."""
    def setup(folder: pathlib.Path) -> None:
        path = folder / relative
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data.encode() if isinstance(data, str) else data)
    return setup


def _folder(relative: str):
    """A setup making the folder ``relative`` in the case folder."""
    def setup(folder: pathlib.Path) -> None:
        (folder / relative).mkdir(parents=True)
    return setup


def _previous_run(folder: pathlib.Path) -> None:
    """An output folder as an earlier run left it: the marker, a table and a report
    (small stand-ins; a run may replace them, an interrupted or refused one may not)."""
    out = folder / "out"
    out.mkdir()
    (out / ".brdf_reconstruct_output").write_text("written by BRDF Reconstruct\n")
    (out / "brdf_0.binary").write_bytes(b"an earlier run's table")
    (out / "report.json").write_text('{"earlier": true}\n')


def _locked_out(folder: pathlib.Path) -> None:
    (folder / "locked").mkdir()
    (folder / "locked").chmod(0o500)


def _three_photos(**photo) -> list[dict]:
    return [dict(photo, image=name) for name in ("view0.exr", "view0_b.exr", "view0_c.exr")]


def _job_arg(folder: pathlib.Path) -> list[str]:
    return [str(folder / "job.toml")]


TEXT = "this is a text file, not what its name says\n"


def cases() -> list[Case]:
    """Every case of the sweep, by class."""
    jf, pa, ph, li, ca, of, se, cl, it = GROUPS
    good = job_text()
    c = [
        # ------------------------------------------------------------- job file
        Case("job-missing", jf, "the job file does not exist", (1,), ("nojob.toml",),
             None, argv=lambda f: [str(f / "nojob.toml")], quick=True),
        Case("job-is-folder", jf, "the job file is a folder", (1,), ("job.toml",), None,
             setup=_folder("job.toml")),
        Case("job-not-toml", jf, "the job file is not TOML", (1,), ("job.toml",),
             "blend = = scene.blend\n[[photo\n"),
        Case("job-empty", jf, "the job file is empty (0 bytes)", (1,), ("mesh", "object"),
             b""),
        Case("job-not-utf8", jf, "the job file is Latin-1 (a comment with an e-acute)",
             (1,), ("job.toml",), ("# caf\u00e9\n" + good).encode("latin-1")),
        Case("job-bom", jf, "a UTF-8 byte-order mark before the job (as Notepad writes)",
             (0,), (), b"\xef\xbb\xbf" + good.encode(), quick=True),
        bad("settings-not-table", jf, "settings = 3, not a [settings] table", "settings",
            top={"settings": 3}),
        bad("photo-listed-twice", jf, "the same image in two [[photo]] entries",
            ("photo 2", "view0.exr"), photos=[{"image": "view0.exr"}, {"image": "./view0.exr"}]),
        bad("photo-not-tables", jf, "photo = [1, 2]", "photo", top={"photo": [1, 2]}),
        bad("photo-file-names", jf, 'photo = ["view0.exr"], a list of file names', "photo",
            top={"photo": ["view0.exr"]}),
        bad("no-photo", jf, "no [[photo]] at all", "photo", top={"photo": DROP}),
        bad("unknown-top-key", jf, 'an unknown top-level key outt = "x"', "outt",
            top={"outt": "x"}),
        bad("unknown-photo-key", jf, "an unknown key in a [[photo]] (lihgt)", "lihgt",
            photo={"lihgt": "Sun"}),
        bad("no-scan", jf, "neither mesh nor object", ("mesh", "object"),
            top={"object": DROP}),
        bad("object-unknown", jf, 'object = "Nothing", not in the .blend', "Nothing",
            top={"object": "Nothing"}),
        bad("object-not-mesh", jf, 'object = "Sun", a light', "Sun", top={"object": "Sun"}),
        bad("mesh-and-object", jf, "both mesh and object", ("mesh", "object"),
            top={"mesh": "scan.ply"}),
        bad("mesh-up-bad", jf, 'mesh_up = "X"', "mesh_up", top={"mesh_up": "X"}),
        bad("up-bad", jf, "up = [1, 2], two numbers", "up", top={"up": [1, 2]}),
        # ------------------------------------------------------------- paths
        bad("image-missing", pa, "the photo's file does not exist", "missing.exr",
            quick=True, photo={"image": "missing.exr"}),
        bad("image-folder", pa, "the photo's path is a folder", "folder.exr",
            photo={"image": "folder.exr"}, setup=_folder("folder.exr")),
        bad("image-empty-path", pa, 'image = ""', "image", photo={"image": ""}),
        bad("blend-missing", pa, "the .blend does not exist", "nope.blend",
            top={"blend": "nope.blend"}),
        bad("blend-text", pa, "a text file named .blend", "text.blend",
            top={"blend": "text.blend"}, setup=_write("text.blend", TEXT)),
        bad("blend-empty", pa, "a 0-byte .blend", "empty.blend", top={"blend": "empty.blend"},
            setup=_write("empty.blend")),
        bad("blend-folder", pa, "the .blend's path is a folder", "folder.blend",
            top={"blend": "folder.blend"}, setup=_folder("folder.blend")),
        bad("mesh-missing", pa, "the mesh file does not exist", "nope.ply",
            top={"object": DROP, "mesh": "nope.ply"}),
        bad("mesh-empty", pa, "a 0-byte .ply", "empty.ply",
            top={"object": DROP, "mesh": "empty.ply"}, setup=_write("empty.ply")),
        bad("mesh-text", pa, "a text file named .ply", "text.ply",
            top={"object": DROP, "mesh": "text.ply"}, setup=_write("text.ply", TEXT)),
        bad("mesh-no-faces", pa, "a .ply of the scan's vertices without faces", "points.ply",
            top={"object": DROP, "mesh": "points.ply"}),
        bad("mesh-nan-vertex", pa, "the scan as a .ply with one vertex at NaN (Blender would "
            "import it as 0)", "nan.ply", top={"object": DROP, "mesh": "nan.ply"}),
        bad("mesh-collapsed", pa, "the scan as a .ply with every vertex at one point",
            "collapsed", top={"object": DROP, "mesh": "collapsed.ply"}),
        bad("mesh-far", pa, "the scan 1000 units off, in no camera's view", "view0.exr",
            top={"object": DROP, "mesh": "far.ply"}),
        bad("mesh-suffix", pa, "a mesh file of an unsupported kind (scan.fbx)", "scan.fbx",
            top={"object": DROP, "mesh": "scan.fbx"}, setup=_write("scan.fbx", TEXT)),
        Case("mesh-good", pa, "control: the scan as a .ply beside the .blend", (0,), (),
             job_text(top={"object": DROP, "mesh": "scan.ply"})),
        bad("mask-missing", pa, "the photo's mask does not exist", "nomask.png",
            photo={"mask": "nomask.png"}),
        bad("mask-wrong-size", pa, "a 10 x 10 mask for the 48 x 48 photo", "mask_small.png",
            photo={"mask": "mask_small.png"}),
        bad("colmap-missing", pa, "the COLMAP model folder does not exist", "sparse",
            top={"colmap": "sparse"}),
        bad("colmap-empty", pa, "an empty folder as the COLMAP model", "empty_model",
            top={"colmap": "empty_model"}, setup=_folder("empty_model")),
        Case("image-unicode-path", pa, "control: a photo named 'ph oto \u00fc.exr'", (0,), (),
             job_text(photo={"image": "ph oto \u00fc.exr"}),
             setup=lambda f: shutil.copy(f / "view0.exr", f / "ph oto \u00fc.exr")),
        # ------------------------------------------------------------- photos
        bad("exr-text", ph, "a text file named .exr", "text.exr", quick=True,
            photo={"image": "text.exr"}, setup=_write("text.exr", TEXT)),
        bad("exr-empty", ph, "a 0-byte .exr", "empty.exr", photo={"image": "empty.exr"},
            setup=_write("empty.exr")),
        bad("exr-truncated", ph, "the photo cut to half its bytes", "cut.exr",
            photo={"image": "cut.exr"},
            setup=lambda f: (f / "cut.exr").write_bytes(
                (f / "view0.exr").read_bytes()[:(f / "view0.exr").stat().st_size // 2])),
        bad("photo-1x1", ph, "a 1 x 1 photo", "tiny.exr", photo={"image": "tiny.exr"}),
        bad("photo-black", ph, "an all-black photo", "black.exr", quick=True,
            photo={"image": "black.exr"}),
        Case("photo-one-black", ph, "one all-black photo among three of the same camera",
             (1, 0), ("black.exr",),
             job_text(photos=[{"image": "view0.exr"}, {"image": "view0_b.exr"},
                              {"image": "black.exr"}])),
        Case("photo-hot-pixels", ph, "three pixels of 1e30 on the sphere", (1, 0),
             ("hot.exr",), job_text(photo={"image": "hot.exr"})),
        bad("photo-nan", ph, "three NaN pixels on the sphere", "nan.exr",
            photo={"image": "nan.exr"}),
        bad("photo-inf", ph, "three +Inf pixels on the sphere", "inf.exr",
            photo={"image": "inf.exr"}),
        Case("photo-negative", ph, "three pixels of -0.5 on the sphere (a processed EXR)",
             (0,), ("negative.exr",), job_text(photo={"image": "negative.exr"})),
        bad("photo-other-aspect", ph, "a 64 x 48 photo for the 48 x 48 camera", "wide.exr",
            photo={"image": "wide.exr"}),
        Case("photo-crop", ph, "an EXR holding a 24 x 24 part of its 48 x 48 frame (its data "
             "window, as a render cropped to a region)", (0,), ("crop.exr",),
             job_text(photo={"image": "crop.exr"})),
        Case("photo-overscan", ph, "control: an EXR whose data window holds its frame and 4 "
             "pixels more each side", (0,), (), job_text(photo={"image": "overscan.exr"})),
        Case("photo-multilayer", ph, "a Blender multilayer EXR: an AO pass before the "
             "Combined layer, and a depth pass", (0,), ("layers.exr",),
             job_text(photo={"image": "layers.exr"})),
        bad("photo-passes-only", ph, "an EXR of two passes (AO, Albedo) and no image layer",
            "passes.exr", photo={"image": "passes.exr"}),
        Case("photo-clipped-float", ph, "a float EXR whose highlight is clipped at a white "
             "level it does not state (a tenth of the lit pixels at one value)", (0,),
             ("clipped.exr",), job_text(photo={"image": "clipped.exr"})),
        Case("photo-gray", ph, "control: a one-channel (Y) EXR of the photo's luminance",
             (0,), (), job_text(photo={"image": "gray.exr"})),
        Case("photo-twice-size", ph, "a 96 x 96 photo (the 48 x 48 one, pixels doubled)",
             (0,), ("big.exr",), job_text(photo={"image": "big.exr"})),
        Case("photo-lit-where-shadow", ph, "a photo rendered with the opposite light", (1, 0),
             ("opposite.exr",), job_text(photo={"image": "opposite.exr"})),
        bad("photo-8bit-linear", ph, "an 8-bit PNG declared color_space = linear",
            "photo8.png", photo={"image": "photo8.png", "color_space": "linear"}),
        bad("color-space-bad", ph, 'color_space = "rgb"', "color_space",
            photo={"color_space": "rgb"}),
        bad("exposure-negative", ph, "exposure = -1", "exposure", photo={"exposure": -1.0}),
        bad("silhouette-margin-negative", ph, "silhouette_margin = -1", "silhouette_margin",
            photo={"silhouette_margin": -1}),
        bad("mask-excludes-all", ph, "a mask excluding every pixel",
            ("mask_none.png", "view0.exr"), photo={"mask": "mask_none.png"}),
        # ------------------------------------------------------------- light
        bad("sun-below-horizon", li, "[photo.sun] at 02:00 UTC in June in Munich",
            ("view0.exr", "sun", "photo 1"), quick=True, photo={"light": DROP, "sun": NIGHT}),
        bad("light-nan", li, "light = [0, nan, 1]", "light",
            photo={"light": [0.0, math.nan, 1.0]}),
        bad("light-zero", li, "light = [0, 0, 0]", "light", photo={"light": [0.0, 0.0, 0.0]}),
        bad("light-strings", li, 'light = ["a", "b", "c"]', "light",
            photo={"light": ["a", "b", "c"]}),
        bad("light-length", li, "light = [1, 2]", "light", photo={"light": [1.0, 2.0]}),
        bad("light-number", li, "light = 5", "light", photo={"light": 5}),
        bad("light-unknown-sun", li, 'light = "Moon", no such Sun', "Moon",
            photo={"light": "Moon"}),
        bad("light-and-sun", li, "both light and [photo.sun]", ("light", "sun"),
            photo={"sun": NIGHT}),
        bad("sun-half-place", li, "[photo.sun] with latitude but no longitude",
            ("longitude", "latitude"),
            photo={"light": DROP, "sun": {"date": "2026-06-21 12:00:00", "latitude": 48.1}}),
        bad("sun-bad-date", li, '[photo.sun] date = "yesterday"', ("date", "yesterday"),
            photo={"light": DROP, "sun": dict(NIGHT, date="yesterday")}),
        bad("sun-latitude-range", li, "[photo.sun] latitude = 200", "latitude",
            photo={"light": DROP, "sun": dict(NIGHT, latitude=200.0)}),
        bad("sun-latitude-string", li, '[photo.sun] latitude = "north"', "latitude",
            photo={"light": DROP, "sun": dict(NIGHT, latitude="north")}),
        bad("sun-no-exif-date", li, "[photo.sun] without date, and the EXR has no EXIF date",
            ("view0.exr", "date"),
            photo={"light": DROP, "sun": {"latitude": 48.1, "longitude": 11.6}}),
        bad("probe-missing", li, "[photo.probe] image does not exist", "noprobe.exr",
            photo={"light": DROP, "probe": {"image": "noprobe.exr"}}),
        bad("probe-center-no-radius", li, "[photo.probe] center without radius", "radius",
            photo={"light": DROP, "probe": {"image": "view0.exr", "center": [24, 24]}}),
        bad("probe-radius-negative", li, "[photo.probe] radius = -5", "radius",
            photo={"light": DROP,
                   "probe": {"image": "view0.exr", "center": [24, 24], "radius": -5}}),
        bad("irradiance-zero", li, "irradiance = 0", "irradiance", photo={"irradiance": 0}),
        bad("irradiance-negative", li, "irradiance = -1", "irradiance",
            photo={"irradiance": -1.0}),
        bad("irradiance-inf", li, "irradiance = inf", "irradiance",
            photo={"irradiance": math.inf}),
        bad("irradiance-two", li, "irradiance = [1, 2]", "irradiance",
            photo={"irradiance": [1, 2]}),
        bad("irradiance-string", li, 'irradiance = "x"', "irradiance",
            photo={"irradiance": "x"}),
        # ------------------------------------------------------------- camera
        bad("camera-unknown", ca, 'camera = "nope.jpg", no such camera', "nope.jpg",
            quick=True, photo={"camera": "nope.jpg"}),
        bad("camera-no-photo", ca, "a [[photo]] with a camera and no image", "view0.jpg",
            photo={"image": DROP}),
        bad("photo-no-camera", ca, "no camera given, and other.exr matches none",
            "other.exr", photo={"image": "other.exr", "camera": DROP}),
        bad("camera-not-camera", ca, 'camera = "Scan", a mesh', "Scan",
            photo={"camera": "Scan"}),
        bad("camera-number", ca, "camera = 3", "camera", quick=True,
            photo={"camera": 3}),
        bad("camera-empty", ca, 'camera = ""', "camera", photo={"camera": ""}),
        # ------------------------------------------------------------- output folder
        bad("out-job-folder", of, 'out = ".", the job\'s own folder (its scene.blend)',
            ("out", "scene.blend"), quick=True, top={"out": "."}, out="."),
        bad("out-is-file", of, "out names an existing file", "notes.txt",
            top={"out": "notes.txt"}, setup=_write("notes.txt", "my notes\n"),
            out="notes.txt"),
        bad("out-below-file", of, "out lies below a file", "notes.txt",
            top={"out": "notes.txt/out"}, setup=_write("notes.txt", "my notes\n")),
        bad("out-users-table", of, "out holds the user's own brdf_0.binary, no overwrite",
            "brdf_0.binary", setup=_write("out/brdf_0.binary", "my own table")),
        bad("out-users-report", of, "out holds the user's own report.json, no overwrite",
            "report.json", setup=_write("out/report.json", '{"mine": true}\n')),
        bad("overwrite-string", of, 'overwrite = "yes"', "overwrite",
            top={"overwrite": "yes"}),
        bad("out-empty-string", of, 'out = ""', "out", top={"out": ""}),
        Case("out-unwritable", of, "out is a folder without write permission (0o500)",
             (1,), ("locked",), job_text(top={"out": "locked"}), setup=_locked_out,
             out="locked", needs_non_root=True),
        Case("out-users-other-files", of, "out holds the user's notes.txt (not a run's name)",
             (0,), (), good, setup=_write("out/notes.txt", "my notes\n")),
        Case("out-previous-run", of, "control: out holds an earlier run's outputs", (0,), (),
             good, setup=_previous_run),
        # ------------------------------------------------------------- settings
        bad("samples-negative", se, "samples = -3", "samples", quick=True,
            settings={"samples": -3}),
        bad("samples-string", se, 'samples = "twelve"', "samples",
            settings={"samples": "twelve"}),
        bad("samples-float", se, "samples = 1.5", "samples", settings={"samples": 1.5}),
        bad("samples-bool", se, "samples = true", "samples", settings={"samples": True}),
        bad("trials-zero", se, "trials = 0", "trials", settings={"trials": 0}),
        bad("seed-negative", se, "seed = -1", "seed", settings={"seed": -1}),
        bad("seed-huge", se, "seed = 2**40, beyond a 32-bit int", "seed",
            settings={"seed": 2**40}),
        bad("subset-fraction-range", se, "subset_fraction = 2.0", "subset_fraction",
            settings={"subset_fraction": 2.0}),
        bad("curvature-nan", se, "curvature_threshold = nan", "curvature_threshold",
            settings={"curvature_threshold": math.nan}),
        bad("kl-bins-range", se, "kl_bins = 2", "kl_bins", settings={"kl_bins": 2}),
        bad("kl-samples-zero", se, "kl_samples = 0", "kl_samples",
            settings={"kl_samples": 0}),
        bad("peak-angle-range", se, "peak_max_angle = 500", "peak_max_angle",
            settings={"peak_max_angle": 500.0}),
        bad("min-cosine-range", se, "min_cosine = 1.5", "min_cosine",
            settings={"min_cosine": 1.5}),
        bad("monotonicity-negative", se, "monotonicity_tolerance = -1",
            "monotonicity_tolerance", settings={"monotonicity_tolerance": -1.0}),
        bad("clip-level-inf", se, "clip_level = inf", "clip_level",
            settings={"clip_level": math.inf}),
        bad("min-reliable-zero", se, "min_reliable_samples = 0", "min_reliable_samples",
            settings={"min_reliable_samples": 0}),
        bad("kl-path-enum", se, 'kl_path = "SLOW"', "kl_path", settings={"kl_path": "SLOW"}),
        bad("preset-enum", se, 'preset = "TURBO"', "preset", settings={"preset": "TURBO"}),
        bad("region-mode-enum", se, 'region_mode = "X"', "region_mode",
            settings={"region_mode": "X"}),
        bad("use-curvature-string", se, 'use_curvature = "yes"', "use_curvature",
            settings={"use_curvature": "yes"}),
        bad("pixel-footprint-string", se, 'pixel_footprint = "on"', "pixel_footprint",
            settings={"pixel_footprint": "on"}),
        bad("unknown-setting", se, "sede = 4 (a typo of seed)", "sede",
            settings={"sede": 4}),
        # the texture's settings (issue 16)
        bad("texture-string", se, 'texture = "on"', "texture", settings={"texture": "on"}),
        bad("texture-no-uv-map", se, "texture = true on a scan .ply without a UV map",
            "uv_on_copy", top={"object": DROP, "mesh": "scan_no_uv.ply"},
            settings={"texture": True}),
        bad("texture-uv-map-unknown", se, 'texture on a scan given uv_map = "Nope"', "Nope",
            settings={"texture": True, "uv_map": "Nope"}),
        bad("texture-size-negative", se, "texture_size = -8", "texture_size",
            settings={"texture_size": -8}),
        bad("texture-size-huge", se, "texture_size = 1000000", "texture_size",
            settings={"texture_size": 1000000}),
        bad("material-model-enum", se, 'material_model = "PBR"', "material_model",
            settings={"material_model": "PBR"}),
        bad("export-gltf-string", se, 'export_gltf = "yes"', "export_gltf",
            settings={"export_gltf": "yes"}),
        bad("uv-on-copy-string", jf, 'uv_on_copy = "yes"', "uv_on_copy",
            top={"uv_on_copy": "yes"}),
        # ------------------------------------------------------------- command line
        Case("argv-none", cl, "no arguments", (2,), argv=lambda f: [], quick=True),
        Case("argv-two", cl, "two job files", (2,),
             argv=lambda f: [str(f / "job.toml"), str(f / "job.toml")]),
        Case("argv-unknown-flag", cl, "--frobnicate", (2,), argv=lambda f: ["--frobnicate"]),
        Case("argv-h", cl, "-h", (2,), argv=lambda f: ["-h"]),
        Case("argv-dashdash-only", cl, "-- and nothing after it", (2,),
             argv=lambda f: ["--"]),
        Case("argv-empty-string", cl, 'an empty argument ""', (1,), ("job file",),
             argv=lambda f: [""]),
        Case("argv-blender-form", cl, "control: -- job.toml, as blender passes it", (0,),
             (), good, argv=lambda f: ["--", str(f / "job.toml")]),
        # ------------------------------------------------------------- interruption
        Case("ctrl-c-gbuffers", it, "Ctrl+C at the first G-buffers line", (130,),
             ("interrupted", "Ctrl+C"), good, interrupt="G-buffers 1/", quick=True),
        Case("ctrl-c-second-photo", it, "Ctrl+C at G-buffers 2/3 of three photos", (130,),
             ("interrupted", "Ctrl+C"), job_text(photos=_three_photos()),
             interrupt="G-buffers 2/3"),
        Case("ctrl-c-footprint", it, "Ctrl+C at the first G-buffers line, the pixel "
             "footprint on (a second render per photo)", (130,), ("interrupted", "Ctrl+C"),
             job_text(settings={"pixel_footprint": True}), interrupt="G-buffers 1/"),
        Case("ctrl-c-science", it, "Ctrl+C as the science starts (observing)", (130,),
             ("interrupted", "Ctrl+C"), good, interrupt="observing"),
        Case("ctrl-c-fitting", it, "Ctrl+C while the material is fitted", (130,),
             ("interrupted", "Ctrl+C"), good, interrupt="fitting the material"),
        Case("ctrl-c-previous-run", it, "Ctrl+C at G-buffers, out holds an earlier run's "
             "outputs (kept whole)", (130,), ("interrupted", "Ctrl+C"), good,
             setup=_previous_run, interrupt="G-buffers 1/"),
    ]
    names = [case.name for case in c]
    assert len(names) == len(set(names)), "case names must be unique"
    assert all(case.group in GROUPS for case in c)
    return c


# --------------------------------------------------------------------------- inputs


def _read_exr(path: pathlib.Path) -> np.ndarray:
    """(H, W, C) float32 pixels of an image file (OpenImageIO)."""
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise RuntimeError(oiio.geterror())
    spec = inp.spec()
    pixels = np.asarray(inp.read_image(0, 0, 0, spec.nchannels, oiio.FLOAT))
    inp.close()
    return pixels.reshape(spec.height, spec.width, spec.nchannels).copy()


def _write_image(path: pathlib.Path, pixels: np.ndarray, origin=(0, 0), frame=None,
                 names=None) -> None:
    """Write (H, W, C) pixels: float32 as float, uint8 as 8-bit (by the suffix's format);
    origin (x, y) and frame (width, height): a data window placed in a display window
    of that size at 0, 0 (default: the pixels are the frame); names: the C channels'
    names (default: the format's own)."""
    import OpenImageIO as oiio

    kind = oiio.FLOAT if pixels.dtype == np.float32 else oiio.UINT8
    h, w, c = pixels.shape
    spec = oiio.ImageSpec(w, h, c, kind)
    spec.x, spec.y = origin
    if frame is not None:
        spec.full_x, spec.full_y, spec.full_width, spec.full_height = 0, 0, *frame
    if names is not None:
        spec.channelnames = names
    out = oiio.ImageOutput.create(str(path))
    if out is None or not out.open(str(path), spec):
        raise RuntimeError(f"cannot write {path}: {oiio.geterror()}")
    out.write_image(np.ascontiguousarray(pixels))
    out.close()


def _write_points_ply(path: pathlib.Path, vertices: np.ndarray) -> None:
    """An ASCII PLY holding ``vertices`` (N, 3) and no faces."""
    lines = ["ply", "format ascii 1.0", f"element vertex {len(vertices)}",
             "property float x", "property float y", "property float z",
             "element face 0", "property list uchar int vertex_indices", "end_header"]
    lines += [f"{x:.6f} {y:.6f} {z:.6f}" for x, y, z in vertices]
    path.write_text("\n".join(lines) + "\n")


def build_inputs(folder: pathlib.Path) -> dict:
    """The files every case starts from, in ``folder``: ``scene.blend`` (the tiny scene
    of ``testkit.blender_scene``), ``view0.exr`` (its 48 x 48 RGBA linear photo) and its
    copies ``view0_b.exr``, ``view0_c.exr``, ``other.exr``; ``opposite.exr`` (the same
    view rendered with the Sun turned to the opposite direction); ``black.exr`` (RGB 0),
    ``hot.exr``, ``nan.exr``, ``inf.exr`` and ``negative.exr`` (three lit pixels
    set to 1e30 / NaN / Inf / -0.5), ``tiny.exr``
    (1 x 1), ``wide.exr`` (64 x 48: 8 black columns each side), ``big.exr`` (96 x 96,
    each pixel doubled); ``photo8.png`` (8-bit sRGB); ``mask_none.png`` (48 x 48, all
    excluded), ``mask_small.png`` (10 x 10); ``scan.ply`` (the scan, exported),
    ``scan_no_uv.ply`` (the same without its UV map), ``points.ply`` (its
    vertices, no faces), ``nan.ply`` (its first vertex at NaN), ``collapsed.ply``
    (every vertex at their mean) and ``far.ply`` (moved 1000 units along x);
    ``gray.exr`` (one channel: the photo's luminance), ``crop.exr`` (the photo's
    middle 24 x 24 as the data window of a 48 x 48 frame) and ``overscan.exr`` (the
    photo in a 56 x 56 data window, 4 black pixels each side beyond the frame),
    ``layers.exr`` (a multilayer EXR: an AO pass of 0.9, the photo as Combined, a
    depth), ``passes.exr`` (AO and Albedo layers, no image) and ``clipped.exr`` (the
    photo clipped at its lit pixels' 90th percentile, a level it does not state).
    Returns what was built and its seconds."""
    import bpy
    from mathutils import Vector

    from testkit import blender_scene as BS

    t0 = time.perf_counter()
    folder.mkdir(parents=True, exist_ok=True)
    built = BS.build(folder)
    scene, sun, scan = built["scene"], built["sun"], built["scan"]
    sun.rotation_quaternion = Vector((0, 0, 1)).rotation_difference(Vector(tuple(-BS.LIGHT)))
    BS.render_photo(scene, folder / "opposite.exr")
    sun.rotation_quaternion = Vector((0, 0, 1)).rotation_difference(Vector(tuple(BS.LIGHT)))
    bpy.ops.object.select_all(action="DESELECT")
    scan.select_set(True)
    bpy.context.view_layer.objects.active = scan
    bpy.ops.wm.ply_export(filepath=str(folder / "scan.ply"), export_selected_objects=True,
                          export_normals=True, apply_modifiers=True)
    bpy.ops.wm.ply_export(filepath=str(folder / "scan_no_uv.ply"), export_selected_objects=True,
                          export_normals=True, export_uv=False, apply_modifiers=True)
    vertices = np.array([tuple(v.co) for v in scan.data.vertices])
    _write_points_ply(folder / "points.ply", vertices)
    for name, changed in (("nan.ply", np.where(np.arange(len(vertices))[:, None] == 0,
                                               np.nan, vertices)),
                          ("collapsed.ply", np.zeros_like(vertices) + vertices.mean(axis=0)),
                          ("far.ply", vertices + [1000.0, 0.0, 0.0])):
        scan.data.vertices.foreach_set("co", changed.astype(np.float32).ravel())
        bpy.ops.wm.ply_export(filepath=str(folder / name), export_selected_objects=True,
                              export_normals=True, apply_modifiers=True)
    scan.data.vertices.foreach_set("co", vertices.astype(np.float32).ravel())
    bpy.ops.wm.save_as_mainfile(filepath=str(folder / "scene.blend"))

    photo = _read_exr(folder / "view0.exr")  # (48, 48, 4) RGBA
    for name in ("view0_b.exr", "view0_c.exr", "other.exr"):
        shutil.copy(folder / "view0.exr", folder / name)
    lit = np.flatnonzero(photo[..., :3].max(axis=-1).ravel() > 0)
    picks = lit[np.linspace(0, len(lit) - 1, 5).astype(int)[1:4]]  # three, inside
    black = photo.copy()
    black[..., :3] = 0.0
    _write_image(folder / "black.exr", black)
    for name, value in (("hot.exr", 1e30), ("nan.exr", np.nan), ("inf.exr", np.inf),
                        ("negative.exr", -0.5)):
        changed = photo.copy().reshape(-1, photo.shape[-1])
        changed[picks, :3] = value
        _write_image(folder / name, changed.reshape(photo.shape))
    tiny = np.ones((1, 1, 4), np.float32)
    tiny[0, 0, :3] = photo[..., :3].reshape(-1, 3)[lit].mean(axis=0)
    _write_image(folder / "tiny.exr", tiny)
    wide = np.zeros((48, 64, 4), np.float32)
    wide[:, 8:56] = photo
    _write_image(folder / "wide.exr", wide)
    _write_image(folder / "big.exr", np.repeat(np.repeat(photo, 2, axis=0), 2, axis=1))
    _write_image(folder / "crop.exr", photo[12:36, 12:36], origin=(12, 12), frame=(48, 48))
    overscan = np.zeros((56, 56, photo.shape[2]), np.float32)
    overscan[4:52, 4:52] = photo
    _write_image(folder / "overscan.exr", overscan, origin=(-4, -4), frame=(48, 48))
    ao = np.full(photo.shape[:2] + (3,), 0.9, np.float32)
    _write_image(folder / "layers.exr", np.concatenate(
        [ao, photo[..., :4], np.full(photo.shape[:2] + (1,), 7.0, np.float32)], axis=-1),
        names=[f"ViewLayer.AO.{c}" for c in "RGB"]
        + [f"ViewLayer.Combined.{c}" for c in "RGBA"] + ["ViewLayer.Depth.Z"])
    _write_image(folder / "passes.exr", np.concatenate([ao, photo[..., :3]], axis=-1),
                 names=[f"{layer}.{c}" for layer in ("AO", "Albedo") for c in "RGB"])
    # the highlight clipped at a white level the file does not state (a RAW converter's
    # EXR of a clipped photo): the lit pixels' 90th percentile, a tenth of them at it
    clipped = photo.copy()
    level = np.float32(np.quantile(photo[..., :3].reshape(-1, 3)[lit].max(axis=1), 0.9))
    clipped[..., :3] = np.minimum(clipped[..., :3], level)
    _write_image(folder / "clipped.exr", clipped)
    luminance = photo[..., :3] @ np.array([0.2126, 0.7152, 0.0722], np.float32)
    _write_image(folder / "gray.exr", np.ascontiguousarray(luminance[..., None]))
    rgb = np.clip(photo[..., :3], 0.0, 1.0)
    srgb = np.where(rgb <= 0.0031308, 12.92 * rgb, 1.055 * np.power(rgb, 1 / 2.4) - 0.055)
    _write_image(folder / "photo8.png", np.round(srgb * 255).astype(np.uint8))
    _write_image(folder / "mask_none.png", np.zeros((48, 48, 1), np.uint8))
    _write_image(folder / "mask_small.png", np.full((10, 10, 1), 255, np.uint8))
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return {"folder": str(folder), "files": sorted(p.name for p in folder.iterdir()),
            "seconds": round(time.perf_counter() - t0, 2)}


# --------------------------------------------------------------------------- running


def snapshot(folder: pathlib.Path) -> dict[str, tuple[str, int]]:
    """Every file below ``folder`` (hidden ones included): relative path -> (sha256,
    bytes)."""
    files = {}
    for root, _dirs, names in os.walk(folder):
        for name in names:
            path = pathlib.Path(root, name)
            files[path.relative_to(folder).as_posix()] = (
                hashlib.sha256(path.read_bytes()).hexdigest(), path.stat().st_size)
    return files


def _child_env() -> dict:
    env = dict(os.environ)
    env.update(CHILD_THREADS)
    return env


def prepare_case(case: Case, folder: pathlib.Path) -> None:
    """Make the case's own files in ``folder`` (already holding the inputs): its setup,
    then its job file."""
    if case.setup is not None:
        case.setup(folder)
    if isinstance(case.job, str):
        (folder / "job.toml").write_text(case.job, encoding="utf-8")
    elif isinstance(case.job, bytes):
        (folder / "job.toml").write_bytes(case.job)


def run_case(case: Case, folder: pathlib.Path, timeout: float = TIMEOUT_S) -> dict:
    """Run the batch entry for ``case`` in ``folder`` (prepared by :func:`prepare_case`);
    returns the outcome: ``command`` (the case folder written ``<case>``), ``status``
    (exit status, None if killed), ``stdout``, ``stderr``, ``seconds`` (wall),
    ``interrupt_sent``, ``timed_out``."""
    argv = (case.argv or _job_arg)(folder)
    command = [sys.executable, *BATCH, *argv]
    t0 = time.perf_counter()
    process = subprocess.Popen(command, cwd=folder, env=_child_env(), text=True,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               preexec_fn=_ctrl_c_as_in_a_terminal)
    killed = threading.Event()

    def kill():
        killed.set()
        process.kill()

    watchdog = threading.Timer(timeout, kill)
    watchdog.start()
    stderr_lines = []
    drain = threading.Thread(target=lambda: stderr_lines.extend(process.stderr), daemon=True)
    drain.start()
    stdout_lines, sent = [], False
    try:
        for line in process.stdout:
            stdout_lines.append(line)
            if case.interrupt and not sent and case.interrupt in line:
                process.send_signal(signal.SIGINT)  # what Ctrl+C in the terminal sends
                sent = True
        process.wait()
        drain.join()
    finally:
        watchdog.cancel()
    return {"command": [pathlib.Path(sys.executable).name, *BATCH,
                        *(a.replace(str(folder), "<case>") for a in argv)],
            "status": None if killed.is_set() else process.returncode,
            "stdout": "".join(stdout_lines), "stderr": "".join(stderr_lines),
            "seconds": round(time.perf_counter() - t0, 2), "interrupt_sent": sent,
            "timed_out": killed.is_set()}


def _ctrl_c_as_in_a_terminal() -> None:
    """In the child, before the batch starts: SIGINT back to its default. A sweep
    started in the background by a non-interactive shell (``cmd &``, as CI may) has
    SIGINT ignored, which its children inherit, and Python then installs no
    KeyboardInterrupt handler: the interruption cases would measure the shell, not
    the batch entry. A user's Ctrl+C in a terminal always meets the default."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _names_in(line: str, names) -> bool:
    """Whether one of ``names`` is in ``line`` as a whole word (case-insensitive)."""
    return any(re.search(rf"(?<!\w){re.escape(n)}(?!\w)", line, re.IGNORECASE)
               for n in names)


def _is_run_output(relative: str, out: str) -> bool:
    """Whether ``relative`` (from the case folder) is a file a run owns in ``out``."""
    from brdf_reconstruct.core import files

    parent, _, name = relative.rpartition("/")
    if pathlib.PurePosixPath(parent or ".") != pathlib.PurePosixPath(out):
        return False
    return name == files.OUTPUT_MARKER or any(
        pathlib.PurePosixPath(name).match(p) for p in files.OUTPUT_NAMES)


def _under(relative: str, out: str) -> bool:
    out = pathlib.PurePosixPath(out)
    return out == pathlib.PurePosixPath(".") or out in pathlib.PurePosixPath(relative).parents


def check_table(path: pathlib.Path) -> str | None:
    """None when the MERL table at ``path`` reads and is finite: no Inf, and NaN (an
    unmeasured cell) only where the cell's light or view is below the horizon; else
    what is wrong."""
    from brdf_reconstruct.core.brdf import merl

    try:
        table = merl.read(path)  # refuses Inf and NaN stored in the file
    except (OSError, ValueError) as error:
        return f"{path.name} does not read: {error}"
    if np.isinf(table).any():
        return f"{path.name} holds Inf"
    nan = np.isnan(table).reshape(3, -1)[:, merl.valid_cells()]
    if nan.any():
        return f"{path.name} has {int(nan.any(axis=0).sum())} unmeasured (NaN) cells above " \
               "the horizon"
    return None


def judge(case: Case, result: dict, before: dict, after: dict,
          folder: pathlib.Path) -> list[str]:
    """Every way the outcome falls short of handled cleanly (module docstring); [] when
    it was handled cleanly."""
    problems = []
    status, out, err = result["status"], result["stdout"], result["stderr"]
    if result["timed_out"]:
        problems.append(f"still running after {TIMEOUT_S:.0f} s: killed")
    elif status not in case.expect:
        problems.append(f"exit {status}, expected {' or '.join(map(str, case.expect))}")
    if case.interrupt and not result["interrupt_sent"]:
        problems.append(f"never printed {case.interrupt!r}, so no Ctrl+C was sent")
    if "Traceback" in out or "Traceback" in err:
        problems.append("a Traceback was printed")
    errors = [ln for ln in err.splitlines() if ln.startswith("error:")]
    if status in (1, 130):
        if len(errors) != 1:
            problems.append(f"{len(errors)} lines starting with 'error:' on stderr, not 1")
        elif case.names and not _names_in(errors[0], case.names):
            problems.append(f"the error does not name {' / '.join(case.names)}")
    if status == 2 and not any(ln.lower().startswith("usage") for ln in err.splitlines()):
        problems.append("no usage line on stderr")
    if status == 0 and case.names:
        notes = [ln for ln in out.splitlines() if ln.startswith("note:")]
        if not any(_names_in(ln, case.names) for ln in notes):
            problems.append(f"no note: line naming {' / '.join(case.names)}")
    # the inputs, and what the output folder held before
    for relative, (digest, _size) in before.items():
        if relative not in after:
            problems.append(f"{relative} was removed")
        elif after[relative][0] != digest:
            if status == 0 and _is_run_output(relative, case.out):
                continue  # a run replaces its own outputs (an earlier run's, or overwrite)
            problems.append(f"{relative} was changed")
    new = sorted(set(after) - set(before))
    outside = [r for r in new if not _under(r, case.out)]
    if outside:
        problems.append(f"new files outside the output folder: {', '.join(outside[:4])}")
    if status != 0 and [r for r in new if _under(r, case.out)]:
        shown = [r for r in new if _under(r, case.out)][:4]
        problems.append(f"a run that failed left new files in {case.out}: {', '.join(shown)}")
    temporary = [r for r in after if ".tmp" in pathlib.PurePosixPath(r).name]
    if temporary:
        problems.append(f"temporary files left: {', '.join(temporary[:4])}")
    empty = [r for r in after if after[r][1] == 0 and before.get(r) != after[r]]
    if empty:
        problems.append(f"0-byte outputs: {', '.join(empty[:4])}")
    if status == 0:
        out_dir = folder / case.out
        table = check_table(out_dir / "brdf_0.binary") if (
            out_dir / "brdf_0.binary").is_file() else "no brdf_0.binary"
        if table:
            problems.append(table)
        try:
            json.loads((out_dir / "report.json").read_text())
        except (OSError, ValueError) as error:
            problems.append(f"report.json missing or not JSON ({type(error).__name__})")
    return problems


def sweep_case(case: Case, inputs: pathlib.Path, work: pathlib.Path,
               timeout: float = TIMEOUT_S) -> dict:
    """One case from a fresh copy of the inputs: run, judged; the row of the table."""
    row = {"case": case.name, "class": case.group, "what": case.what,
           "expected": case.expected_text()}
    if case.needs_non_root and os.geteuid() == 0:
        return row | {"ok": None, "skipped": "running as root, whom permissions do not bind"}
    folder = work / case.name
    shutil.copytree(inputs, folder)
    try:
        prepare_case(case, folder)
        out_existed = (folder / case.out).exists()
        before = snapshot(folder)
        result = run_case(case, folder, timeout)
        after = snapshot(folder)
        problems = judge(case, result, before, after, folder)
    finally:
        for root, dirs, _names in os.walk(folder):  # a locked folder is unlocked to remove it
            for name in dirs:
                pathlib.Path(root, name).chmod(0o755)
    errors = [ln for ln in result["stderr"].splitlines() if ln.startswith("error:")]
    usage = [ln for ln in result["stderr"].splitlines() if ln.lower().startswith("usage")]
    notes = [ln for ln in result["stdout"].splitlines() if ln.startswith("note:")]
    return row | {"ok": not problems, "problems": problems, "status": result["status"],
                  "got": _got(result["status"], errors, usage), "error_lines": errors,
                  "usage_lines": usage, "notes": notes, "command": result["command"],
                  "seconds": result["seconds"], "interrupt_sent": result["interrupt_sent"],
                  "traceback": "Traceback" in result["stdout"] + result["stderr"],
                  "out_folder_created": not out_existed and (folder / case.out).is_dir(),
                  "stderr_tail": result["stderr"].splitlines()[-6:]}


def _got(status, errors, usage) -> str:
    if status is None:
        return "killed (hang)"
    line = errors[0] if errors else (usage[0] if usage and status == 2 else "")
    return f"{status}" + (f": {line}" if line else "")


def _cost(case: Case) -> int:
    """A rough rank of a case's run time, to start the long ones first: a full run,
    a run stopped after its G-buffers or science, a job refused on reading."""
    if 0 in case.expect or case.interrupt:
        return 0
    return 1 if case.group in ("photos", "light", "camera") else 2


# --------------------------------------------------------------------------- report


def table_lines(rows: list[dict]) -> list[str]:
    """The table (case, class, expected, got, ok) in :data:`GROUPS` order, each case
    that was not handled cleanly followed by its problems."""
    width = max(len(r["case"]) for r in rows)
    head = f"{'case':<{width}}  {'class':<13}  {'expected':<34}  ok    got"
    lines = [head, "-" * len(head)]
    order = {g: i for i, g in enumerate(GROUPS)}
    for r in sorted(rows, key=lambda r: order[r["class"]]):
        ok = "skip" if r["ok"] is None else ("yes" if r["ok"] else "NO")
        got = r.get("got", r.get("skipped", ""))
        got = got if len(got) <= 90 else got[:87] + "..."
        lines.append(f"{r['case']:<{width}}  {r['class']:<13}  {r['expected']:<34}  "
                     f"{ok:<4}  {got}")
        for problem in r.get("problems", []):
            lines.append(f"{'':<{width}}    why: {problem}")
    return lines


def summary(rows: list[dict], seconds: float) -> dict:
    """Counts: handled cleanly / run, per class, the skipped cases and the failing ones."""
    ran = [r for r in rows if r["ok"] is not None]
    handled = sum(r["ok"] for r in ran)
    by_class = {g: {"handled": sum(r["ok"] for r in ran if r["class"] == g),
                    "run": sum(r["class"] == g for r in ran)} for g in GROUPS}
    return {"headline": f"{handled}/{len(ran)} handled cleanly", "handled": handled,
            "run": len(ran), "skipped": [r["case"] for r in rows if r["ok"] is None],
            "not_handled": [r["case"] for r in ran if not r["ok"]],
            "by_class": by_class, "seconds_total": round(seconds, 1)}


# --------------------------------------------------------------------------- main


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true",
                        help="only the cases marked quick (a few of every class)")
    parser.add_argument("--cases", default="",
                        help="comma-separated case names to run (default: all)")
    parser.add_argument("--workers", type=int, default=2,
                        help="cases run at once, each in its own process (default 2)")
    parser.add_argument("--timeout", type=float, default=TIMEOUT_S,
                        help="seconds before a case is killed as a hang (default 300)")
    parser.add_argument("--work", type=pathlib.Path, default=None,
                        help="folder for the inputs and the cases' folders (default: a "
                        "temporary folder, removed at the end)")
    parser.add_argument("--keep", action="store_true", help="keep the work folder")
    parser.add_argument("--out", type=pathlib.Path, default=None,
                        help="the result file (default bench/results/bad_inputs.json; "
                        "bad_inputs_quick.json with --quick, bad_inputs_subset.json with "
                        "--cases, so a part never replaces the full sweep's file)")
    parser.add_argument("--list", action="store_true", help="list the cases and stop")
    args = parser.parse_args(argv)
    if args.out is None:
        name = "_subset" if args.cases else ("_quick" if args.quick else "")
        args.out = common.RESULTS / f"bad_inputs{name}.json"
    chosen = cases()
    if args.list:
        for case in chosen:
            print(f"{case.name:<28} {case.group:<13} {case.expected_text():<40} {case.what}")
        print(f"{len(chosen)} cases")
        return 0
    if args.cases:
        wanted = [n.strip() for n in args.cases.split(",") if n.strip()]
        unknown = set(wanted) - {c.name for c in chosen}
        if unknown:
            parser.error(f"unknown cases: {', '.join(sorted(unknown))}")
        chosen = [c for c in chosen if c.name in wanted]
    elif args.quick:
        chosen = [c for c in chosen if c.quick]
    # the add-on's basis cache, as make sets it (a case must not build its own)
    os.environ.setdefault("BRDF_RECONSTRUCT_CACHE", str(common.ROOT / ".cache"))
    info = common.machine(note=f"{args.workers} cases at once, each a batch process "
                          f"with {CHILD_THREADS['OMP_NUM_THREADS']} BLAS thread")
    if args.work is not None:
        args.work.mkdir(parents=True, exist_ok=True)
    work = pathlib.Path(tempfile.mkdtemp(prefix="brdf_bad_inputs_", dir=args.work))
    t0 = time.perf_counter()
    try:
        print(f"building the inputs in {work / 'inputs'}", flush=True)
        inputs = build_inputs(work / "inputs")
        (work / "cases").mkdir()
        rows = []
        with concurrent.futures.ThreadPoolExecutor(max_workers=args.workers) as pool:
            futures = {pool.submit(sweep_case, c, work / "inputs", work / "cases",
                                   args.timeout): c
                       for c in sorted(chosen, key=_cost)}
            for future in concurrent.futures.as_completed(futures):
                row = future.result()
                rows.append(row)
                ok = "skip" if row["ok"] is None else ("ok" if row["ok"] else "NOT OK")
                print(f"[{len(rows):3d}/{len(chosen)}] {ok:<6} {row['class']}/{row['case']}"
                      f" ({row.get('seconds', 0):.1f} s)", flush=True)
        seconds = time.perf_counter() - t0
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)
    order = {c.name: i for i, c in enumerate(cases())}
    rows.sort(key=lambda r: order[r["case"]])
    result = summary(rows, seconds)
    print()
    print("\n".join(table_lines(rows)))
    print()
    if result["skipped"]:
        print(f"skipped: {', '.join(result['skipped'])}")
    print(f"{result['headline']} ({seconds:.0f} s, {args.workers} at once)")
    document = {"summary": result | {"workers": args.workers,
                                     "seconds_inputs": inputs["seconds"]},
                "cases": rows, "inputs": inputs["files"],
                "machine": common.machine_end(info)}
    path = common.write_json(args.out, document, arguments=args)
    print(f"wrote {path}")
    return 0 if result["handled"] == result["run"] else 1


if __name__ == "__main__":
    sys.exit(main())
