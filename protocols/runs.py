"""Starting, resuming and re-analysing runs: sessions + procedures + the bench."""

from __future__ import annotations

import threading
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, TypeAlias, cast

import benchlab
from benchlab.drivers.errors import BenchlabError, UsageError
from benchlab.procedures import ProcedureName, entry, entry_of
from benchlab.protocols.engine import (
    ProgressFn,
    PromptFn,
    ResultFn,
    Runner,
    procedure_steps,
    record_in_catalogue,
)
from benchlab.protocols.params import (
    BenchLimits,
    Params,
    ParamsError,
    RadiometryParams,
    load_params,
    params_to_dict,
    parse_params,
)
from benchlab.session import FRAME_LOAD_THREADS, Session, SessionError

if TYPE_CHECKING:
    from benchlab.analysis.bars.estimators import EstimatorChoice
    from benchlab.bench import Bench
    from benchlab.protocols.characterise.steps import CharacteriseProcedure
    from benchlab.protocols.depth.steps import DepthProcedure
    from benchlab.protocols.fov.steps import FovProcedure
    from benchlab.protocols.mtf.steps import MtfProcedure
    from benchlab.protocols.radiometry import RadiometryProcedure

#: Key of the bench configuration inside the session's parameter snapshot.
BENCH_KEY = "bench"


class FramesModifiedError(BenchlabError):
    """Saved frames no longer match the hashes journalled when they were acquired."""


class SessionCompleteError(SessionError):
    """``resume`` of a session that already completed: there is nothing to do."""


class UnknownEstimatorError(UsageError):
    """An estimator name that the analysis library does not know."""


def check_estimator(name: str | None) -> EstimatorChoice | None:
    """Refuse an unknown estimator before anything runs; ``name`` typed as a known one (a
    command line's or a file's string becomes an :data:`EstimatorChoice` here)."""
    from benchlab.analysis.bars.estimators import ESTIMATORS

    if name is not None and name != "auto" and name not in ESTIMATORS:
        raise UnknownEstimatorError(
            f"unknown estimator {name!r}; choose auto, {', '.join(sorted(ESTIMATORS))}")
    return cast("EstimatorChoice | None", name)


AnyProcedure: TypeAlias = ("MtfProcedure | RadiometryProcedure | CharacteriseProcedure | "
                           "DepthProcedure | FovProcedure")


def make_procedure(params: Params) -> AnyProcedure:
    """The procedure object for a parameter set (:mod:`benchlab.procedures`).

    Each procedure module is imported only when its procedure is asked for: re-analysing an
    MTF session never loads the characterisation's or the radiometry's analysis (start-up).

    Raises
    ------
    ParamsError
        For parameters of no registered procedure.
    """
    try:
        procedure = entry_of(params)
    except TypeError as exc:
        raise ParamsError("<params>", [f"procedure: {exc}"]) from None
    made: AnyProcedure = procedure.load("procedure_class")(params)
    return made


def _resolve_params(
    procedure: str, params: Params | str | Path | None, limits: BenchLimits | None
) -> tuple[Params, str]:
    """Validate the parameters in full, bench limits included, before anything is touched."""
    if params is None or isinstance(params, str | Path):
        source = str(params) if params is not None else f"default {procedure}.toml"
        return load_params(procedure, params, limits), source
    try:
        expected = entry(procedure).load("params_class")
    except KeyError as exc:
        raise ParamsError("<params>", [f"procedure: {exc.args[0]}"]) from None
    if not isinstance(params, expected):
        raise ParamsError("<params>", [f"procedure: {type(params).__name__} given for "
                                       f"{procedure!r}"])
    return parse_params(procedure, params.raw, "<params>", limits), "<params>"


