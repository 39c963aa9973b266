"""The step engine: runs a procedure's steps against a bench, journalled in a session.

A step is done when the session journal says so (``step_completed``); ``run()`` always starts at
the first step not done, so a fresh run, a retry after a failed step and a resume after a crash
are the same call. Frames are saved (flushed, atomic) by :meth:`StepContext.acquire` before the
step is marked done, and a frame already on disk is read back instead of acquired again, so a
crash between the two loses nothing and repeats nothing.

The bench is put in its safe state (LEDs off, stage stopped) when ``run()`` leaves for any
reason: normal end, a failed step, abort, Ctrl-C.
"""

from __future__ import annotations

import json
import logging
import sys
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, Protocol

import numpy as np
import numpy.typing as npt

from benchlab.drivers.errors import BenchlabError, DeviceError
from benchlab.drivers.shutdown import interrupt_reason, received, signal_name
from benchlab.session import Session, read_results
from benchlab.storage import load_frame_tiff

log = logging.getLogger(__name__)

if TYPE_CHECKING:
    from benchlab.bench import Bench

StepKind = Literal["setup", "manual", "focus", "acquire", "analysis"]


class RunAborted(BenchlabError):
    """The operator aborted the run (abort event set, or a prompt declined)."""

    #: The session the run was writing (set by :meth:`Runner.run`; status "aborted").
    session_path: Path | None = None


class RunInterrupted(RunAborted):
    """A stop signal (SIGINT, SIGTERM, SIGHUP) arrived during a step. Whatever the step raised
    afterwards - a dark frame once the signal switched the LED off, a stopped move - is the
    consequence of the interruption, never the step's own failure: status "interrupted", and
    ``resume`` runs the step again."""

    def __init__(self, step: Step, signum: int, consequence: BaseException) -> None:
        self.step = step
        self.signum = int(signum)
        #: What the step raised after the signal (journalled as ``consequence``).
        self.consequence = consequence
        super().__init__(f"interrupted by {signal_name(signum)} during step {step.id} "
                         f"({step.title})")

    @property
    def exit_status(self) -> int:
        """``128 + signal number``, as for a process ended by the signal."""
        return 128 + self.signum


class StepFailed(BenchlabError):
    """A step raised; the session stays resumable and ``run()`` again retries the step."""

    #: The session the run was writing (set by :meth:`Runner.run`; status "failed").
    session_path: Path | None = None

    def __init__(self, step: Step, cause: BaseException, unsafe: str = "") -> None:
        self.step = step
        self.cause = cause
        #: Why the safe state could not be reached afterwards (a device lost), else "".
        self.unsafe = unsafe
        super().__init__(f"step {step.id} ({step.title}) failed: {cause}"
                         + (f"; {unsafe}" if unsafe else ""))


@dataclass(frozen=True)
class Step:
    """One step of a procedure.

    ``action(ctx)`` does the work. ``restore(ctx)``, when set, re-establishes the physical
    state the step left behind (camera settings, mounted target) and is replayed for completed
    steps when a run resumes in a new process.
    """

    id: str
    title: str
    kind: StepKind
    table_step: str
    action: Callable[[StepContext], None]
    prompt: str | None = None
    restore: Callable[[StepContext], None] | None = None
    info: Mapping[str, Any] = field(default_factory=dict)


PromptFn = Callable[[Step, str], bool]
ProgressFn = Callable[[int, int, "Step | None"], None]
ResultFn = Callable[[Step, Mapping[str, Any]], None]


class Procedure(Protocol):
    """What the engine needs from a procedure (see ``mtf.py`` / ``radiometry.py``)."""

    name: str

    def steps(self) -> list[Step]: ...

    def analyze(self, session: Session, estimator: str | None) -> Path: ...


@dataclass(frozen=True)
class RunOutcome:
    """What a finished run hands back."""

    session_path: Path
    results_path: Path
    tables: Mapping[str, Any]
    summary: Mapping[str, Any]
    duration_s: float


