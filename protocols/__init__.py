"""Measurement procedures: Table 4.10 MTF, section 4.4 relative radiometry, the camera
characterisation (EMVA 1288 photon transfer, ``characterise/``) and the depth of field
(section 2.2.4: the stage carries the chart through focus, ``depth/``).

Python API for scripted sessions (and for the TUI)
==================================================

Everything the ``benchlab run / resume / analyze SESSION`` commands do is these calls::

    import threading
    from benchlab.bench import Bench, BenchConfig
    from benchlab.protocols import load_params, start_run, resume_run, reanalyze

    params = load_params("mtf")                  # or load_params("mtf", "my-mtf.toml")
    # -> MtfParams / RadiometryParams; raises ParamsError listing EVERY problem (file + field)

    def prompt(step, message) -> bool:           # manual steps (thread the lens, roll pattern...)
        return input(f"{message} [Enter/n] ") != "n"   # False aborts the run

    def progress(done, total, step) -> None:     # before each step; step is None at the end
        print(f"{done}/{total}", step.title if step else "done")

    abort = threading.Event()                    # set() from any thread: abort at next check

    config = BenchConfig.load(None, simulate=True)   # or BenchConfig.load("bench.toml")
    with Bench.open(config, simulate=True) as bench:  # safe_state (LEDs off, stage stopped)
        # simulated bench only: seed=0, noise=True, time_scale=2000.0 (stage sim speed-up);
        # bench.world / bench.sim_led / bench.sim_stage / bench.sim_camera are the simulators
        runner = start_run("mtf", bench=bench, params=params, root="sessions",
                           operator="ana", prompt=prompt, progress=progress, abort=abort,
                           on_result=None, estimator=None)
        runner.steps        # list[Step]: .id, .title, .kind, .table_step, .prompt (checklist)
        runner.session.path # the session folder, created before any device command
        outcome = runner.run()   # -> RunOutcome(session_path, results_path, tables, summary,
                                 #                duration_s)

* ``params`` may be a Params object, a path, or None (packaged defaults). Parameters are also
  checked against the bench (LED current ceiling, stage travel) before anything moves; to check
  a file before opening any device: ``load_params("radiometry", path, config.limits())``.
* ``runner.run()`` starts at the first incomplete step. It raises ``RunAborted`` (abort set or a
  prompt declined; its subclass ``RunInterrupted`` when a stop signal arrived during a step,
  whatever the step raised after it) or ``StepFailed`` (``.step``, ``.cause``); the bench is
  already safe (LEDs off, stage stopped) and the session resumable. **Retry** a failed step = call
  ``runner.run()`` again. ``KeyboardInterrupt`` propagates after the bench is made safe.
* ``estimator``: ``None`` = the parameter file's (default ``"auto"``: forward view with the
  analysis library's default fit, radial view with histogram peaks, whose bars run obliquely
  through the ROI), or ``"histogram"``, ``"sinefit"``, ``"variance"`` for both views.
* A retry first calls ``bench.recover()`` (reconnects a camera that was unplugged and is back).
* ``on_result(step, mapping)``: optional; called after each acquisition with that frame's
  partial results (e.g. ``{"element": "G2E4", "orientation": "sagittal", "modulation": 0.6}``)
  so a UI can fill its tables as steps complete.
* The back-focus step calls ``prompt`` with a message showing the current sharpness; a live
  figure is available at any time from ``benchlab.analysis.focus.sharpness(pixels)`` on a frame
  from ``bench.grab(exposure_ms=..., gain=...)`` (a UI polls that while the prompt is open).
* Resume an interrupted session (Ctrl-C, crash, kill -9) - nothing acquired is repeated or lost::

      with Bench.open(BenchConfig.from_session("sessions/2026..._mtf"), simulate=True) as bench:
          outcome = resume_run("sessions/2026..._mtf", bench=bench, prompt=prompt,
                               progress=progress, abort=abort).run()

* Re-analyse saved frames into a new results version (frames verified by hash)::

      results_dir = reanalyze("sessions/2026..._mtf", estimator="histogram")

* HTML report: ``benchlab.report.render.write_report(session_path, out=None)`` -> path.

Results: ``outcome.tables`` maps table names (``table_4_11``, ``table_4_12``, ``table_4_13``,
``table_4_15``; radiometry ``table_4_16``; depth ``depth_of_field`` and the others listed in
``benchlab.protocols.depth.analysis``) to lists of row dicts (one dict per table row); the
same tables are written as CSV + JSON under ``SESSION/results/vN/`` (``Session.write_results``).
``outcome.summary`` is that version's ``summary.json`` (version, estimator, frame hashes, and
``summary`` with the headline numbers).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from benchlab.protocols.engine import (
    RunAborted,
    RunInterrupted,
    Runner,
    RunOutcome,
    Step,
    StepFailed,
)
from benchlab.protocols.mtf.params import MtfParams
from benchlab.protocols.params import (
    Params,
    ParamsError,
    RadiometryParams,
    load_params,
    parse_params,
)

if TYPE_CHECKING:  # the real signatures, for mypy and readers
    from benchlab.protocols.runs import reanalyze, resume_run, start_run

__all__ = [
    "MtfParams",
    "Params",
    "ParamsError",
    "RadiometryParams",
    "RunAborted",
    "RunInterrupted",
    "RunOutcome",
    "Runner",
    "Step",
    "StepFailed",
    "load_params",
    "parse_params",
    "reanalyze",
    "resume_run",
    "start_run",
]


def __getattr__(name: str) -> object:
    """``start_run``, ``resume_run`` and ``reanalyze`` from :mod:`benchlab.protocols.runs`,
    imported on first use (it opens the bench layer: ``benchlab --help`` never needs it)."""
    if name in ("start_run", "resume_run", "reanalyze"):
        from benchlab.protocols import runs

        return getattr(runs, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
