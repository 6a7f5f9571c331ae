"""Fixtures of the Blender tests (pip ``bpy``): the scene reset and the registration.

Every test here starts in an empty file (``empty_scene``, autouse), unless it
shares a scene that its module built once (``shared_scene``). Tests that need
the add-on ask for ``registered``.
"""

import pytest

try:
    import bpy
except ImportError:  # the test modules skip themselves (pytest.importorskip)
    bpy = None


def _empty_file():
    """Blender's factory startup file, emptied (``use_empty``). The same file as
    ``read_factory_settings(use_empty=True)`` gives (compared: every data-block
    and every scene setting) without resetting the preferences, which no test
    changes: 0.05 s a test instead of 0.2 s."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)


@pytest.fixture(autouse=True)
def empty_scene(request):
    """Guarantee: each test starts in a new, empty file: one scene ("Scene", with
    the factory settings: EEVEE, no objects, camera or world), no data-block but
    that scene and Blender's workspaces and screens, no file path (nothing saved
    over a .blend by accident), and the add-on not registered (``registered``).

    The exception is a test that uses ``shared_scene``, directly or through a
    module-scoped fixture that builds a scene on it: nothing is reset before it,
    so what that fixture built is still there (``shared_scene`` reset the file
    once, before the module built it). A test of that module that does not use
    it gets the reset, so keep such tests after the ones that share the scene."""
    if bpy is not None and "shared_scene" not in request.fixturenames:
        _empty_file()


@pytest.fixture(scope="module")
def shared_scene():
    """An empty file once per module (as ``empty_scene`` makes one), for a
    module-scoped fixture that builds a scene several tests use: request it from
    that fixture. Tests that use it are not reset by ``empty_scene``."""
    _empty_file()
    return bpy.context.scene


@pytest.fixture
def registered():
    """The add-on registered (``brdf_reconstruct.register()``: its classes and
    ``Scene.brdf``) for one test and unregistered after it, even when the test
    fails; yields the context scene. A fixture that builds its scene with a reset
    of its own (``testkit.blender_scene.build``) asks for this one after building,
    with ``request.getfixturevalue("registered")``, so the add-on is registered in
    the built file as in Blender."""
    import brdf_reconstruct

    brdf_reconstruct.register()
    try:
        yield bpy.context.scene
    finally:
        brdf_reconstruct.unregister()


@pytest.fixture
def tiny(tmp_path, request):
    """The tiny scene of ``testkit.blender_scene.build`` (a sphere scan, its camera, a
    Sun and a photo of it) in ``tmp_path``, the add-on registered in it and
    ``scene.brdf`` set for tiny runs; a module adds what it needs on top."""
    from testkit import blender_scene as BS

    built = BS.build(tmp_path)
    request.getfixturevalue("registered")  # after the build, which reads a new file
    BS.settings_for_tiny_runs(built, tmp_path / "out")
    return built
