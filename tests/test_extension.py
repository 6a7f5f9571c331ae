"""The built extension zip installs into pip ``bpy`` through Blender's own extension system.

`scripts/build_extension.py` (what `make extension` runs) builds the linux-x64
zip with the cp311 wheels only; Blender's ``blender_ext.py validate`` accepts
it. A fresh Python process with the venv's ``bpy`` and a throw-away user
folder (``BLENDER_USER_RESOURCES``, ``HOME``) then installs it with
``bpy.ops.extensions.package_install_files`` into the ``user_default``
repository, which enables it as ``bl_ext.user_default.brdf_reconstruct``.
The venv's own scipy and pycolmap are hidden from that process, so the
bundled wheels must be what gets imported, and ``brdf.import_colmap`` runs on
a small synthetic COLMAP model: relative imports work inside ``bl_ext.*`` and
the bundled pycolmap reads the model.

The Blender route of the batch entry (``blender --background --python
<extension>/brdf_addon/batch.py -- job.toml``) is run the same way: there is no
Blender binary on the test machines, so the installed extension's ``batch.py``
is executed as Blender's ``--python`` executes a file (a new ``__main__``
module with only ``__name__``, ``__file__`` and ``__builtins__``, no package,
Blender's whole command line in ``sys.argv``) inside the process where the
extension is installed and enabled.

Downloaded wheels are cached in .cache/wheels (the first run fetches about
75 MB from PyPI); the test is skipped off linux x86_64, or when PyPI cannot be
reached and the cache lacks the wheels.
"""

import importlib.util
import json
import os
import platform
import subprocess
import sys
import textwrap
import tomllib
import urllib.request
import zipfile
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parent.parent
SCRIPT = REPO / "scripts" / "build_extension.py"
CACHE = REPO / ".cache" / "wheels"
PLATFORM = "linux-x64"
PYTHON = "3.11"

if importlib.util.find_spec("bpy") is None:
    pytest.skip("the pip bpy module is not installed", allow_module_level=True)
if not (sys.platform.startswith("linux") and platform.machine() in ("x86_64", "AMD64")):
    pytest.skip(
        f"installs the linux-x64 zip into this bpy; this is {sys.platform} {platform.machine()}",
        allow_module_level=True,
    )