def start_run(
    procedure: ProcedureName,
    *,
    bench: Bench,
    params: Params | str | Path | None = None,
    root: str | Path = "sessions",
    operator: str = "",
    sample: str = "",
    lot: str = "",
    prompt: PromptFn | None = None,
    progress: ProgressFn | None = None,
    abort: threading.Event | None = None,
    on_result: ResultFn | None = None,
    estimator: EstimatorChoice | None = None,
) -> Runner:
    """Validate everything, create the session folder, return a runner (nothing moved yet)."""
    check_estimator(estimator)
    resolved, source = _resolve_params(procedure, params, bench.config.limits())
    snapshot = {**params_to_dict(resolved), BENCH_KEY: bench.config.to_dict()}
    procedure_obj = make_procedure(resolved)
    procedure_steps(procedure_obj)  # its steps are sound before any folder exists
    calibration = None
    if isinstance(resolved, RadiometryParams):  # the one procedure that linearises with it
        from benchlab.calibration import (
            check_run_curve,
            read_run_calibration,
        )

        calibration = read_run_calibration(bench.config)  # refused before any folder exists
        if calibration is not None:  # and it has the curve the analysis will need
            check_run_curve(calibration, resolved.measurement_gain, resolved.bits)
    elif procedure == "characterise":  # its end edits the bench file: can it?
        from benchlab.calibration import check_bench_editable

        check_bench_editable(bench.config)
    session = Session.create(
        Path(root), procedure=procedure, params=snapshot, operator=operator,
        devices=bench.identities(), software_version=benchlab.__version__, sample=sample,
        lot=lot,
    )
    if calibration is not None:  # before any frame: what every analysis will use
        from benchlab.calibration import keep_session_calibration

        keep_session_calibration(session, *calibration)
    session.log_event("run_started", simulate=bench.simulated, estimator=estimator,
                      params_source=source)
    record_in_catalogue(session.path)
    return Runner(procedure_obj, session, bench, prompt=prompt, progress=progress,
                  abort=abort, on_result=on_result, estimator=estimator)


def session_params(session: Session) -> Params:
    """The validated parameter snapshot a session was started with."""
    snap = {k: v for k, v in session.params.items() if k != BENCH_KEY}
    return parse_params(session.procedure, snap, str(session.path / "session.json"))


class RetakeUsageError(UsageError):
    """``--retake`` names a step the session's plan has not, or one not taken yet."""


def retake_steps(session: Session, steps: Sequence[str]) -> list[str]:
    """The step ids ``steps`` (``--retake``) checked against the session's plan: each an
    acquisition step of its procedure, already taken. Returned in plan order, once each.
    Only reads the session.

    Raises
    ------
    RetakeUsageError
        Naming the unknown id and listing the valid ones, or the step not taken yet.
    """
    plan = make_procedure(session_params(session)).steps()
    valid = [s.id for s in plan if s.kind == "acquire"]
    wanted = [s.strip() for s in steps]
    if not wanted or any(not s for s in wanted):
        raise RetakeUsageError(f"--retake: give step ids separated by commas; valid steps of "
                               f"{session.path.name}: {', '.join(valid)}")
    unknown = [s for s in wanted if s not in valid]
    if unknown:
        other = [s for s in unknown if s in {st.id for st in plan}]
        why = (f" ({', '.join(other)}: not an acquisition step, it takes no frames)"
               if other else "")
        raise RetakeUsageError(f"--retake: unknown step {', '.join(map(repr, unknown))}{why}; "
                               f"valid steps of {session.path.name}: {', '.join(valid)}")
    done = session.completed_steps()
    fresh = [s for s in wanted if s not in done]
    if fresh:
        raise RetakeUsageError(f"--retake: step {', '.join(fresh)} has not been taken yet "
                               "(benchlab resume without --retake takes it)")
    return [s for s in valid if s in set(wanted)]


def resume_run(
    session_path: str | Path,
    *,
    bench: Bench,
    prompt: PromptFn | None = None,
    progress: ProgressFn | None = None,
    abort: threading.Event | None = None,
    on_result: ResultFn | None = None,
    estimator: EstimatorChoice | None = None,
    retake: Sequence[str] = (),
    retake_reason: str = "",
) -> Runner:
    """Reopen an interrupted session; ``run()`` continues from its first incomplete step.

    With ``retake`` (step ids, :func:`retake_steps`), also a completed session: ``run()``
    takes those steps again - their earlier frames kept beside the new ones - and
    re-analyses; see :class:`benchlab.protocols.engine.Runner`."""
    check_estimator(estimator)
    session = Session.open(Path(session_path))
    steps = retake_steps(session, retake) if retake else []
    previous = session.status
    if previous == "completed" and not steps:
        raise SessionCompleteError(f"{session.path}: session is complete; nothing to resume")
    params = session_params(session)
    session.hold()  # SessionBusyError naming the live process that writes it
    bad = session.verify_frames()
    if bad:
        session.release()
        raise FramesModifiedError(f"{session.path}: frames changed since acquisition: "
                                  f"{', '.join(bad)}")
    session.remove_temporary_files()  # a kill in the middle of an atomic write
    # A retake records the status it started from at once: killed before it began, a
    # completed session still reads as completed (Session.status).
    session.update_meta(status="running", **({"retake": {
        "status": "starting", "steps": steps, "previous_status": previous}} if steps else {}))
    session.log_event("run_resumed", simulate=bench.simulated, devices=bench.identities())
    record_in_catalogue(session.path)
    return Runner(make_procedure(params), session, bench, prompt=prompt, progress=progress,
                  abort=abort, on_result=on_result, estimator=estimator, retake=steps,
                  retake_reason=retake_reason, previous_status=previous if steps else None)


