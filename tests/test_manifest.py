"""blender_manifest.toml passes Blender's own extension validator and builds cleanly."""

import re
import subprocess
import sys
import tomllib
import urllib.parse
import zipfile
from pathlib import Path

import pytest

bpy = pytest.importorskip("bpy")

REPO = Path(__file__).resolve().parent.parent
MANIFEST = REPO / "blender_manifest.toml"


def _scripts_dir() -> Path:
    # bpy/<major.minor>/scripts: found through the installed bpy, never a venv path.
    return Path(bpy.utils.system_resource("SCRIPTS"))


def _blender_ext() -> Path:
    path = _scripts_dir() / "addons_core" / "bl_pkg" / "cli" / "blender_ext.py"
    assert path.is_file(), path
    return path


def _valid_tags() -> Path:
    # `blender --command extension validate` checks tags against this list by default;
    # the bare CLI only does when given --valid-tags.
    path = _scripts_dir() / "modules" / "_bpy_internal" / "extensions" / "tags.py"
    assert path.is_file(), path
    return path


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, str(_blender_ext()), *args],
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_manifest_identity():
    manifest = tomllib.loads(MANIFEST.read_text(encoding="utf-8"))
    assert manifest["id"] == "brdf_reconstruct"
    assert manifest["type"] == "add-on"
    assert manifest["schema_version"] == "1.0.0"


def test_maintainer_and_website_are_well_formed():
    """The extension's page names who answers for it and where it lives: maintainer
    as "Name <e-mail>" (Blender's convention), website an http(s) URL with a host."""
    manifest = tomllib.loads(MANIFEST.read_text(encoding="utf-8"))
    match = re.fullmatch(r"(?P<name>\S.*\S) <(?P<email>[^<>@\s]+@[^<>@\s]+\.[^<>@\s]+)>",
                         manifest["maintainer"])
    assert match, manifest["maintainer"]
    url = urllib.parse.urlsplit(manifest["website"])
    assert url.scheme in ("http", "https") and url.netloc, manifest["website"]


def test_validator_accepts_repo():
    result = _run("validate", "--valid-tags", str(_valid_tags()), str(REPO))
    assert result.returncode == 0, result.stdout + result.stderr
    assert "Success" in result.stdout


def test_built_package_is_valid_and_lean(tmp_path):
    result = _run(
        "build",
        "--source-dir", str(REPO),
        "--output-dir", str(tmp_path),
        "--valid-tags", str(_valid_tags()),
    )  # fmt: skip
    assert result.returncode == 0, result.stdout + result.stderr
    (archive,) = tmp_path.glob("*.zip")

    result = _run("validate", "--valid-tags", str(_valid_tags()), str(archive))
    assert result.returncode == 0, result.stdout + result.stderr

    with zipfile.ZipFile(archive) as zf:
        names = zf.namelist()
    assert "__init__.py" in names
    assert "brdf_addon/__init__.py" in names
    assert "core/__init__.py" in names
    # the default basis' measured materials and their terms travel with the code
    assert "core/brdf/data/merl_nbrdf.npz" in names
    assert "core/brdf/data/README.md" in names
    excluded = (".venv/", ".git/", ".ci/", "tests/", "bench/", "testkit/", "docs/", "__pycache__/")
    leaked = [n for n in names if any(n.startswith(e) or f"/{e}" in n for e in excluded)]
    assert not leaked, leaked
    assert not [n for n in names if ".egg-info/" in n]
    # the manifest's own patterns keep the developers' root files out too
    root_files = {"README.md", "Makefile", "pyproject.toml", "requirements.txt",
                  "requirements-bench.txt"}
    assert not root_files & set(names), sorted(root_files & set(names))
