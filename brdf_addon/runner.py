"""One reconstruction run in steps (:class:`Run`), split where Blender must and must
not be touched.

1. ``photo_input.gather_photo`` (main thread, bpy), one photo per step: the
   photo, its light and its Cycles G-buffers; ``gathering.capture_inputs`` makes
   them ``core.method.pipeline.PhotoInput`` (``gathering.gather`` does all at once).
2. ``core.method.pipeline.run`` (a worker thread, no bpy): the science.
3. ``outputs.write_back`` (main thread, bpy): tables, pictures, report,
   materials.

The operator (``operators/reconstruct.py``), the batch entry and the tests all
drive a :class:`Run`. Nothing of the user's is modified.
"""

from __future__ import annotations

import contextlib
import signal
import threading
import time
import traceback

import numpy as np

from ..core.method import pipeline, selection
from . import gathering, outputs, photo_input, prefs, props

# The basis build's progress line on the terminal and the status bar: at most this
# often (it is called after every table, a few times a second).
BASIS_MESSAGE_INTERVAL_S = 1.0


# The operator's report when Ctrl+C interrupts a background run (Blender would turn
# the KeyboardInterrupt into a traceback); the batch entry turns it back into exit 130.
INTERRUPTED = "Interrupted (Ctrl+C); nothing was written half-way"


# Ctrl+C seen during a batch run (set by on_sigint). Python's own SIGINT handler only
# raises KeyboardInterrupt, and one raised while a destructor runs (Cycles frees its
# render engine in __del__) is printed and swallowed: the run would go on and exit 0.
_interrupted = threading.Event()


def on_sigint(signum, frame) -> None:
    """SIGINT handler of a batch run: records the interrupt, then raises
    KeyboardInterrupt as Python's default handler does. If that exception is
    swallowed, the run's next check (:meth:`Run.step`, the pipeline's cancel
    poll) raises it again."""
    _interrupted.set()
    raise KeyboardInterrupt


def check_interrupt() -> None:
    """Raise KeyboardInterrupt if Ctrl+C came since :func:`sigint_recorded` began."""
    if _interrupted.is_set():
        raise KeyboardInterrupt


@contextlib.contextmanager
def sigint_recorded():
    """While the block runs (main thread), Ctrl+C is recorded as well as raised
    (:func:`on_sigint`); the previous handler comes back afterwards."""
    _interrupted.clear()
    previous = signal.signal(signal.SIGINT, on_sigint)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        _interrupted.clear()


class RunFailed(Exception):
    """The run stopped on something that is not the user's input (out of memory, a
    bug): one sentence for the user; ``details`` holds the traceback for the console."""

    def __init__(self, message: str, details: str = ""):
        super().__init__(message)
        self.details = details


def failure_sentence(error: BaseException) -> str:
    """One sentence for an unexpected exception in the run."""
    if isinstance(error, MemoryError):
        return ("the reconstruction ran out of memory; close other programs, or use "
                "fewer or smaller photos")
    text = str(error).strip().splitlines()[0] if str(error).strip() else ""
    what = f"{type(error).__name__}: {text}" if text else type(error).__name__
    return f"the reconstruction failed unexpectedly ({what}); nothing was written"


