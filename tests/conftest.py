"""Shared fixtures. No bpy here: core tests must run without Blender."""

import os
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parent.parent
# git-ignored; the default basis is built once, then reused (make sets the same place)
CACHE = pathlib.Path(os.environ.get("BRDF_RECONSTRUCT_CACHE", ROOT / ".cache"))
# the add-on (prefs.cache_dir) finds the same basis cache as the core tests
os.environ.setdefault("BRDF_RECONSTRUCT_CACHE", str(CACHE))


@pytest.fixture(scope="session")
def default_basis():
    """The built-in basis (built on first use, about two minutes; cached in .cache/)."""
    from brdf_reconstruct.core.brdf import basis

    return basis.load_default(cache_dir=CACHE)


@pytest.fixture(scope="session")
def heldout_tables():
    from brdf_reconstruct.core.brdf import database

    return {s["name"]: database.make_table(s) for s in database.heldout_specs()}


@pytest.fixture
def registered_scene():
    """An empty factory scene with the add-on registered (unregistered afterwards).
    Imports bpy only when a test asks for it."""
    bpy = pytest.importorskip("bpy")
    import brdf_reconstruct

    bpy.ops.wm.read_factory_settings(use_empty=True)
    brdf_reconstruct.register()
    try:
        yield bpy.context.scene
    finally:
        brdf_reconstruct.unregister()