class StepContext:
    """What a step's action may use: the bench, the session, prompts, abort checks, frames."""

    def __init__(self, runner: Runner, step: Step) -> None:
        self.runner = runner
        self.step = step
        self.bench = runner.bench
        self.session = runner.session

    def check_abort(self) -> None:
        """Raise :class:`RunAborted` if the abort event is set."""
        if self.runner.abort.is_set():
            raise RunAborted(f"aborted at step {self.step.id}")

    def move_stage_mm(self, target_mm: float) -> None:
        """Move the stage to ``target_mm``; the abort key stops it and is an abort, not a fault."""
        self.check_abort()
        try:
            self.bench.move_stage_mm(target_mm, abort=self.runner.abort)
        except DeviceError:
            self.check_abort()  # stopped by the abort key: an abort, not a fault
            raise

    def home_stage(self) -> None:
        """Home the stage when the bench has one (a resumed run may meet a fresh stage); the
        abort key stops it and is an abort, not a fault."""
        if not self.bench.has_stage:
            return
        try:
            self.bench.home_stage(abort=self.runner.abort)
        except DeviceError:
            self.check_abort()  # stopped by the abort key or a quit: an abort, not a fault
            raise

    def ask(self, message: str) -> None:
        """Ask the operator to do something; declining aborts the run."""
        self.check_abort()
        self.runner.session.log_event("prompt", step=self.step.id, message=message)
        if not self.runner.prompt(self.step, message):
            raise RunAborted(f"operator declined at step {self.step.id}")
        self.check_abort()

    def acquire(
        self, name: str, *, exposure_ms: float, gain: float, extra: Mapping[str, Any] | None = None
    ) -> npt.NDArray[Any]:
        """Grab one frame and save it under this step, or return the one already saved.

        The frame file is written and flushed before this returns, so analysis never runs on a
        frame that is not on disk.
        """
        existing = self.runner.saved_frame_path(self.step.id, name)
        if existing is not None:
            pixels, _ = load_frame_tiff(existing)
            self.runner.session.log_event("frame_reused", step=self.step.id, name=name)
            return pixels
        self.check_abort()
        pixels, meta = self.bench.grab(exposure_ms=exposure_ms, gain=gain)
        metadata = {**meta, "step": self.step.id, "name": name, **dict(extra or {})}
        self.runner.session.save_frame(self.step.id, name, pixels, metadata)
        return pixels

    def reject_frames(self, names: Sequence[str], reason: str) -> None:
        """Set aside this step's frames ``names`` (their content is unusable): journalled,
        kept on disk, never analysed; a retry of the step acquires new ones."""
        self.runner.session.reject_frames(self.step.id, names, reason)

    def report(self, data: Mapping[str, Any]) -> None:
        """Hand a partial result (e.g. one ROI's modulation) to the UI."""
        if self.runner.on_result is not None:
            self.runner.on_result(self.step, data)


def procedure_steps(procedure: Procedure) -> list[Step]:
    """A procedure's steps, refused when two share an id (each id names its journal entries
    and frame files)."""
    steps = procedure.steps()
    ids = [s.id for s in steps]
    dup = sorted({i for i in ids if ids.count(i) > 1})
    if dup:
        raise BenchlabError(f"{procedure.name}: duplicate step ids {', '.join(dup)}")
    return steps


def _never_prompted(step: Step, message: str) -> bool:
    raise RunAborted(f"step {step.id} needs the operator ({message}) but no prompt was given")


