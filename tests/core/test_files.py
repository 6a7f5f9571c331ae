"""Output files are never half-written (core.files): a temporary name beside the
destination, renamed when complete; an error or Ctrl+C leaves the old file."""

import os

import numpy as np
import pytest

from brdf_reconstruct.core import files
from brdf_reconstruct.core.brdf import merl
from brdf_reconstruct.core.method import pictures


def _leftovers(folder):
    return sorted(p.name for p in folder.iterdir() if ".tmp" in p.name)


def test_write_text_lands_whole_and_leaves_no_temporary(tmp_path):
    path = tmp_path / "report.json"
    files.write_text(path, '{"a": 1}')
    assert path.read_text() == '{"a": 1}'
    files.write_text(path, '{"a": 2}')  # replacing a previous output
    assert path.read_text() == '{"a": 2}'
    assert _leftovers(tmp_path) == []


def test_temporary_name_keeps_the_suffix_and_the_folder(tmp_path):
    tmp = files.temporary_name(tmp_path / "brdf_0_slice.png")
    assert tmp.parent == tmp_path and tmp.suffix == ".png" and tmp.name.startswith(".")
    assert str(os.getpid()) in tmp.name


def test_an_error_mid_write_keeps_the_previous_file(tmp_path):
    path = tmp_path / "brdf_0.binary"
    path.write_bytes(b"previous complete file")
    with pytest.raises(RuntimeError, match="disk full"), files.replacing(path) as tmp:
        tmp.write_bytes(b"half a ta")
        raise RuntimeError("disk full")
    assert path.read_bytes() == b"previous complete file"
    assert _leftovers(tmp_path) == []


def test_ctrl_c_as_the_table_is_written_leaves_no_partial_table(tmp_path, monkeypatch):
    """The interruption lands at the rename, the last moment: the old table stays
    whole and readable, and no 0- or 12-byte file is left."""
    table = np.full((3, *merl.SHAPE), 0.1)
    path = tmp_path / "brdf_0.binary"
    merl.write(path, table)
    before = path.read_bytes()

    def interrupted(src, dst):
        raise KeyboardInterrupt

    monkeypatch.setattr(files.os, "replace", interrupted)
    with pytest.raises(KeyboardInterrupt):
        merl.write(path, table * 2.0)
    monkeypatch.undo()
    assert path.read_bytes() == before  # the old table, whole
    assert merl.read(path).shape == (3, *merl.SHAPE)
    assert _leftovers(tmp_path) == []


def test_ctrl_c_before_a_first_table_leaves_nothing(tmp_path, monkeypatch):
    path = tmp_path / "brdf_0.binary"
    monkeypatch.setattr(files.os, "replace", lambda src, dst: (_ for _ in ()).throw(
        KeyboardInterrupt()))
    with pytest.raises(KeyboardInterrupt):
        merl.write(path, np.full((3, *merl.SHAPE), 0.1))
    assert list(tmp_path.iterdir()) == []


def test_a_picture_is_written_through_a_temporary_png(tmp_path, monkeypatch):
    seen = []
    real_replace = os.replace

    def spy(src, dst):
        seen.append((os.path.basename(src), os.path.getsize(src)))
        real_replace(src, dst)

    monkeypatch.setattr(files.os, "replace", spy)
    pictures.write_png(tmp_path / "fig.png", np.full((4, 5, 3), 0.5))
    assert (tmp_path / "fig.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert len(seen) == 1 and seen[0][0].endswith(".png") and seen[0][1] > 0
    assert _leftovers(tmp_path) == []


def test_a_run_would_replace_only_its_own_names_in_an_unmarked_folder(tmp_path):
    assert files.files_a_run_would_replace(tmp_path / "missing") == []
    for name in ("brdf_0.binary", "brdf_2_slice.png", "report.json", "scene.blend",
                 "notes.txt", "scan.ply", "view0.exr"):
        (tmp_path / name).write_text("the user's")
    assert files.files_a_run_would_replace(tmp_path) == [
        "brdf_0.binary", "brdf_2_slice.png", "report.json", "scene.blend"]
    files.mark_output_folder(tmp_path)  # a run wrote here: its outputs may be replaced
    assert files.files_a_run_would_replace(tmp_path) == []
    assert (tmp_path / files.OUTPUT_MARKER).is_file() and _leftovers(tmp_path) == []
