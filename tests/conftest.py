"""Fixtures of every test. No bpy here: core tests must run without Blender (the
Blender tests' scene reset and registration are in blender/conftest.py).

This folder is on ``sys.path`` (pytest's "prepend" import mode puts each
conftest.py's and test file's folder there; there is no __init__.py, the
repository root being a package itself), so test files in any sub-folder import
its helper modules (``image_files``) by name. Helper and test file names are
therefore unique across tests/."""

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
    """The built-in analytic basis (built on first use, about 40 s; cached in .cache/)."""
    from brdf_reconstruct.core.brdf import basis

    return basis.load_default(cache_dir=CACHE)


@pytest.fixture(scope="session")
def measured_basis():
    """The product's default basis: the shipped pack's 80 measured materials (built on
    first use, about 25 s; cached in .cache/)."""
    from brdf_reconstruct.core.brdf import basis

    return basis.load_measured(cache_dir=CACHE)


@pytest.fixture(scope="session")
def heldout_tables():
    from brdf_reconstruct.core.brdf import database

    return {s["name"]: database.make_table(s) for s in database.heldout_specs()}
