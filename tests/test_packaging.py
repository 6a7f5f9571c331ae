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
        for m in pkgutil.iter_modules(core.__path__):
            importlib.import_module("brdf_reconstruct.core." + m.name)
        assert callable(brdf_reconstruct.register)
        assert "bpy" not in sys.modules, "importing the package pulled in bpy"
        assert "brdf_reconstruct.brdf_addon" not in sys.modules
        """
    )
    result = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True
    )
    assert result.returncode == 0, result.stderr
