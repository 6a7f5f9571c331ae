#!/usr/bin/env python3
"""Build installable per-platform extension zips with bundled scipy and pycolmap wheels.

    .venv/bin/python scripts/build_extension.py            # what `make extension` runs
    .venv/bin/python scripts/build_extension.py --platforms linux-x64 --pythons 3.11

Steps:
1. Fetch the wheels of the packages pinned in requirements.txt (scipy, pycolmap)
   for every requested platform and Python with ``pip download --only-binary=:all:
   --no-deps``, into a cache (default ``.cache/wheels``, git-ignored) that later
   runs reuse without the network. numpy and OpenImageIO ship with Blender and
   are never bundled. A pinned version without a wheel for a platform/Python is
   reported (never replaced by another version) and that Python is left out of
   that platform's zip.
2. Copy what an installed extension needs, and only that (:data:`SHIPPED`: the
   root ``__init__.py``, the manifest, ``brdf_addon/``, ``core/``, ``operators/``,
   a license file if the repository has one; never tests, benches, ``testkit/``,
   docs, scripts, the developers' README, ``requirements*.txt``, Makefile or
   ``pyproject.toml``), minus the manifest's ``[build] paths_exclude_pattern``
   inside those (caches, dot-files), to a temporary staging folder; put the
   wheels in ``wheels/`` there and write ``wheels = [...]`` and
   ``platforms = [...]`` into the STAGED manifest; the committed manifest stays
   wheel-free for development.
3. Run Blender's own ``blender_ext.py build --split-platforms`` (from the pip
   ``bpy`` wheel, or ``--blender-ext``) into ``dist/``, then
   ``blender_ext.py validate`` on every zip. Blender names them
   ``<id>-<version>-<platform>.zip``, e.g. ``brdf_reconstruct-0.1.0-linux_x64.zip``.

Exit status: 0 when every requested zip was built and validated (missing wheels
are reported but are not an error unless ``--strict``), 1 otherwise.
"""

from __future__ import annotations

import argparse
import fnmatch
import importlib.util
import os
import re
import shutil
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
MANIFEST = "blender_manifest.toml"
STAGE_MARKER = ".brdf_extension_stage"

# What the zip holds from the source tree (an allow-list: a new file at the root is
# left out until it is added here), and license files if there are any.
SHIPPED = ("__init__.py", MANIFEST, "brdf_addon", "core", "operators")
SHIPPED_GLOBS = ("LICENSE*", "COPYING*")

# Packages bundled as wheels; their versions come from requirements.txt.
BUNDLED = ("scipy", "pycolmap")
# Blender ships these; bundling them would shadow Blender's own copies.
NEVER_BUNDLED = ("numpy", "openimageio")

# Blender platform -> the pip `--platform` tag to download for. pip also accepts
# wheels for older glibc / macOS versions than the one given here.
# - linux: glibc 2.28 is the floor of Blender 4.2+ official builds.
# - macOS: pycolmap 4.2.1 only has macosx_14_0_arm64 wheels, so the extension
#   needs macOS 14 on Apple silicon; scipy then gets its macOS 14 (Accelerate) wheel.
PLATFORM_TAGS = {
    "linux-x64": "manylinux_2_28_x86_64",
    "windows-x64": "win_amd64",
    "macos-arm64": "macosx_14_0_arm64",
}
# Python 3.11: Blender 4.2-5.0; Python 3.13: Blender 5.1.
DEFAULT_PYTHONS = ("3.11", "3.13")


def log(msg: str) -> None:
    print(msg, flush=True)


def pinned_versions(requirements: Path, names=BUNDLED) -> dict[str, str]:
    """{name: version} for `name==version` lines of requirements.txt (every name must be pinned)."""
    pins = {}
    for line in requirements.read_text(encoding="utf-8").splitlines():
        m = re.match(r"^\s*([A-Za-z0-9_.\-]+)\s*==\s*([^\s;#]+)", line)
        if m:
            pins[m.group(1).lower().replace("_", "-")] = m.group(2)
    missing = [n for n in names if n not in pins]
    if missing:
        raise SystemExit(f"error: {requirements} pins no exact version (==) for {missing}")
    return {n: pins[n] for n in names}