class Runner:
    """Runs a procedure's steps in order on a bench, journalled in a session.

    Parameters
    ----------
    procedure : Procedure
        From :func:`benchlab.protocols.make_procedure`.
    session : benchlab.session.Session
        Fresh (``Session.create``) or reopened (``Session.open``) for resume.
    bench : benchlab.bench.Bench
        An open bench.
    prompt : callable ``(step, message) -> bool``
        Manual steps; ``False`` aborts.
    progress : callable ``(done, total, step_or_None)``
        Called before each step starts and once with ``None`` at the end.
    abort : threading.Event
        Set from any thread to abort at the next check.
    on_result : callable ``(step, mapping)``, optional
        Partial results as steps complete.
    estimator : str, optional
        Modulation estimator for the final analysis (default: params, then the library default).
    retake : sequence of str, optional
        Completed acquisition steps to take again (``benchlab resume --retake``): run again
        with the analysis after them, their new frames beside the old ones, made current only
        when every one of them is taken (:meth:`benchlab.session.Session.adopt_retake`).
    retake_reason : str
        Why (journalled and in ``session.json``).
    previous_status : str, optional
        The session's status before this run (a stopped retake of a completed session leaves
        it completed: its previous takes are whole).
    """

    def __init__(
        self,
        procedure: Procedure,
        session: Session,
        bench: Bench,
        *,
        prompt: PromptFn | None = None,
        progress: ProgressFn | None = None,
        abort: threading.Event | None = None,
        on_result: ResultFn | None = None,
        estimator: str | None = None,
        retake: Sequence[str] = (),
        retake_reason: str = "",
        previous_status: str | None = None,
    ) -> None:
        self.procedure = procedure
        self.session = session
        self.bench = bench
        self.prompt: PromptFn = prompt or _never_prompted
        self.progress = progress
        self.abort = abort or threading.Event()
        self.on_result = on_result
        self.estimator = estimator
        self.steps: list[Step] = procedure_steps(procedure)
        self._restored = False
        #: Retake: the steps to take again (until adopted), and every step to run again
        #: although the journal has it done (those steps and the analysis), until it has run.
        self._retake_steps = [s.id for s in self.steps if s.id in set(retake)]
        self._retake = list(self._retake_steps)  # emptied once adopted
        self._retake_reason = retake_reason
        self._previous_status = previous_status
        self._redo: set[str] = set()
        #: Why the last attempt to make the bench safe failed ("" when the devices confirmed
        #: it): what a caller says about safety once ``run()`` has raised.
        self.unsafe = ""

    # -- state ------------------------------------------------------------------------------
    def completed(self) -> set[str]:
        return set(self.session.completed_steps()) - self._redo

    def pending(self) -> list[Step]:
        """Steps not done yet, in order."""
        done = self.completed()
        return [s for s in self.steps if s.id not in done]

    def saved_frame_path(self, step_id: str, name: str) -> Path | None:
        frames = self.session.step_frames(step_id)
        path = frames.get(name) if isinstance(frames, Mapping) else None
        return Path(path) if path is not None else None

    # -- running ----------------------------------------------------------------------------
    def run(self) -> RunOutcome:
        """Run (or resume, or retry) from the first incomplete step to the end.

        Raises :class:`RunAborted` or :class:`StepFailed`; the session stays resumable and
        the bench is left safe in every case. The session's owner lock is held while this
        runs (``SessionBusyError`` if another process holds it) and released after.
        """
        self.session.hold()
        try:
            return self._run_held()
        finally:
            self.session.release()

    def _run_held(self) -> RunOutcome:
        t0 = time.perf_counter()
        total = len(self.steps)
        all_done = False
        try:
            if self._retake and self.session.retake_running is None:
                # (again after a failed attempt: every step of it is taken anew)
                self.session.begin_retake(self._retake, self._retake_reason,
                                          self._previous_status)
                self._redo = set(self._retake) | {s.id for s in self.steps
                                                  if s.kind == "analysis"}
            done = self.completed()
            if done and not self._restored:
                self._restore(done)  # a new process (resume)
            elif self._restored and hasattr(self.bench, "recover"):
                self._recover()  # a retry: reconnect what the failure lost
            self._restored = True
            ran: Step | None = None  # the last step run (a retake skips done steps between)
            skipped: list[Step] = []
            for step in self.steps:
                if step.id in done:
                    if ran is not None and self._retake_steps:
                        skipped.append(step)
                    continue
                self._check_abort(step)
                if skipped:
                    self._set_up_again(skipped, step)
                    skipped = []
                if self.progress is not None:
                    self.progress(len(done), total, step)
                self._run_step(step)
                done.add(step.id)
                self._redo.discard(step.id)
                ran = step
                if self._retake and self._retake[-1] == step.id:
                    takes = self.session.adopt_retake()  # every retaken step has new frames
                    log.info("retake adopted: %s", takes)
                    self._retake = []
            if self.progress is not None:
                self.progress(total, total, None)
            all_done = True
        except KeyboardInterrupt as exc:  # Ctrl-C, SIGTERM, SIGHUP (drivers.shutdown)
            self.session.log_event("interrupted", reason=interrupt_reason(exc))
            self._stopped("interrupted")
            raise
        except RunAborted as exc:
            exc.session_path = self.session.path
            stop_signal = received()  # the UI aborted the run because the process is stopping
            if stop_signal is not None and not isinstance(exc, RunInterrupted):  # (journalled)
                self.session.log_event("interrupted", reason=signal_name(stop_signal))
            self._stopped("aborted" if stop_signal is None else "interrupted")
            raise
        except StepFailed as exc:
            exc.session_path = self.session.path
            self._stopped("failed")
            raise
        except Exception:
            if self._retake_steps:  # e.g. a prompt no one can answer: the retake says so
                self._stopped("failed")
            raise
        finally:
            if all_done:
                self._safe_state_after(None)
            else:
                self._safe_state_after(sys.exc_info()[1])
                record_in_catalogue(self.session.path)  # the catalogue shows why it stopped
        results = self.session.latest_results()
        if results is not None and _partial(results):
            # a resume with every step already done (stopped after the analysis step) after a
            # re-analysis of the unfinished session: the final results are not partial
            results = Path(self.procedure.analyze(self.session, self.estimator))
        if results is None:  # every procedure ends with an analysis step that writes them
            raise BenchlabError(f"{self.procedure.name}: the run ended without results")
        self.session.finish()
        record_in_catalogue(self.session.path)
        tables, summary = read_results(results)
        return RunOutcome(
            session_path=Path(self.session.path), results_path=Path(results),
            tables=tables, summary=summary, duration_s=time.perf_counter() - t0,
        )

    def _stopped(self, status: str) -> None:
        """Record why the run stopped. A retake not yet adopted is stopped (its previous takes
        stay current); a retake of a completed session leaves it completed (its previous
        takes are whole; :meth:`benchlab.session.Session.results_stale` says when results
        predate an adopted retake)."""
        self.session.stop_retake(status)
        keep = bool(self._retake_steps) and self._previous_status == "completed"
        self.session.update_meta(status="completed" if keep else status)

    def _set_up_again(self, skipped: list[Step], step: Step) -> None:
        """Before a step after done ones were skipped (a retake): replay what those steps set
        up (camera, mounted target) and ask the operator to set the bench up as at the last
        manual step among them."""
        manual: Step | None = None
        for done in skipped:
            self._replay(done)
            if done.kind == "manual" and done.prompt:
                manual = done
        if manual is not None:
            StepContext(self, manual).ask(f"Before {step.id}: set up as at '{manual.title}': "
                                          f"{manual.prompt}")

    def _replay(self, step: Step) -> None:
        """Re-establish what a completed step left behind (its ``restore``); a failure is a
        failed step: status "failed", resumable."""
        if step.restore is None:
            return
        try:
            step.restore(StepContext(self, step))
        except RunAborted:
            raise
        except Exception as exc:
            stopped = self._stopped_during(step, exc, "")
            if stopped is not None:
                raise stopped from exc
            log.info("restoring step %s failed: %s: %s", step.id, type(exc).__name__, exc)
            self.session.log_event("step_failed", step=step.id,
                                   error=f"restoring: {type(exc).__name__}: {exc}")
            raise StepFailed(step, exc) from exc

    def _recover(self) -> None:
        try:
            self.bench.recover()
        except BenchlabError as exc:
            step = (self.pending() or self.steps)[0]
            self.session.log_event("step_failed", step=step.id,
                                   error=f"{type(exc).__name__}: {exc}")
            raise StepFailed(step, exc) from exc

    def _check_abort(self, step: Step) -> None:
        if self.abort.is_set():
            self.session.log_event("aborted", step=step.id)
            raise RunAborted(f"aborted before step {step.id}")

    def _safe_state_after(self, exc: BaseException | None) -> str:
        """The safe state on the way out of ``exc``. If a device cannot be made safe (lost
        mid-move), the reason is noted on ``exc`` and returned: it must not replace the error
        that got us here, nor stop the journal and catalogue from saying so."""
        try:
            self.bench.safe_state()
        except BenchlabError as safe_exc:
            self.unsafe = str(safe_exc)
            if exc is None:
                raise
            exc.add_note(str(safe_exc))
            return str(safe_exc)
        self.unsafe = ""
        return ""

    def _run_step(self, step: Step) -> None:
        ctx = StepContext(self, step)
        log.info("step %s: %s", step.id, step.title)
        self.session.log_event("step_started", step=step.id, title=step.title)
        try:
            step.action(ctx)
        except RunAborted as exc:
            self._safe_state_after(exc)
            self.session.log_event("aborted", step=step.id, message=str(exc))
            raise
        except Exception as exc:
            unsafe = self._safe_state_after(exc)
            stopped = self._stopped_during(step, exc, unsafe)
            if stopped is not None:
                raise stopped from exc
            log.info("step %s failed: %s: %s", step.id, type(exc).__name__, exc)
            extra: dict[str, Any] = {"safe_state": unsafe} if unsafe else {}
            self.session.log_event(
                "step_failed", step=step.id, error=f"{type(exc).__name__}: {exc}", **extra
            )
            raise StepFailed(step, exc, unsafe) from exc
        self.session.mark_step_completed(step.id)

    def _stopped_during(self, step: Step, exc: Exception, unsafe: str) -> RunAborted | None:
        """If the run was being stopped when ``step`` raised ``exc`` - a stop signal arrived,
        or the abort key was pressed - journal ``exc`` as the consequence of that and return
        the exception to raise instead of a failure; else None (the step itself failed).

        A stop signal switches the LEDs off and stops the stage at once (drivers.shutdown)
        while the step goes on, so its next frame check or move fails for that reason alone
        (issue 38: a SIGTERM journalled as ``step_failed: FrameContentError``)."""
        consequence = f"{type(exc).__name__}: {exc}"
        extra: dict[str, Any] = {"safe_state": unsafe} if unsafe else {}
        stop_signal = received()
        if stop_signal is not None:
            log.info("step %s interrupted by %s, then: %s", step.id, signal_name(stop_signal),
                     consequence)
            self.session.log_event("interrupted", step=step.id, reason=signal_name(stop_signal),
                                   consequence=consequence, **extra)
            return RunInterrupted(step, stop_signal, exc)
        if self.abort.is_set():
            self.session.log_event("aborted", step=step.id, consequence=consequence, **extra)
            return RunAborted(f"aborted during step {step.id}")
        return None

    def _restore(self, done: set[str]) -> None:
        """Re-establish what completed steps left behind (a resume in a new process)."""
        last_manual: Step | None = None
        for step in self.steps:
            if step.id not in done:
                break
            self._replay(step)
            if step.kind == "manual":
                last_manual = step
        if last_manual is not None and last_manual.prompt and self.pending():
            ctx = StepContext(self, last_manual)
            first = self.pending()[0].id
            ctx.ask(f"Retake of {first}: set up as at '{last_manual.title}': "
                    f"{last_manual.prompt}" if first in self._retake else
                    f"Resuming: check the set-up is still as at '{last_manual.title}': "
                    f"{last_manual.prompt}")
        self.session.log_event("resumed", completed=sorted(done))


def _partial(results: Path) -> bool:
    """Whether a results version says it came from an unfinished session."""
    try:
        return bool(json.loads((results / "summary.json").read_text(encoding="utf-8"))
                    .get("partial"))
    except (OSError, ValueError, AttributeError):
        return False


def frames_of(session: Session, step_ids: Sequence[str]) -> dict[str, dict[str, npt.NDArray[Any]]]:
    """Load every saved frame of the given steps: ``{step_id: {name: pixels}}``."""
    out: dict[str, dict[str, npt.NDArray[Any]]] = {}
    for sid in step_ids:
        frames = session.step_frames(sid)
        out[sid] = {name: np.asarray(load_frame_tiff(path)[0]) for name, path in frames.items()}
    return out


def record_in_catalogue(folder: Path) -> None:
    """:func:`benchlab.catalog.index.record_session`, imported when a run records (SQLite and the
    catalogue are not imported by a re-analysis before its results exist)."""
    from benchlab.catalog.index import record_session

    record_session(folder)
