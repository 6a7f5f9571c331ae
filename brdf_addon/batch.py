"""Batch entry: run a job file headless, the same operators as the panel.

    blender --background --python <extension>/brdf_addon/batch.py -- job.toml
    python -m brdf_reconstruct.brdf_addon.batch job.toml

Exit status: 0 on success; 1 with one line "error: ..." on stderr for a bad
job (missing file, unknown camera name, light below the horizon, no reliable
pixels, ...); 2 for a wrong command line. Outputs go to the job's ``out``
folder: ``brdf_<region>.binary``, ``report.json``, pictures, and ``scene.blend``
(a copy: the job's own .blend is never written).

Run by Blender, the script uses the installed, enabled extension
(``bl_ext.<repo>.brdf_reconstruct``), so the user's preferences hold; a job
without a .blend starts from Blender's empty factory startup file without
resetting the preferences (see :func:`_import_package`, :func:`run_job`).
"""

from __future__ import annotations

import pathlib
import sys


def _args(argv):
    if "--" in argv:
        argv = argv[argv.index("--") + 1:]
    return argv


PACKAGE_ID = "brdf_reconstruct"  # the manifest's id: the installed extension's folder


def _import_package():
    """The add-on package this batch entry belongs to (never a second copy of it).

    - Imported, or run by ``python -m brdf_reconstruct.brdf_addon.batch``: its own
      package.
    - Run as a script by ``blender --python <extension>/brdf_addon/batch.py`` (a
      ``__main__`` module without a package): the ENABLED extension
      ``bl_ext.<repo>.brdf_reconstruct``, the one in this script's folder first, so
      its preferences (device, database, cache folder) hold and its classes are
      not registered twice. This script's extension installed but disabled is a
      ValueError (one sentence).
    - Neither (a checkout run by Blender, not installed): ``brdf_reconstruct`` from
      ``pip install -e``, else the checkout's folder imported by its name.
    """
    import importlib

    package = globals().get("__package__")
    if package:
        return importlib.import_module(package.rpartition(".")[0])
    root = pathlib.Path(__file__).resolve().parent.parent
    installed = _enabled_extension(root)
    if installed is not None:
        return installed
    try:
        import brdf_reconstruct as package  # pip install -e / tests
    except ImportError:
        sys.path.insert(0, str(root.parent))
        package = importlib.import_module(root.name)
    return package


def _enabled_extension(root: pathlib.Path):
    """The enabled extension module whose folder is ``root``, else any enabled
    ``bl_ext.*.brdf_reconstruct`` (its operators are the ones Blender runs), else
    None; ValueError when ``root`` is an installed extension that is not enabled."""
    import importlib

    import bpy

    preferences = bpy.context.preferences
    names = [name for name in preferences.addons.keys()
             if name.startswith("bl_ext.") and name.endswith("." + PACKAGE_ID)]

    def folder(name):
        module = sys.modules.get(name)
        path = getattr(module, "__file__", None)
        return pathlib.Path(path).resolve().parent if path else None

    names.sort(key=lambda name: folder(name) != root)  # this script's own first
    if names and folder(names[0]) == root:
        return sys.modules[names[0]]
    for repo in preferences.extensions.repos:
        if repo.enabled and repo.directory and (
                pathlib.Path(repo.directory).resolve() == root.parent):
            name = f"bl_ext.{repo.module}.{root.name}"
            raise ValueError(f"the extension {name} is installed but not enabled: enable "
                             "BRDF Reconstruct in Preferences > Add-ons, or give Blender "
                             f"--addons {name} before --python")
    return importlib.import_module(names[0]) if names else None


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
        try:
            bpy.ops.wm.open_mainfile(filepath=str(job.blend))
        except RuntimeError as error:  # a damaged file that passed load()'s header check
            raise ValueError(f"blend {job.blend.name} could not be opened "
                             f"({_operator_message(error)}): save the scene again") from None
    else:
        # the factory startup file, emptied. Never read_factory_settings: it also resets
        # the preferences, which disables the installed extension and drops its
        # bundled wheels' site-packages from sys.path (issue 13)
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    if not hasattr(bpy.types.Scene, "brdf"):
        package.register()
    scene = bpy.context.scene
    try:
        job_mod.apply(job, scene)
    except RuntimeError as error:  # an operator's report (apply names a mesh it refused)
        raise ValueError(f"the job could not be set up: {_operator_message(error)}") from None
    runner = import_module(package.__name__ + ".brdf_addon.runner")
    with runner.sigint_recorded():  # a Ctrl+C that Python swallows still ends the run
        try:
            bpy.ops.brdf.reconstruct()
        except RuntimeError as error:  # the operator's one-line report
            message = _operator_message(error)
            if message.startswith(runner.INTERRUPTED):
                raise KeyboardInterrupt from None
            raise ValueError(message) from None
        runner.check_interrupt()  # one swallowed while the results were written
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
