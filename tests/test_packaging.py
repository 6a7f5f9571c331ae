"""Packaging and the import rule: the science is importable without Blender, and the
extension's zip holds only what an installed extension needs."""

import importlib.util
import subprocess
import sys
import textwrap
import tomllib
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent


def test_core_imports_without_bpy(tmp_path):
    # Run from an unrelated directory so only the editable install can resolve the package.
    code = textwrap.dedent(
        """
        import sys
        import brdf_reconstruct
        import pkgutil, importlib
        import brdf_reconstruct.core as core
        names = [m.name for m in pkgutil.walk_packages(core.__path__, "brdf_reconstruct.core.")]
        for name in names:
            importlib.import_module(name)
        for part in ("brdf", "capture", "method", "bake"):
            assert f"brdf_reconstruct.core.{part}" in names, names
        assert len(names) >= 30, names
        assert callable(brdf_reconstruct.register)
        assert "bpy" not in sys.modules, "importing the package pulled in bpy"
        assert "brdf_reconstruct.brdf_addon" not in sys.modules
        """
    )
    result = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True
    )
    assert result.returncode == 0, result.stderr


def _build_script():
    spec = importlib.util.spec_from_file_location(
        "build_extension", REPO / "scripts" / "build_extension.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _expected_files() -> set[str]:
    """From the repository as it is: every file of the three code folders (no
    caches, no dot-files), the root __init__.py, the manifest, a license file."""
    found = {"__init__.py", "blender_manifest.toml"}
    found |= {p.name for p in REPO.glob("LICENSE*") if p.is_file()}
    for folder in ("brdf_addon", "core", "operators"):
        for path in (REPO / folder).rglob("*"):
            rel = path.relative_to(REPO)
            if path.is_file() and not any(part == "__pycache__" or part.startswith(".")
                                          for part in rel.parts):
                found.add(rel.as_posix())
    return found


def test_zip_holds_only_what_the_installed_extension_needs(tmp_path):
    """scripts/build_extension.py's staging, then Blender's own build of it (what
    `make extension` does, without the wheels, so no network): the zip's names are
    the add-on's code, the manifest and a license file if any; never testkit/,
    tests/, bench/, docs/, scripts/, requirements*.txt, the Makefile, the
    developers' README or pyproject.toml."""
    if importlib.util.find_spec("bpy") is None:
        pytest.skip("Blender's blender_ext.py comes with the pip bpy module")
    build = _build_script()
    manifest = tomllib.loads((REPO / "blender_manifest.toml").read_text(encoding="utf-8"))
    stage = tmp_path / "stage" / manifest["id"]
    build.stage_source(REPO, stage, manifest["build"]["paths_exclude_pattern"])
    scripts = build.blender_scripts_dir()
    (tmp_path / "dist").mkdir()
    result = subprocess.run(
        [sys.executable, str(scripts / "addons_core/bl_pkg/cli/blender_ext.py"), "build",
         "--source-dir", str(stage), "--output-dir", str(tmp_path / "dist"),
         "--valid-tags", str(scripts / "modules/_bpy_internal/extensions/tags.py")],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert result.returncode == 0, result.stdout + result.stderr
    (archive,) = (tmp_path / "dist").glob("*.zip")
    with zipfile.ZipFile(archive) as zf:
        names = {n for n in zf.namelist() if not n.endswith("/")}
    never = ("testkit/", "tests/", "bench/", "docs/", "scripts/", "requirements", "Makefile",
             "README", "pyproject.toml", ".")
    assert not [n for n in names if n.startswith(never)]
    assert names == _expected_files(), sorted(names ^ _expected_files())
