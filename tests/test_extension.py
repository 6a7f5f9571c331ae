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