class Run:
    """A run in steps, so a modal operator can keep Blender responsive.

    Each :meth:`step` does a bounded piece of work in the calling (main)
    thread: one photo's G-buffers, polling the worker, or writing back. The
    science (basis load and ``core.method.pipeline.run``) runs in a worker thread that
    never touches bpy. :meth:`cancel` stops at the next step boundary; until
    :meth:`step` reports done nothing has been written, so a cancelled run
    leaves the scene as it was. With ``threaded=False`` everything runs in the
    caller's thread (background mode, tests).
    """

    def __init__(self, scene, threaded: bool = True, bake: bool = True, on_progress=None):
        self.scene = scene
        self.threaded = threaded
        self.bake = bake
        self.on_progress = on_progress
        self.progress = 0.0
        self.message = "starting"
        self.report = None
        self._cancel = False
        self._inputs = []
        self._gathered = []
        self._capture = None
        self._photo = 0
        self._thread = None
        self._outcome = None
        self._timings = {}
        self._cycles_queue = None
        self._fits = {}
        self._t0 = time.perf_counter()
        gathering.check_scene(scene)
        self._settings = props.pipeline_settings(scene.brdf)
        self._n_photos = len(scene.brdf.photos)
        self._exposure = photo_input.exposure_plan(scene)
        self._basis_plan = prefs.basis_plan(scene)  # refused here, before any work
        self._basis_info = None
        # (shape, prior) of a textured run, read here, before any work (a missing texture
        # file is refused now), and its core.method.textured.TexturedResult
        self._texture, self._texture_note = (
            self._texture_plan() if scene.brdf.texture else (None, None))
        self._textured = None

    @property
    def message(self) -> str:
        """What the run is doing now, one line; setting it calls ``on_progress(progress,
        message)`` (the batch entry prints it; the panel polls instead)."""
        return self._message

    @message.setter
    def message(self, text: str) -> None:
        self._message = text
        if self.on_progress is not None:
            self.on_progress(self.progress, text)

    def cancel(self) -> None:
        """Ask the run to stop: at the next step, or (in the worker) at the next check
        of the basis build or the pipeline; :meth:`step` raises ``pipeline.Cancelled``
        once the worker has stopped."""
        self._cancel = True

    def _cancelled(self) -> bool:
        check_interrupt()  # a batch run's Ctrl+C ends it as an interruption, not a cancel
        return self._cancel

    def _basis_progress(self):
        """``progress(fraction, message)`` for the basis build: the message at most
        every :data:`BASIS_MESSAGE_INTERVAL_S`, and always its last one."""
        last = [-np.inf]

        def progress(fraction, message):
            now = time.perf_counter()
            if fraction >= 1.0 or now - last[0] >= BASIS_MESSAGE_INTERVAL_S:
                last[0] = now
                self.message = f"{message} ({fraction:.0%}; first run only)"
        return progress

    def _science(self) -> None:
        try:
            t0 = time.perf_counter()
            basis, self._basis_info = prefs.load_planned(
                self._basis_plan, progress=self._basis_progress(), cancelled=self._cancelled)
            self._timings["basis_load"] = time.perf_counter() - t0

            def progress(f, msg):
                self.progress, self.message = 0.3 + 0.6 * f, msg

            if self._texture is not None:
                from ..core.method import textured

                shape, prior = self._texture
                self._textured = textured.run(
                    basis, self._inputs, self._settings, textured.TextureSettings(shape=shape),
                    prior=prior, progress=progress, cancelled=self._cancelled)
                result = self._textured.result
            else:
                result = pipeline.run(basis, self._inputs, self._settings, progress=progress,
                                      cancelled=self._cancelled)
            if self.bake:  # the lobe fits are numpy: here, not in the main thread
                from ..core.bake import fitting

                for r in result.regions:
                    if self._cancel:
                        raise pipeline.Cancelled("cancelled by the user")
                    if r.status == "ok":
                        self.message = f"region {r.region}: fitting the material"
                        t_fit = time.perf_counter()
                        self._fits[r.region] = (r.winner, fitting.fit(r.table))
                        self._timings[f"fit_region_{r.region}"] = time.perf_counter() - t_fit
            self._outcome = ("ok", result)
        except pipeline.Cancelled as error:
            self._outcome = ("cancelled", error)
        except (ValueError, OSError) as error:
            self._outcome = ("error", error)
        except Exception as error:  # noqa: BLE001 - any other fault ends the run cleanly
            self._outcome = ("failed", RunFailed(failure_sentence(error),
                                                 traceback.format_exc()))

    def step(self) -> bool:
        """Advance; True when finished. Raises ValueError (one sentence) on a user
        error, :class:`RunFailed` on any other fault of the science, and
        ``pipeline.Cancelled`` after :meth:`cancel` (once the worker thread, if
        any, has stopped, so nothing runs on behind the user's back), and
        KeyboardInterrupt after a batch run's Ctrl+C (:func:`on_sigint`)."""
        check_interrupt()
        if self._cancel:
            if self._thread is not None and self._thread.is_alive():
                self.message = "cancelling"
                return False
            raise pipeline.Cancelled("cancelled by the user")
        if self._photo < self._n_photos:  # G-buffers: one photo per step (bpy)
            t0 = time.perf_counter()
            self.message = f"G-buffers {self._photo + 1}/{self._n_photos}"
            scales, notes = self._exposure
            self._gathered.append(photo_input.gather_photo(
                self.scene, self.scene.brdf.photos[self._photo], float(scales[self._photo]),
                notes[self._photo]))
            self._photo += 1
            if self._photo == self._n_photos:
                self._inputs, self._capture = gathering.capture_inputs(self._gathered)
                if self._texture_note is not None:
                    self._capture["texture"] = self._texture_note
            self.progress = 0.3 * self._photo / self._n_photos
            self._timings["gbuffers"] = self._timings.get("gbuffers", 0.0) + (
                time.perf_counter() - t0)
            return False
        if self._thread is None and self._outcome is None:
            t0 = time.perf_counter()
            if self.threaded:
                import threading

                self._thread = threading.Thread(target=self._science, daemon=True)
                self._thread.start()
                return False
            self._science()
            self._timings["science"] = time.perf_counter() - t0
        if self._thread is not None and self._thread.is_alive():
            return False
        status, value = self._outcome
        if status == "cancelled":
            raise value
        if status == "error":
            raise ValueError(str(value)) from value
        if status == "failed":
            raise value
        if self.scene.brdf.kl_path == "CYCLES" and self._cycles_step(value):
            return False
        check_interrupt()  # nothing written yet
        self.progress, self.message = 0.9, "writing results"
        self._timings["total_before_outputs"] = time.perf_counter() - self._t0
        self.report = outputs.write_back(
            self.scene, self._inputs, value, self._timings, self.bake, self._fits, self._capture,
            self._basis_info, textured=self._textured)
        self.progress, self.message = 1.0, "done"
        return True

    def _texture_plan(self):
        """((shape, prior), note) of the albedo image: the scan's own texture as the
        prior (``scan_texture``), read in the main thread; the note is the report's."""
        from . import scan_texture

        s = self.scene.brdf
        image = scan_texture.find_image(s.target)
        shape = scan_texture.texture_shape(image, s.texture_size)
        prior = None if image is None else scan_texture.read_prior(image, shape)
        note = {"shape": list(shape), "uv_map": s.uv_map or "(active render map)",
                "prior": None if image is None else image.name}
        return (shape, prior), note

    def _cycles_step(self, result) -> bool:
        """The accurate selection path, one candidate per step; True while work remains."""
        from . import cycles_select

        if self._cycles_queue is None:
            self._cycles_queue = [(r, t) for r in result.regions if r.status == "ok"
                                  for t in range(len(r.candidates))]
            self._cycles_total = max(len(self._cycles_queue), 1)
            self._cycles_kl = {}
        if not self._cycles_queue:
            return False
        t0 = time.perf_counter()
        r, t = self._cycles_queue.pop(0)
        s = self.scene.brdf
        self.message = f"region {r.region}: Cycles render of trial {t + 1}/{len(r.candidates)}"
        # a textured run compares the candidates with the photos at the reference colour
        inputs = self._inputs if self._textured is None else self._textured.inputs
        kl = cycles_select.score_candidate(self.scene, inputs, r.region,
                                           r.candidates[t].astype(np.float64), s.kl_samples,
                                           s.kl_bins, device=prefs.cycles_device())
        self._cycles_kl.setdefault(r.region, []).append(float(kl.mean()))
        if len(self._cycles_kl[r.region]) == len(r.candidates):
            scores = np.array(self._cycles_kl[r.region])
            # the trials the photos' check excluded (pipeline: none in the paper's mode)
            photo_check = {k: v for k, v in r.selection.items() if k.startswith("photo_")}
            eligible = np.ones(len(scores), dtype=bool)
            eligible[photo_check.get("photo_excluded", [])] = False
            winner, kl_winner = selection.eligible_winner(scores, eligible), int(np.argmin(scores))
            r.selection = {"path": "cycles", "cycles_samples": int(s.kl_samples),
                           "cycles_bounces": 0, "fast_kl": [float(k) for k in r.kl],
                           "fast_winner": int(r.winner), "agree": winner == r.winner,
                           **photo_check}
            if winner != kl_winner:
                r.selection["kl_winner"] = kl_winner
            r.kl, r.winner = scores, winner
            if r.refine_inputs is None:
                r.table = r.candidates[winner].astype(np.float64)
            elif winner != r.refinement.get("trial"):
                pipeline.refine_chosen(r, cancelled=self._cancelled)  # the Cycles winner refitted
            if self._textured is not None and winner != r.selection["fast_winner"]:
                self._textured.retexture(r)  # the texture under the new winner
        done = self._cycles_total - len(self._cycles_queue)
        self.progress = 0.85 + 0.05 * done / self._cycles_total
        self._timings["cycles_selection"] = self._timings.get("cycles_selection", 0.0) + (
            time.perf_counter() - t0)
        return True

    def run(self) -> dict:
        """All steps in this thread (background mode); returns the report."""
        while not self.step():
            pass
        return self.report

