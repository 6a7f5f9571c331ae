"""A run always ends: a fault in the worker thread, a fault in a main-thread step,
and Esc during the first run's basis build each end the run with one sentence and
the scene as it was (``brdf_addon.runner``, ``operators/reconstruct.py``)."""

import time
import types

import pytest

bpy = pytest.importorskip("bpy")

from brdf_reconstruct.brdf_addon import prefs, runner  # noqa: E402
from brdf_reconstruct.core.method import pipeline  # noqa: E402
from brdf_reconstruct.operators.reconstruct import BRDF_OT_reconstruct  # noqa: E402
from testkit import blender_scene as BS  # noqa: E402


def _with_photo(built):
    from brdf_reconstruct.brdf_addon import photo_list

    added, _ = photo_list.add_photos(built["scene"], [str(built["photo"])])
    added[0].irradiance = (BS.lit_irradiance(),) * 3
    return built["scene"]


def _data_counts():
    return {k: len(getattr(bpy.data, k)) for k in ("materials", "images", "node_groups",
                                                   "objects", "lights")}


def _run_until_it_raises(run, seconds=60.0):
    """Step the run as the panel's timer does, with a pause between steps (a count of
    busy steps raced the worker thread on a loaded machine), for at most ``seconds``."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if run.step():
            raise AssertionError("the run finished instead of failing")
        time.sleep(0.001)
    raise AssertionError("the run never ended")


@pytest.mark.parametrize("fault, words", [
    (MemoryError(), "ran out of memory"),
    (TypeError("unsupported operand"), "TypeError: unsupported operand"),
])
def test_a_fault_in_the_worker_thread_ends_the_run_with_one_sentence(tiny, monkeypatch,
                                                                     fault, words):
    scene = _with_photo(tiny)
    before = _data_counts()

    def load_planned(plan, progress=None, cancelled=None):
        raise fault

    monkeypatch.setattr(prefs, "load_planned", load_planned)
    run = runner.Run(scene, threaded=True)
    with pytest.raises(runner.RunFailed) as caught:
        _run_until_it_raises(run)
    message = str(caught.value)
    assert words in message and "\n" not in message
    assert "Traceback" in caught.value.details  # kept for the console, not the user
    assert run._thread is not None and not run._thread.is_alive()
    assert _data_counts() == before and len(scene.brdf.results) == 0
    assert not (tiny["dir"] / "out").exists()


class _FakeWindowManager:
    def __init__(self):
        self.calls = []

    def event_timer_remove(self, timer):
        self.calls.append("timer removed")

    def progress_end(self):
        self.calls.append("progress ended")

    def progress_update(self, value):
        self.calls.append("progress updated")


class _RaisingRun:
    progress, message = 0.5, "writing results"

    def __init__(self, error):
        self.error = error

    def step(self):
        raise self.error


@pytest.mark.parametrize("error", [KeyError("brdf_0"), RuntimeError("Cycles device lost"),
                                   runner.RunFailed("the reconstruction ran out of memory")])
def test_the_modal_run_always_finishes(tiny, error):
    """Any exception out of a step (a worker fault, or a bpy error while writing
    back) ends the modal operator: timer removed, progress bar ended, ``running``
    False (so every button works again), one ERROR line."""
    scene = tiny["scene"]
    scene.brdf.running = True
    wm = _FakeWindowManager()
    reports = []
    op = types.SimpleNamespace(_run=_RaisingRun(error), _timer=object(), _status="",
                               report=lambda kind, text: reports.append((kind, text)))
    op._finish = lambda context: BRDF_OT_reconstruct._finish(op, context)
    context = types.SimpleNamespace(
        scene=scene, window_manager=wm, screen=types.SimpleNamespace(areas=[]),
        workspace=types.SimpleNamespace(status_text_set=lambda text: None))
    result = BRDF_OT_reconstruct.modal(op, context, types.SimpleNamespace(type="TIMER"))
    assert result == {"CANCELLED"}
    assert scene.brdf.running is False and op._timer is None
    assert "timer removed" in wm.calls and "progress ended" in wm.calls
    assert len(reports) == 1 and reports[0][0] == {"ERROR"} and "\n" not in reports[0][1]


def test_esc_during_the_first_runs_basis_build_stops_it(tiny, tmp_path, monkeypatch):
    """No basis cached yet: the run builds the built-in basis, says so on its progress
    line, and stops at the next table when cancelled, leaving no cache file."""
    scene = _with_photo(tiny)
    cache = tmp_path / "empty_cache"
    monkeypatch.setenv("BRDF_RECONSTRUCT_CACHE", str(cache))
    before = _data_counts()
    messages = []
    run = runner.Run(scene, threaded=True, on_progress=lambda f, m: messages.append(m))
    deadline = time.monotonic() + 300  # a hang, not a timing: the build takes minutes
    while not any("building the BRDF basis" in m for m in messages):
        assert run.step() is False and time.monotonic() < deadline
        time.sleep(0.01)  # as the modal timer polls
    assert "table 1/" in next(m for m in messages if "BRDF basis" in m)
    run.cancel()
    with pytest.raises(pipeline.Cancelled):
        while time.monotonic() < deadline:
            run.step()
            time.sleep(0.01)
    assert not run._thread.is_alive()  # the worker stopped before the run said so
    assert not cache.exists() or not list(cache.glob("basis-*"))
    assert _data_counts() == before and len(scene.brdf.results) == 0
    assert not (tiny["dir"] / "out").exists()


class _BuildingRun:
    progress = 0.3
    message = "building the BRDF basis (once): table 12/150 (6%; first run only)"

    def step(self):
        return False


def test_the_panel_shows_the_basis_builds_progress_line(tiny):
    """While the worker builds the basis, each timer tick copies the run's line to
    ``scene.brdf.status``, which the panel draws on its progress bar, and to the
    status bar with the Esc hint."""
    scene = tiny["scene"]
    shown = []
    op = types.SimpleNamespace(_run=_BuildingRun(), _timer=object(), _status="",
                               report=lambda kind, text: None)
    context = types.SimpleNamespace(
        scene=scene, window_manager=_FakeWindowManager(),
        screen=types.SimpleNamespace(areas=[]),
        workspace=types.SimpleNamespace(status_text_set=shown.append))
    assert BRDF_OT_reconstruct.modal(op, context, types.SimpleNamespace(type="TIMER")) == {
        "RUNNING_MODAL"}
    assert scene.brdf.status == _BuildingRun.message
    assert scene.brdf.progress == pytest.approx(0.3)
    assert shown == [f"BRDF: {_BuildingRun.message} (Esc to cancel)"]


def test_ctrl_c_in_a_background_run_is_the_interrupted_line(tiny, monkeypatch):
    """Blender turns an exception in ``execute`` into a traceback; the operator
    reports Ctrl+C as one line instead, which the batch entry turns into exit 130."""
    scene = _with_photo(tiny)

    def interrupted(self):
        raise KeyboardInterrupt

    monkeypatch.setattr(runner.Run, "run", interrupted)
    with pytest.raises(RuntimeError) as caught:
        bpy.ops.brdf.reconstruct()
    assert runner.INTERRUPTED in str(caught.value) and "Traceback" not in str(caught.value)
    assert len(scene.brdf.results) == 0 and not (tiny["dir"] / "out").exists()


def test_an_output_folder_that_cannot_be_written_is_refused_before_any_work(tiny, monkeypatch):
    """Root ignores permissions, so the test stands in for the permission check."""
    from brdf_reconstruct.brdf_addon import gathering

    scene = _with_photo(tiny)
    real = gathering.os.access
    monkeypatch.setattr(gathering.os, "access",
                        lambda path, mode: False if str(path) == str(tiny["dir"]) else
                        real(path, mode))
    with pytest.raises(ValueError, match=r"cannot be written \(.* is not writable for you\)"):
        runner.Run(scene, threaded=False)
    assert not (tiny["dir"] / "out").exists()
