"""Packaging and the import rule: the science is importable without Blender."""

import subprocess
import sys
import textwrap


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
