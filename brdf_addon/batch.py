"""Batch entry: run a job file headless, the same operators as the panel.

    blender --background --python <extension>/brdf_addon/batch.py -- job.toml
    python -m brdf_reconstruct.brdf_addon.batch job.toml

Exit status: 0 on success; 1 with one line "error: ..." on stderr for a bad
job (missing file, unknown camera name, light below the horizon, no reliable
pixels, ...); 2 for a wrong command line. Outputs go to the job's ``out``
folder: ``brdf_<region>.binary``, ``report.json``, pictures, and ``scene.blend``
(a copy: the job's own .blend is never written).
"""

from __future__ import annotations

import sys


def _args(argv):
    if "--" in argv:
        argv = argv[argv.index("--") + 1:]
    return argv


def _import_package():
    """The add-on package, whether run by ``-m`` or as a script inside Blender."""
    try:
        import brdf_reconstruct as package  # pip install -e / tests
    except ImportError:
        import importlib
        import pathlib

        root = pathlib.Path(__file__).resolve().parent.parent
        sys.path.insert(0, str(root.parent))
        package = importlib.import_module(root.name)
    return package


def main(argv=None) -> int:
    argv = _args(list(sys.argv[1:] if argv is None else argv))
    if len(argv) != 1 or argv[0].startswith("-"):  # -h, --help, or an unknown flag
        print("usage: batch.py job.toml  (after -- when run by blender)", file=sys.stderr)
        return 2
    try:
        report = run_job(argv[0])
    except (ValueError, OSError) as error:
        print(f"error: {_one_line(error)}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("error: interrupted (Ctrl+C); no output is half-written (each file is "
              "renamed into place only when complete)", file=sys.stderr)
        return 130
    ok = sum(r["status"] == "ok" for r in report["regions"])
    print(f"done: {ok} region(s) reconstructed; outputs in {report['out']}")
    return 0


def run_job(path) -> dict:
    """Load, apply and run a job; returns the report. ValueError on a bad job."""
    import bpy

    package = _import_package()
    from importlib import import_module

    job_mod = import_module(package.__name__ + ".brdf_addon.job")
    job = job_mod.load(path)
    if job.blend is not None:
        bpy.ops.wm.open_mainfile(filepath=str(job.blend))
    else:
        bpy.ops.wm.read_factory_settings(use_empty=True)
    if not hasattr(bpy.types.Scene, "brdf"):
        package.register()
    scene = bpy.context.scene
    job_mod.apply(job, scene)
    job.out.mkdir(parents=True, exist_ok=True)
    try:
        bpy.ops.brdf.reconstruct()
    except RuntimeError as error:  # the operator's one-line report
        raise ValueError(_operator_message(error)) from None
    import json

    report = json.loads((job.out / "report.json").read_text())
    files = import_module(package.__name__ + ".core.files")
    with files.replacing(job.out / "scene.blend") as tmp:  # never half-written
        bpy.ops.wm.save_as_mainfile(filepath=str(tmp), copy=True)
    report["out"] = str(job.out)
    return report


def _one_line(error) -> str:
    """The first line of an error's message (a file error names the file)."""
    text = str(error).strip()
    return text.splitlines()[0] if text else type(error).__name__


def _operator_message(error) -> str:
    lines = [ln.strip() for ln in str(error).splitlines() if ln.strip()]
    for line in lines:
        if line.lower().startswith("error:"):
            return line[6:].strip()
    return lines[0] if lines else "the reconstruction failed"


if __name__ == "__main__":
    sys.exit(main())
