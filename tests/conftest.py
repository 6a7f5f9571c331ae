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
    from brdf_reconstruct.core import basis

    return basis.load_default(cache_dir=CACHE)


@pytest.fixture(scope="session")
def heldout_tables():
    from brdf_reconstruct.core import database

    return {s["name"]: database.make_table(s) for s in database.heldout_specs()}