def reanalyze(session_path: str | Path | Session, estimator: EstimatorChoice | None = None, *,
              catalogue: bool = True, new_version: bool = False) -> Path:
    """Analyse a session's saved frames again into a new results version - or, when an
    existing version has the same frames, settings, software version and byte-identical
    results, into none: that version's folder is returned (and the journal says
    ``results_matched``), so repeated re-analyses do not pile up identical versions.
    ``new_version=True`` always writes one (a benchmark timing the writes).

    Frame hashes are checked against the journal before and after: raw frames are only read.
    ``catalogue=False`` leaves the catalogue update to the caller (a batch records all its
    sessions from its parent process, :func:`benchlab.catalog.index.session_recorder`).
    ``session_path`` may be a :class:`Session` already opened (the CLI opens it and starts
    loading its frames before it imports the analysis).
    """
    check_estimator(estimator)
    session = (session_path if isinstance(session_path, Session)
               else Session.open(Path(session_path)))
    status = session.status  # before holding: a dead writer's "running" is "interrupted"
    session.hold()  # a live run (or another analysis) writing it is named and refused
    try:
        _prefetch_frames(session)
        if status != "completed":
            steps = make_procedure(session_params(session)).steps()
            done = session.completed_steps()
            # Partial when a frame is still to be taken, not because of the status: a run
            # stopped after its last acquisition (or its analysis) has every frame.
            if any(st.id not in done for st in steps if st.kind != "analysis"):
                session.mark_results_partial(status, sum(1 for st in steps if st.id in done),
                                             len(steps))
        session.reuse_identical_results = not new_version
        return _reanalyze_held(session, estimator, catalogue)
    finally:
        session.release()


def _prefetch_frames(session: Session) -> None:
    """Start loading an MTF session's frames (its 15 frames are all analysed) on threads, so
    the inflating overlaps the import of the analysis (``make_procedure``) and the checks that
    follow. Other procedures load their frames themselves (a characterisation has hundreds).
    Parameters that do not parse start nothing: the error comes where it always did. Nor does
    a batch worker (:func:`benchlab.analysis.threads.one_thread`: its siblings have the cores)."""
    from benchlab.analysis.threads import one_thread

    if session.prefetching or one_thread():
        return
    try:
        params = session_params(session)
    except (ParamsError, SessionError):
        return
    if entry_of(params).name == "mtf":
        session.prefetch_frames(FRAME_LOAD_THREADS)


def _reanalyze_held(session: Session, estimator: str | None, catalogue: bool) -> Path:
    procedure = make_procedure(session_params(session))
    # Frames still loading ahead are checked by their loads (the bytes hashed are the bytes
    # analysed), so the analysis starts while the last frames load; every other frame is
    # checked here, and all of them again before any result is written.
    session.verify_frames_before_results = True
    bad = session.verify_frames(trust_loads=True)
    if bad:
        raise FramesModifiedError(f"{session.path}: frames changed since acquisition: "
                                  f"{', '.join(bad)}")
    before = session.frames()
    session.log_event("reanalysis_started", durable=False, estimator=estimator)
    try:
        out = procedure.analyze(session, estimator)
    except SessionError as exc:  # a load found its frame changed: say so as above
        bad = session.verify_frames()
        if bad:
            raise FramesModifiedError(f"{session.path}: frames changed since acquisition: "
                                      f"{', '.join(bad)}") from exc
        raise
    if session.verify_frames() or session.frames() != before:
        raise FramesModifiedError(f"{session.path}: frames changed during re-analysis")
    if catalogue:
        record_in_catalogue(session.path)
    return out