def _cp(python: str) -> str:
    major, minor = python.split(".")
    return f"cp{major}{minor}"


def _cached_wheel(folder: Path, name: str, version: str) -> Path | None:
    found = sorted(folder.glob(f"{name}-{version}-*.whl")) if folder.is_dir() else []
    return found[0] if found else None


def fetch_wheel(
    name: str, version: str, platform: str, python: str, cache: Path, *, offline: bool
) -> tuple[Path | None, str]:
    """The wheel of `name==version` for a Blender platform and Python "3.x", cached.

    Returns (path, "") or (None, reason). The cache has one folder per
    platform/python, so a cached wheel is found without asking pip.
    """
    folder = cache / platform / _cp(python)
    if (hit := _cached_wheel(folder, name, version)) is not None:
        return hit, ""
    if offline:
        return None, f"not in the cache {folder} (offline)"
    folder.mkdir(parents=True, exist_ok=True)
    cmd = [
        sys.executable, "-m", "pip", "download", "--disable-pip-version-check",
        "--only-binary=:all:", "--no-deps",
        "--platform", PLATFORM_TAGS[platform],
        "--python-version", python,
        "--implementation", "cp",
        "-d", str(folder),
        f"{name}=={version}",
    ]  # fmt: skip
    log(f"  downloading {name}=={version} for {platform} / Python {python}")
    result = subprocess.run(cmd, capture_output=True, text=True)
    if result.returncode != 0:
        lines = [ln for ln in result.stderr.splitlines() if ln.startswith("ERROR")]
        return None, " / ".join(lines) or result.stderr.strip()[-400:]
    if (hit := _cached_wheel(folder, name, version)) is None:
        return None, f"pip reported success but no {name}-{version} wheel is in {folder}"
    return hit, ""


def _exclude_matcher(patterns: list[str]):
    """A subset of gitignore matching, enough to keep big folders out of staging.

    blender_ext.py applies the full patterns again when it builds.
    """
    rules = []
    for p in patterns:
        anchored = p.startswith("/")
        dir_only = p.endswith("/")
        rules.append((p.strip("/"), anchored, dir_only))

    def excluded(rel: str, is_dir: bool) -> bool:
        name = rel.rsplit("/", 1)[-1]
        for pat, anchored, dir_only in rules:
            if dir_only and not is_dir:
                continue
            if anchored and fnmatch.fnmatchcase(rel, pat):
                return True
            if not anchored and "/" not in pat and fnmatch.fnmatchcase(name, pat):
                return True
        return False

    return excluded


def shipped_paths(src: Path) -> list[Path]:
    """The files and folders of ``src`` that go into the zip (:data:`SHIPPED`, then
    any license file); SystemExit when one of :data:`SHIPPED` is missing."""
    missing = [name for name in SHIPPED if not (src / name).exists()]
    if missing:
        raise SystemExit(f"error: {src} has no {', '.join(missing)}: not an extension source")
    licenses = sorted({p for pattern in SHIPPED_GLOBS for p in src.glob(pattern) if p.is_file()})
    return [src / name for name in SHIPPED] + licenses


def stage_source(src: Path, dst: Path, patterns: list[str]) -> None:
    """Copy :func:`shipped_paths` of ``src`` into the new folder ``dst``, leaving out
    what ``patterns`` (the manifest's ``paths_exclude_pattern``) match inside them."""
    excluded = _exclude_matcher(patterns)

    def ignore(dirpath: str, names: list[str]) -> list[str]:
        rel_dir = Path(dirpath).relative_to(src).as_posix()
        prefix = "" if rel_dir == "." else rel_dir + "/"
        return [n for n in names if excluded(prefix + n, os.path.isdir(os.path.join(dirpath, n)))]

    dst.mkdir(parents=True)
    for path in shipped_paths(src):
        if path.is_dir():
            shutil.copytree(path, dst / path.name, ignore=ignore, symlinks=False)
        else:
            shutil.copy2(path, dst / path.name)


