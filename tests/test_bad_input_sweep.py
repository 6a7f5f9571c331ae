"""The bad-input sweep (``bench/bad_inputs.py``, issue 13) as a test: its ``--quick``
part (a few cases of every class of bad input: job file, paths, photos, light, camera,
output folder, settings, command line, interruption), each run through the batch entry
in a fresh process and judged by the sweep's rules (its module docstring): the
expected exit status, one ``error:`` line naming the field or file, no traceback, the
inputs unchanged, nothing half-written, finite outputs when it runs.

The sweep is run as a script, as ``make bench`` runs it (no test imports a bench
module); its JSON result is read back. ``make bench`` runs every case.
"""

import json
import pathlib
import subprocess
import sys

import pytest

pytest.importorskip("bpy")

ROOT = pathlib.Path(__file__).resolve().parent.parent
SWEEP = ROOT / "bench" / "bad_inputs.py"


def _table(rows) -> str:
    """The cases not handled cleanly: case, class, expected, what happened and why."""
    lines = []
    for r in rows:
        lines.append(f"{r['case']} [{r['class']}] expected {r['expected']}; got {r['got']}")
        lines += [f"    why: {p}" for p in r["problems"]]
    return "\n".join(lines)


def test_quick_sweep_every_case_handled_cleanly(tmp_path):
    result = tmp_path / "bad_inputs.json"
    done = subprocess.run([sys.executable, str(SWEEP), "--quick", "--out", str(result),
                           "--work", str(tmp_path)], capture_output=True, text=True,
                          cwd=ROOT)
    assert result.is_file(), done.stdout[-2000:] + done.stderr[-2000:]
    document = json.loads(result.read_text())
    rows = [r for r in document["cases"] if r["ok"] is not None]  # skipped: as root
    by_class = document["summary"]["by_class"]
    # the quick part covers every class of bad input
    assert by_class and all(counts["run"] >= 1 for counts in by_class.values()), by_class
    failing = [r for r in rows if not r["ok"]]
    assert not failing, (f"{len(rows) - len(failing)}/{len(rows)} handled cleanly; not "
                         f"handled:\n{_table(failing)}")
    assert document["summary"]["headline"] == f"{len(rows)}/{len(rows)} handled cleanly"
    assert done.returncode == 0, done.stderr[-2000:]
    # the work folder (inputs and the cases' copies) is removed at the end
    assert [p.name for p in tmp_path.iterdir()] == ["bad_inputs.json"]
