"""Reconstruct the BRDF of every region: ``brdf.reconstruct``.

Observations -> reliable region -> trials -> KL selection -> bake, per region
(``brdf_addon.runner``). Interactive: modal, one bounded step per timer tick
(one photo's G-buffers, or a poll of the worker thread that runs the numpy
science), with a progress bar and Esc to cancel, which leaves the scene as it
was. Background mode (batch, tests): the same steps, synchronously.
"""

import os
import sys
import traceback

import bpy

from ..brdf_addon import gathering, runner
from ..core.method import pipeline

DEBUG_VARIABLE = "BRDF_RECONSTRUCT_DEBUG"  # set to 1: a failure's traceback on stderr


def _ready(context) -> bool:
    s = getattr(context.scene, "brdf", None)
    return s is not None and not s.running and s.target is not None and len(s.photos) > 0


class BRDF_OT_reconstruct(bpy.types.Operator):
    """Reconstruct a BRDF per region from the lit photos (Esc cancels)"""

    bl_idname = "brdf.reconstruct"
    bl_label = "Reconstruct BRDF"
    bl_options = {"REGISTER", "UNDO"}

    _run = None
    _timer = None

    @classmethod
    def poll(cls, context):
        return _ready(context)

    def execute(self, context):
        try:
            echo = _echo if bpy.app.background else None
            report = runner.Run(context.scene, threaded=False,
                                              on_progress=echo).run()
        except (ValueError, OSError, pipeline.Cancelled) as error:
            self.report({"ERROR"}, _sentence(error))
            return {"CANCELLED"}
        except Exception as error:  # noqa: BLE001 - a fault, not the user's input
            self.report({"ERROR"}, _failure(error))
            return {"CANCELLED"}
        except KeyboardInterrupt:  # Ctrl+C in a background run: the batch exits 130
            self.report({"ERROR"}, runner.INTERRUPTED)
            return {"CANCELLED"}
        self._report_done(report)
        return {"FINISHED"}

    def invoke(self, context, _event):
        if bpy.app.background or context.window is None:
            return self.execute(context)
        try:
            self._run = runner.Run(context.scene, threaded=True)
        except (ValueError, OSError) as error:
            self.report({"ERROR"}, _sentence(error))
            return {"CANCELLED"}
        settings = context.scene.brdf
        self._status = settings.status
        settings.running, settings.progress = True, 0.0
        wm = context.window_manager
        wm.progress_begin(0.0, 1.0)
        self._timer = wm.event_timer_add(0.1, window=context.window)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        if event.type == "ESC":
            self._run.cancel()
            return {"RUNNING_MODAL"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        settings = context.scene.brdf
        try:
            done = self._run.step()
        except pipeline.Cancelled:
            self._finish(context)
            settings.status = self._status
            self.report({"WARNING"}, "Reconstruction cancelled; nothing was changed")
            return {"CANCELLED"}
        except (ValueError, OSError) as error:
            self._finish(context)
            settings.status = self._status
            self.report({"ERROR"}, _sentence(error))
            return {"CANCELLED"}
        except Exception as error:  # noqa: BLE001 - any fault still ends the modal run
            self._finish(context)
            settings.status = self._status
            self.report({"ERROR"}, _failure(error))
            return {"CANCELLED"}
        settings.progress = self._run.progress
        if not done:  # the panel's progress bar reads it (the basis build's line too)
            settings.status = self._run.message
        context.window_manager.progress_update(self._run.progress)
        context.workspace.status_text_set(f"BRDF: {self._run.message} (Esc to cancel)")
        for area in context.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()
        if not done:
            return {"RUNNING_MODAL"}
        self._finish(context)
        self._report_done(self._run.report)
        return {"FINISHED"}

    def _finish(self, context):
        wm = context.window_manager
        if self._timer is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()
        context.workspace.status_text_set(None)
        context.scene.brdf.running = False
        context.scene.brdf.progress = 0.0

    def _report_done(self, report):
        for line in gathering.capture_notes(report.get("capture", {})):
            self._note("INFO", line)
        ok = [r for r in report["regions"] if r["status"] == "ok"]
        skipped = [r for r in report["regions"] if r["status"] != "ok"]
        for r in skipped:
            self.report({"WARNING"}, f"Skipped {r['label']}: {r['reason']}")
        for r in ok:
            for line in pipeline.region_notes(r):
                self._note("WARNING", f"{r['label']}: {line}")
        self.report({"INFO"}, f"Reconstructed {len(ok)} region(s); "
                    f"{len(skipped)} skipped")

    def _note(self, level: str, line: str):
        """A note on the run for its user: the panel's report at ``level``, or in a
        batch run one ``note: ...`` line (Blender would print a report there too, so
        the line would come twice)."""
        if bpy.app.background:
            print(f"note: {line}", flush=True)
        else:
            self.report({level}, line)


def _failure(error: Exception) -> str:
    """One report line for a fault that is not the user's input; its traceback goes
    to stderr when ``$BRDF_RECONSTRUCT_DEBUG`` is set (the batch entry prints only
    the line otherwise; the panel's console gets it always)."""
    if not isinstance(error, runner.RunFailed):
        error = runner.RunFailed(runner.failure_sentence(error), traceback.format_exc())
    if os.environ.get(DEBUG_VARIABLE) or not bpy.app.background:
        print(error.details, file=sys.stderr, flush=True)
    hint = "" if os.environ.get(DEBUG_VARIABLE) else f" (set {DEBUG_VARIABLE}=1 for details)"
    return _sentence(error) + hint


def _sentence(error) -> str:
    text = str(error).strip().splitlines()[0] if str(error).strip() else type(error).__name__
    return text[:1].upper() + text[1:]


CLASSES = (BRDF_OT_reconstruct,)


def _echo(progress: float, message: str) -> None:
    """Progress on the terminal for background (batch) runs: one line per step."""
    print(f"[{progress:4.0%}] {message}", flush=True)