def _toml_str_list(values: list[str]) -> str:
    if not values:
        return "[]"
    return "[\n" + "".join(f'  "{v}",\n' for v in values) + "]"


def write_staged_manifest(path: Path, wheels: list[str], platforms: list[str]) -> None:
    """Add top-level `wheels` and `platforms` keys before the first [table] of the manifest."""
    lines = path.read_text(encoding="utf-8").splitlines()
    lines = [ln for ln in lines if not re.match(r"^\s*(wheels|platforms)\s*=", ln)]
    first_table = next((i for i, ln in enumerate(lines) if ln.lstrip().startswith("[")), len(lines))
    block = [
        "# Added by scripts/build_extension.py (staged copy only).",
        f"wheels = {_toml_str_list(wheels)}",
        f"platforms = {_toml_str_list(platforms)}",
        "",
    ]
    lines[first_table:first_table] = block
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    data = tomllib.loads(path.read_text(encoding="utf-8"))
    assert data["wheels"] == wheels and data["platforms"] == platforms, "manifest edit failed"


def blender_scripts_dir() -> Path:
    """bpy/<major.minor>/scripts of the installed pip `bpy`, found without importing bpy."""
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        raise SystemExit(
            "error: the pip `bpy` module is not installed (run `make venv`), or pass --blender-ext"
        )
    for location in spec.submodule_search_locations:
        found = sorted(Path(location).glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
        if found:
            return found[-1].parents[3]
    raise SystemExit("error: blender_ext.py not found in the pip `bpy` package")


def run_blender_ext(blender_ext: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(blender_ext), *args], capture_output=True, text=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--platforms", default=",".join(PLATFORM_TAGS),
        help=f"comma-separated Blender platforms (default: {','.join(PLATFORM_TAGS)})",
    )  # fmt: skip
    parser.add_argument(
        "--pythons", default=",".join(DEFAULT_PYTHONS),
        help="comma-separated Python versions to bundle wheels for "
        f"(default: {','.join(DEFAULT_PYTHONS)})",
    )  # fmt: skip
    parser.add_argument("--source-dir", type=Path, default=ROOT)
    parser.add_argument("--output-dir", type=Path, default=ROOT / "dist")
    parser.add_argument(
        "--cache-dir", type=Path, default=ROOT / ".cache" / "wheels",
        help="downloaded wheels, reused across runs (default: .cache/wheels)",
    )  # fmt: skip
    parser.add_argument("--requirements", type=Path, default=ROOT / "requirements.txt")
    parser.add_argument(
        "--offline", action="store_true", help="use only cached wheels, never call pip"
    )
    parser.add_argument(
        "--strict", action="store_true",
        help="fail when a pinned version has no wheel for a requested platform/Python",
    )  # fmt: skip
    parser.add_argument(
        "--blender-ext", type=Path, default=None,
        help="path to Blender's blender_ext.py (default: from the pip bpy package)",
    )  # fmt: skip
    parser.add_argument(
        "--staging-dir", type=Path, default=None,
        help="stage here and keep it (default: a temporary folder, removed afterwards)",
    )  # fmt: skip
    args = parser.parse_args(argv)

    platforms = [p.strip() for p in args.platforms.split(",") if p.strip()]
    pythons = [p.strip() for p in args.pythons.split(",") if p.strip()]
    unknown = [p for p in platforms if p not in PLATFORM_TAGS]
    if unknown or not platforms:
        parser.error(f"unknown platform(s) {unknown}; choose from {list(PLATFORM_TAGS)}")
    bad_py = [p for p in pythons if not re.fullmatch(r"3\.\d+", p)]
    if bad_py or not pythons:
        parser.error(f"Python versions look like 3.11, got {pythons}")

    src = args.source_dir.resolve()
    manifest = tomllib.loads((src / MANIFEST).read_text(encoding="utf-8"))
    pins = pinned_versions(args.requirements)
    if args.blender_ext is not None:
        blender_ext = args.blender_ext.resolve()
        valid_tags = blender_ext.parents[3] / "modules/_bpy_internal/extensions/tags.py"
    else:
        scripts = blender_scripts_dir()
        blender_ext = scripts / "addons_core/bl_pkg/cli/blender_ext.py"
        valid_tags = scripts / "modules/_bpy_internal/extensions/tags.py"
    valid_tags_args = ["--valid-tags", str(valid_tags)] if valid_tags.is_file() else []

    log(
        f"bundling {', '.join(f'{n}=={v}' for n, v in pins.items())} "
        f"(never {', '.join(NEVER_BUNDLED)}: Blender ships them)"
    )
    log(f"platforms: {', '.join(platforms)}; Pythons: {', '.join(pythons)}")

    wheels: dict[str, list[Path]] = {p: [] for p in platforms}
    missing: list[str] = []
    for platform in platforms:
        for python in pythons:
            got, why = {}, {}
            for name, version in pins.items():
                path, reason = fetch_wheel(
                    name, version, platform, python, args.cache_dir, offline=args.offline
                )
                if path is None:
                    why[name] = reason
                else:
                    got[name] = path
            if why:
                # Half a set is no use: the add-on needs both, so leave this Python out.
                for name, reason in why.items():
                    missing.append(
                        f"{name}=={pins[name]} has no wheel for {platform} / Python {python} "
                        f"({PLATFORM_TAGS[platform]}): {reason}"
                    )
                log(f"  {platform} / Python {python}: NOT bundled (missing {', '.join(why)})")
                continue
            for path in got.values():
                log(f"  {platform} / Python {python}: {path.name}")
            wheels[platform].extend(got.values())

    if missing:
        log("\nWARNING: pinned versions without a wheel (no other version was picked):")
        for m in missing:
            log(f"  - {m}")
        if args.strict:
            return 1
    empty = [p for p in platforms if not wheels[p]]
    if empty:
        log(f"error: no complete wheel set for {', '.join(empty)}; not building them")
        platforms = [p for p in platforms if wheels[p]]
        if not platforms:
            return 1
    ok = not empty

    args.output_dir.mkdir(parents=True, exist_ok=True)
    tmp = None
    if args.staging_dir is None:
        tmp = tempfile.TemporaryDirectory(prefix="brdf_extension_stage_")
        stage = Path(tmp.name) / manifest["id"]
    else:
        stage = args.staging_dir.resolve()
        if stage.exists():
            if not (stage / STAGE_MARKER).is_file():
                log(f"error: {stage} exists and is not a staging folder made by this script")
                return 1
            shutil.rmtree(stage)
    try:
        patterns = list(manifest.get("build", {}).get("paths_exclude_pattern", []))
        stage_source(src, stage, patterns)
        (stage / STAGE_MARKER).touch()  # a dot-file: blender_ext.py leaves it out of the zip
        (stage / "wheels").mkdir()
        rel_wheels = []
        for platform in platforms:
            for path in wheels[platform]:
                target = stage / "wheels" / path.name
                if not target.exists():
                    try:
                        os.link(path, target)  # same file system: no copy
                    except OSError:
                        shutil.copy2(path, target)
                    rel_wheels.append(f"./wheels/{path.name}")
        write_staged_manifest(stage / MANIFEST, sorted(rel_wheels), platforms)

        result = run_blender_ext(
            blender_ext, "build", "--split-platforms",
            "--source-dir", str(stage), "--output-dir", str(args.output_dir.resolve()),
            *valid_tags_args,
        )  # fmt: skip
        log(result.stdout.rstrip())
        if result.returncode != 0:
            log(f"error: blender_ext.py build failed\n{result.stderr}")
            return 1
    finally:
        if tmp is not None:
            tmp.cleanup()

    log("")
    for platform in platforms:
        zip_name = f"{manifest['id']}-{manifest['version']}-{platform.replace('-', '_')}.zip"
        archive = args.output_dir / zip_name
        if not archive.is_file():
            log(f"error: expected {archive} was not built")
            ok = False
            continue
        result = run_blender_ext(blender_ext, "validate", *valid_tags_args, str(archive))
        status = "valid" if result.returncode == 0 else "INVALID"
        log(f"{archive} ({archive.stat().st_size / 1e6:.1f} MB): {status}")
        if result.returncode != 0:
            log(result.stdout + result.stderr)
            ok = False
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