def _load_script():
    spec = importlib.util.spec_from_file_location("build_extension", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


build_extension = _load_script()
PINS = build_extension.pinned_versions(REPO / "requirements.txt")
SCRIPTS = build_extension.blender_scripts_dir()
BLENDER_EXT = SCRIPTS / "addons_core" / "bl_pkg" / "cli" / "blender_ext.py"
VALID_TAGS = SCRIPTS / "modules" / "_bpy_internal" / "extensions" / "tags.py"
MANIFEST = tomllib.loads((REPO / "blender_manifest.toml").read_text(encoding="utf-8"))
ZIP_NAME = f"{MANIFEST['id']}-{MANIFEST['version']}-{PLATFORM.replace('-', '_')}.zip"
MODULE = f"bl_ext.user_default.{MANIFEST['id']}"


def _wheels_cached() -> bool:
    folder = CACHE / PLATFORM / f"cp{PYTHON.replace('.', '')}"
    return all(build_extension._cached_wheel(folder, n, v) for n, v in PINS.items())


def _pypi_reachable() -> bool:
    try:
        with urllib.request.urlopen("https://pypi.org/simple/pycolmap/", timeout=15) as r:
            return r.status == 200
    except OSError:
        return False


@pytest.fixture(scope="module")
def archive(tmp_path_factory) -> Path:
    if not _wheels_cached() and not _pypi_reachable():
        pytest.skip(f"PyPI cannot be reached and {CACHE} lacks the {PLATFORM} cp311 wheels")
    out = tmp_path_factory.mktemp("dist")
    result = subprocess.run(
        [
            sys.executable, str(SCRIPT),
            "--platforms", PLATFORM, "--pythons", PYTHON,
            "--cache-dir", str(CACHE), "--output-dir", str(out), "--strict",
        ],
        capture_output=True, text=True, timeout=900,
    )  # fmt: skip
    assert result.returncode == 0, result.stdout + result.stderr
    assert [p.name for p in out.glob("*.zip")] == [ZIP_NAME], result.stdout
    return out / ZIP_NAME


def test_zip_is_valid_and_bundles_only_this_platform(archive):
    result = subprocess.run(
        [sys.executable, str(BLENDER_EXT), "validate", "--valid-tags", str(VALID_TAGS),
         str(archive)],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert result.returncode == 0, result.stdout + result.stderr

    with zipfile.ZipFile(archive) as zf:
        names = zf.namelist()
        manifest = tomllib.loads(zf.read("blender_manifest.toml").decode("utf-8"))
    wheels = sorted(n for n in names if n.endswith(".whl"))
    assert [w.split("/")[0] for w in wheels] == ["wheels"] * len(wheels)
    assert sorted(w.split("/")[1].split("-")[0] for w in wheels) == sorted(PINS)
    for w in wheels:
        name, version, py, _abi, plat = Path(w).stem.split("-")
        assert version == PINS[name] and py == "cp311" and plat.endswith("x86_64"), w
    assert not [n for n in names if n.lower().startswith(("wheels/numpy", "wheels/openimageio"))]
    assert manifest["platforms"] == [PLATFORM]
    assert manifest["build"]["generated"]["platforms"] == [PLATFORM]
    assert sorted(manifest["wheels"]) == [f"./{w}" for w in wheels]
    assert "__init__.py" in names and "operators/import_colmap.py" in names
    leaked = ("tests/", "bench/", "testkit/", "docs/", "scripts/", "dist/", ".cache/", ".venv/")
    assert not [n for n in names if n.startswith(leaked) or "__pycache__/" in n]
    # only what the installed extension needs: the code, the manifest, the wheels
    # (and a license file if the repository gets one); never the developers'
    # README, requirements*.txt, Makefile or pyproject.toml
    files = {n for n in names if not n.endswith("/")}
    assert files - set(wheels) == _shipped_files(), sorted(files ^ _shipped_files())


def _shipped_files() -> set[str]:
    """What the zip must hold besides its wheels, from the repository as it is: every
    file of the add-on's three code folders (no caches, no dot-files), the root
    ``__init__.py``, the manifest and a license file if there is one."""
    found = {"__init__.py", "blender_manifest.toml"}
    found |= {p.name for p in REPO.glob("LICENSE*") if p.is_file()}
    for folder in ("brdf_addon", "core", "operators"):
        for path in (REPO / folder).rglob("*"):
            rel = path.relative_to(REPO)
            if path.is_file() and not any(part == "__pycache__" or part.startswith(".")
                                          for part in rel.parts):
                found.add(rel.as_posix())
    return found


# Runs in a fresh interpreter: the venv's scipy/pycolmap are hidden before bpy starts,
# so only the extension's bundled wheels can satisfy those imports.
CHILD = textwrap.dedent(
    """
    import importlib.abc, importlib.machinery, json, os, site, sys

    VENV_SITE = {os.path.realpath(p) for p in site.getsitepackages()}
    HIDDEN = {"scipy", "pycolmap"}

    class HideVenvCopies(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            if path is not None or name not in HIDDEN:
                return None
            paths = [p for p in sys.path if os.path.realpath(p or ".") not in VENV_SITE]
            spec = importlib.machinery.PathFinder.find_spec(name, paths)
            if spec is None:
                raise ModuleNotFoundError(f"{name} (the venv's copy is hidden)", name=name)
            return spec

    sys.meta_path.insert(0, HideVenvCopies())

    import bpy  # first: bpy puts addon_utils on sys.path
    import addon_utils

    zip_path, model_dir, module = sys.argv[1:4]
    out = {"repos": [r.module for r in bpy.context.preferences.extensions.repos]}
    out["install"] = sorted(bpy.ops.extensions.package_install_files(
        filepath=zip_path, repo="user_default", enable_on_install=True))
    out["addons"] = sorted(bpy.context.preferences.addons.keys())
    out["loaded"] = list(addon_utils.check(module))
    out["module_file"] = sys.modules[module].__file__
    out["ext_dir"] = bpy.utils.user_resource("EXTENSIONS")

    bpy.ops.wm.read_homefile(use_empty=True)
    out["import"] = sorted(bpy.ops.brdf.import_colmap(directory=model_dir))
    cams = [o for o in bpy.data.objects if o.type == "CAMERA"]
    out["cameras"] = sorted(o["brdf_image_name"] for o in cams)
    op = bpy.types.Operator.bl_rna_get_subclass_py("BRDF_OT_import_colmap")
    out["operator_module"] = op.__module__

    import pycolmap, scipy, scipy.linalg
    out["pycolmap"] = [pycolmap.__version__, pycolmap.__file__]
    out["scipy"] = [scipy.__version__, scipy.__file__]
    out["dev_package_imported"] = "brdf_reconstruct" in sys.modules
    import importlib
    prefs = importlib.import_module(module + ".brdf_addon.prefs")
    out["prefs_registered"] = type(prefs.get()).__name__
    out["cache_dir"] = str(prefs.cache_dir())
    print("RESULT " + json.dumps(out))
    """
)


@pytest.fixture(scope="module")
def colmap_model(tmp_path_factory) -> Path:
    pytest.importorskip("pycolmap")
    from brdf_reconstruct.core.capture import cameras as camconv
    from testkit import synthetic

    views = [
        ("left.jpg", "PINHOLE", [500, 500, 320, 240], 640, 480,
         *camconv.look_at([3, -1, 1], [0, 0, 0])),
        ("right.jpg", "SIMPLE_PINHOLE", [600, 400, 300], 800, 600,
         *camconv.look_at([-2, -3, 1.5], [0, 0, 0])),
    ]  # fmt: skip
    xyz = np.random.default_rng(0).uniform(-0.5, 0.5, (50, 3))
    model = tmp_path_factory.mktemp("colmap") / "sparse"
    model.mkdir()
    synthetic.synthetic_reconstruction(views, xyz).write(str(model))
    return model


def test_install_enable_and_run_operator(archive, colmap_model, tmp_path):
    home = tmp_path / "home"
    home.mkdir()
    user = tmp_path / "blender_user"
    env = {
        k: v for k, v in os.environ.items() if not k.startswith(("BLENDER_USER_", "PYTHON", "XDG_"))
    }
    env.update(
        HOME=str(home),  # anything still aimed at ~ lands here, never in the real ~/.config
        BLENDER_USER_RESOURCES=str(user),  # pip bpy: config, scripts, extensions under here
        BRDF_RECONSTRUCT_CACHE=str(tmp_path / "cache"),
    )
    script = tmp_path / "child.py"
    script.write_text(CHILD, encoding="utf-8")
    result = subprocess.run(
        [sys.executable, "-s", str(script), str(archive), str(colmap_model), MODULE],
        capture_output=True, text=True, timeout=600, env=env, cwd=tmp_path,
    )  # fmt: skip
    log = result.stdout + result.stderr
    assert result.returncode == 0, log
    lines = [ln for ln in result.stdout.splitlines() if ln.startswith("RESULT ")]
    assert lines, log
    out = json.loads(lines[-1][len("RESULT ") :])

    ext_dir = user / "extensions"
    assert Path(out["ext_dir"]).resolve() == ext_dir.resolve(), out
    assert "user_default" in out["repos"], out
    assert out["install"] == ["FINISHED"], log
    assert MODULE in out["addons"], out
    assert out["loaded"] == [True, True], out  # enabled by default and loaded
    installed = ext_dir / "user_default" / MANIFEST["id"]
    assert Path(out["module_file"]).resolve() == (installed / "__init__.py").resolve()
    assert out["operator_module"] == f"{MODULE}.operators.import_colmap"
    assert not out["dev_package_imported"]  # the repo's editable package was never used

    assert out["import"] == ["FINISHED"], log
    assert out["cameras"] == ["left.jpg", "right.jpg"]
    # preferences exist once installed, and the cache goes to the extension's user
    # folder, never into the extension's own folder
    assert out["prefs_registered"] == "BRDFPreferences"
    cache = Path(out["cache_dir"]).resolve()
    assert cache.is_relative_to(ext_dir.resolve()) and not cache.is_relative_to(installed)

    site_packages = ext_dir / ".local" / "lib" / "python3.11" / "site-packages"
    for name in ("pycolmap", "scipy"):
        version, path = out[name]
        assert version == PINS[name]
        assert Path(path).resolve().is_relative_to(site_packages.resolve()), (name, path)
    print("bundled pycolmap:", out["pycolmap"][1])

    assert not (home / ".config").exists(), sorted(p.name for p in home.iterdir())


# The batch entry as `blender --background --python <extension>/brdf_addon/batch.py --
# job.toml` runs it, in a fresh interpreter where the zip is installed and enabled
# (venv copies of scipy, pycolmap and the repository's own package hidden, as they
# are in Blender). Blender's --python (PyC_DefaultNameSpace, then running the file)
# makes a NEW module "__main__" holding only __name__, __file__ and __builtins__ (no
# __package__, __spec__ or sys.path entry for the script), executes the file in it,
# with sys.argv Blender's whole command line; SystemExit ends Blender with its code.
BATCH_CHILD = textwrap.dedent(
    """
    import builtins, importlib, importlib.abc, importlib.machinery, json, os, site, sys
    import types

    VENV_SITE = {os.path.realpath(p) for p in site.getsitepackages()}
    HIDDEN = {"scipy", "pycolmap", "brdf_reconstruct", "testkit"}

    class HideVenvCopies(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            if path is not None or name not in HIDDEN:
                return None
            paths = [p for p in sys.path if os.path.realpath(p or ".") not in VENV_SITE]
            spec = importlib.machinery.PathFinder.find_spec(name, paths)
            if spec is None:
                raise ModuleNotFoundError(f"{name} (the venv's copy is hidden)", name=name)
            return spec

    sys.meta_path.insert(0, HideVenvCopies())

    import bpy
    import addon_utils

    zip_path, job, module, pref_cache = sys.argv[1:5]
    bpy.ops.extensions.package_install_files(
        filepath=zip_path, repo="user_default", enable_on_install=True)
    prefs = bpy.context.preferences
    prefs.addons[module].preferences.cache_folder = pref_cache  # the user's preference
    out = {"addons_before": sorted(prefs.addons.keys()),
           "repos_before": [(r.module, r.directory, r.enabled) for r in prefs.extensions.repos],
           "scipy_before": "scipy" in sys.modules, "pycolmap_before": "pycolmap" in sys.modules}
    path_before = list(sys.path)

    # which basis cache files the run reads, and whether it builds (saves) one
    basis = importlib.import_module(module + ".core.brdf.basis")
    read, built = [], []
    load, save = basis.load, basis.save

    def spy_load(path, *args, **kwargs):
        read.append(os.path.realpath(os.path.dirname(os.path.abspath(path))))
        return load(path, *args, **kwargs)

    def spy_save(value, path, *args, **kwargs):
        built.append(os.fspath(path))
        return save(value, path, *args, **kwargs)

    basis.load, basis.save = spy_load, spy_save

    script = os.path.join(os.path.dirname(sys.modules[module].__file__), "brdf_addon",
                          "batch.py")
    argv, main_before = sys.argv, sys.modules["__main__"]
    sys.argv = ["blender", "--background", "--python", script, "--", job]
    main = types.ModuleType("__main__")  # as PyModule_New: __package__, __spec__ None
    main.__file__, main.__builtins__ = script, builtins
    sys.modules["__main__"] = main
    try:
        with open(script, "rb") as f:
            exec(compile(f.read(), script, "exec"), main.__dict__)
        out["exit"] = 0
    except SystemExit as stop:
        out["exit"] = stop.code
    finally:
        sys.modules["__main__"], sys.argv = main_before, argv

    out["addons_after"] = sorted(prefs.addons.keys())
    out["repos_after"] = [(r.module, r.directory, r.enabled) for r in prefs.extensions.repos]
    out["loaded_after"] = list(addon_utils.check(module))
    out["cache_folder_after"] = prefs.addons[module].preferences.cache_folder
    out["path_lost"] = [p for p in path_before if p not in sys.path]
    out["read"], out["built"] = read, built
    out["top_level"] = sorted(n for n in sys.modules
                              if n == "brdf_reconstruct" or n.startswith("brdf_reconstruct."))
    out["pycolmap"] = getattr(sys.modules.get("pycolmap"), "__file__", None)
    op = bpy.types.Operator.bl_rna_get_subclass_py("BRDF_OT_reconstruct")
    out["operator_module"] = op.__module__
    print("RESULT " + json.dumps(out))
    """
)


@pytest.fixture(scope="module")
def no_blend_job(tmp_path_factory) -> Path:
    """A tiny job without a .blend: the sphere scan of ``testkit.blender_scene`` as
    ``scan.ply``, its camera as a COLMAP model, and a photo rendered through the
    camera that model imports; the light a direction, the irradiance the Sun's."""
    bpy = pytest.importorskip("bpy")
    pytest.importorskip("pycolmap")
    from brdf_reconstruct.brdf_addon import colmap_import
    from brdf_reconstruct.core.capture import cameras as camconv
    from testkit import blender_scene as BS
    from testkit import synthetic

    folder = tmp_path_factory.mktemp("no_blend_job")
    built = BS.build(folder, photo=False)
    scene, scan = built["scene"], built["scan"]
    focal = 50.0 / 36.0 * BS.SIZE  # the test scene's 50 mm lens on a 36 mm sensor
    pose = camconv.look_at(tuple(built["camera"].location), (0.0, 0.0, 0.0))
    views = [(BS.IMAGE_NAME, "PINHOLE", [focal, focal, BS.SIZE / 2, BS.SIZE / 2],
              BS.SIZE, BS.SIZE, *pose)]
    co = np.zeros(len(scan.data.vertices) * 3)
    scan.data.vertices.foreach_get("co", co)
    (folder / "sparse").mkdir()
    synthetic.synthetic_reconstruction(views, co.reshape(-1, 3)).write(str(folder / "sparse"))
    bpy.data.objects.remove(built["camera"])
    scene.camera = None  # the imported camera becomes the scene's, with its render size
    colmap_import.import_cameras(scene, str(folder / "sparse"))
    BS.render_photo(scene, folder / "view0.exr")
    bpy.ops.object.select_all(action="DESELECT")
    scan.select_set(True)
    bpy.context.view_layer.objects.active = scan
    bpy.ops.wm.ply_export(filepath=str(folder / "scan.ply"), export_selected_objects=True,
                          export_normals=True)
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    job = folder / "job.toml"
    job.write_text(textwrap.dedent(f"""\
        mesh = "scan.ply"
        colmap = "sparse"
        out = "out"

        [settings]
        curvature_threshold = 1.5
        samples = 12
        trials = 2
        seed = 4

        [[photo]]
        image = "view0.exr"
        camera = "{BS.IMAGE_NAME}"
        light = {[float(x) for x in BS.LIGHT]}
        irradiance = {BS.lit_irradiance()}
        """))
    return job


def test_blender_python_route_runs_the_installed_extension(archive, no_blend_job,
                                                           measured_basis, tmp_path):
    """`blender --background --python <installed>/brdf_addon/batch.py -- job.toml` on a
    job without a .blend (emulated: no Blender binary here, see the module's
    docstring): exit 0 with the outputs; the extension, its repositories and its
    wheels' path untouched by the run's new empty file (read_factory_settings used to
    reset the preferences and lose the bundled pycolmap); the batch used the enabled
    extension itself, so the user's preference (cache folder) holds and no second,
    top-level copy of the package is imported; the basis read from that folder."""
    home, user = tmp_path / "home", tmp_path / "blender_user"
    home.mkdir()
    pref_cache, env_cache = tmp_path / "pref_cache", tmp_path / "env_cache"
    pref_cache.mkdir()
    # the product's default basis, measured (basis._cached's file name)
    name = f"basis-{measured_basis.fingerprint[:24]}.npz"
    (pref_cache / name).symlink_to(Path(os.environ["BRDF_RECONSTRUCT_CACHE"]) / name)
    env = {
        k: v for k, v in os.environ.items() if not k.startswith(("BLENDER_USER_", "PYTHON", "XDG_"))
    }
    env.update(HOME=str(home), BLENDER_USER_RESOURCES=str(user),
               BRDF_RECONSTRUCT_CACHE=str(env_cache))  # must not be used: the preference is
    script = tmp_path / "batch_child.py"
    script.write_text(BATCH_CHILD, encoding="utf-8")
    result = subprocess.run(
        [sys.executable, "-s", str(script), str(archive), str(no_blend_job), MODULE,
         str(pref_cache)],
        capture_output=True, text=True, timeout=900, env=env, cwd=tmp_path,
    )  # fmt: skip
    log = result.stdout + result.stderr
    assert result.returncode == 0, log
    lines = [ln for ln in result.stdout.splitlines() if ln.startswith("RESULT ")]
    assert lines, log
    out = json.loads(lines[-1][len("RESULT ") :])

    assert out["exit"] == 0, log
    assert "done: 1 region(s) reconstructed" in result.stdout, log
    folder = no_blend_job.parent / "out"
    assert {"brdf_0.binary", "report.json", "scene.blend"} <= {p.name for p in folder.iterdir()}
    report = json.loads((folder / "report.json").read_text())
    assert [r["status"] for r in report["regions"]] == ["ok"]

    # the preferences, the extension and its wheels survive the run's empty file
    assert MODULE in out["addons_before"]
    assert out["addons_after"] == out["addons_before"]
    assert out["repos_after"] == out["repos_before"]
    assert out["loaded_after"] == [True, True]
    assert out["cache_folder_after"] == str(pref_cache)
    assert out["path_lost"] == []
    site_packages = user / "extensions" / ".local" / "lib" / "python3.11" / "site-packages"
    assert not out["pycolmap_before"]  # first imported during the run, after the reset
    assert Path(out["pycolmap"]).resolve().is_relative_to(site_packages.resolve())

    # the enabled extension ran: no second copy, its operator, its preferences
    assert out["top_level"] == []
    assert out["operator_module"] == f"{MODULE}.operators.reconstruct"
    assert out["read"] and set(out["read"]) == {str(pref_cache.resolve())}, out["read"]
    assert out["built"] == []  # read, not rebuilt
    assert not env_cache.exists() and not (home / ".cache" / "brdf_reconstruct").exists()
