"""``make demo`` (bench/demo.py) replaces only its own output folder: a folder
holding a user's files, the checkout, or a file is refused before any work,
with one line and exit status 2, and nothing in it is touched."""

import pathlib
import subprocess
import sys

import pytest

DEMO = pathlib.Path(__file__).resolve().parent.parent / "bench" / "demo.py"


def _demo(out):
    return subprocess.run([sys.executable, str(DEMO), "--out", str(out)],
                          capture_output=True, text=True, timeout=300)


def test_a_folder_with_a_users_notes_is_refused_and_kept(tmp_path):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("my notes")
    result = _demo(out)
    assert result.returncode == 2, result.stderr
    lines = [ln for ln in result.stderr.splitlines() if ln.strip()]
    assert lines[-1].startswith("error: ") and "did not make" in lines[-1]
    assert "Traceback" not in result.stderr
    assert (out / "notes.txt").read_text() == "my notes"
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]


@pytest.mark.parametrize("where", ["checkout", "parent"])
def test_the_checkout_or_its_parent_is_refused(where):
    root = DEMO.parent.parent
    result = _demo(root if where == "checkout" else root.parent)
    assert result.returncode == 2, result.stderr
    assert "holds it" in result.stderr
    assert (root / "README.md").is_file()


def test_a_file_is_refused(tmp_path):
    target = tmp_path / "file.txt"
    target.write_text("keep")
    result = _demo(target)
    assert result.returncode == 2 and "is a file" in result.stderr
    assert target.read_text() == "keep"
