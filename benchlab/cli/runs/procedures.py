"""``benchlab run``, ``resume``, ``report`` and re-analysis of a session folder."""

from __future__ import annotations

import argparse
import os
import sys
import threading
import time
from collections.abc import Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

from benchlab.cli import PROCEDURES, positive_int
from benchlab.cli.output import add_output_option, print_outcome
from benchlab.drivers.errors import BenchlabError

if TYPE_CHECKING:
    from benchlab.bench import Bench
    from benchlab.session import Session


class _Progress:
    """A one-line progress bar on a terminal; one plain line per step otherwise."""

    def __init__(self, stream: TextIO, width: int = 30) -> None:
        self.stream = stream
        self.tty = stream.isatty()
        self.width = width

    def __call__(self, done: int, total: int, step: Any) -> None:
        title = step.title if step is not None else "done"
        if self.tty:
            filled = int(self.width * done / max(total, 1))
            bar = "#" * filled + "-" * (self.width - filled)
            self.stream.write(f"\r[{bar}] {done}/{total} {title[:50]:<50}")
            if step is None:
                self.stream.write("\n")
        else:
            self.stream.write(f"[{done}/{total}] {title}\n")
        self.stream.flush()

    def line(self, text: str) -> None:
        if self.tty:
            self.stream.write("\r" + " " * (self.width + 60) + "\r")
        self.stream.write(text + "\n")
        self.stream.flush()


def _live_sharpness(bench: Bench, step: Any, stream: TextIO) -> str:
    """Back-focus step on a terminal: show the sharpness of fresh frames until Enter."""
    from benchlab.analysis.focus import sharpness

    answer: list[str] = []
    done = threading.Event()

    def read() -> None:
        try:
            answer.append(input())
        except EOFError:
            answer.append("n")
        done.set()

    threading.Thread(target=read, daemon=True, name="focus-input").start()
    best = 0.0
    while not done.is_set():
        pixels, _ = bench.grab(exposure_ms=step.info.get("exposure_ms", 300.0),
                               gain=step.info.get("gain", 1.0), fresh=False)
        now = sharpness(pixels)
        best = max(best, now)
        stream.write(f"\r  sharpness {now:10.1f}   best {best:10.1f}   [Enter at best focus] ")
        stream.flush()
        done.wait(0.1)  # display pacing only; the camera delivers frames at its own rate
    stream.write("\n")
    return answer[0] if answer else ""


def _prompter(yes: bool, progress: _Progress, bench: Bench) -> Any:
    def prompt(step: Any, message: str) -> bool:
        if yes:
            progress.line(f"  {step.id}: {message} [--yes]")
            return True
        if not sys.stdin.isatty():
            raise BenchlabError(f"step {step.id} needs the operator ({message}); "
                                "run on a terminal or pass --yes")
        progress.line(f"  {step.id}: {message}")
        if step.kind == "focus":
            answer = _live_sharpness(bench, step, progress.stream).strip().lower()
        else:
            answer = input("  Done? [Y/n] ").strip().lower()
        return answer in ("", "y", "yes")

    return prompt


def _print_tables(tables: Mapping[str, Sequence[Mapping[str, Any]]], out: TextIO,
                  partial: bool = False) -> None:
    from benchlab.report.tables import TERMINAL_VIEWS, format_table
    from benchlab.report.text_table import terminal_width

    mark = " [PARTIAL: session incomplete]" if partial else ""
    width = terminal_width()  # the tables fit the terminal (COLUMNS, else 80)
    for name, rows in tables.items():
        view = TERMINAL_VIEWS.get(name)
        if view is None or not rows:
            continue
        out.write(f"\n{view.title}{mark}\n{format_table(rows, view.columns, width)}\n")


def chart_notes(summary: Mapping[str, Any]) -> list[str]:
    """What read the forward view, and the chart finder's warnings (e.g. an implied
    magnification that differs from the configured one: the frequencies are the found
    chart's), from a results summary (``summary.json`` or its ``summary``)."""
    summ = summary.get("summary", summary)
    if not isinstance(summ, Mapping):
        return []
    lines = []
    if summ.get("forward_estimator"):
        lines.append(f"forward view read by: {summ['forward_estimator']}")
    chart = summ.get("chart")
    if isinstance(chart, Mapping):
        lines += [f"warning: chart: {w}" for w in chart.get("warnings") or ()]
    return lines


def _print_notes(doc: Mapping[str, Any], out: TextIO) -> None:
    """What a results version warns about (e.g. clipped or skipped radiometry rows) and the
    response calibration it used."""
    summ = doc.get("summary") or {}
    if not isinstance(summ, Mapping):
        return
    cal = summ.get("linearised")
    if isinstance(cal, Mapping):
        out.write(f"\nlinearised with {cal.get('file')} (sha256 {cal.get('sha256')}"
                  + (f", session copy {cal['copy']}" if cal.get("copy") else "") + ")\n")
    for warning in summ.get("warnings") or ():
        out.write(f"benchlab: warning: {warning}\n")


def _run_or_resume(args: argparse.Namespace, resume: bool) -> int:
    from benchlab.bench import Bench, BenchConfig
    from benchlab.protocols import RunAborted, RunInterrupted, StepFailed
    from benchlab.protocols.runs import check_estimator, resume_run, start_run

    progress = _Progress(sys.stderr)
    retake = _retake_arg(args) if resume else []
    if resume:
        session_path = Path(args.session)
        if _resume_preflight(session_path, retake):
            return 0
        if args.config:
            config = BenchConfig.load(args.config, simulate=args.simulate)
        else:
            config = BenchConfig.from_session(session_path)
    else:
        from benchlab.cli.config import bench_file_in_force, sessions_in_force

        bench_file = bench_file_in_force(args.config, simulate=args.simulate)
        if not args.simulate and bench_file.value is None:
            raise BenchlabError("the real bench needs a bench file: --config bench.toml, or "
                                "`benchlab config init` for a default one (or use --simulate)")
        config = BenchConfig.load(bench_file.value, simulate=args.simulate)
        sessions_root = sessions_in_force(args.out).value
        from benchlab.session import check_sessions_root

        check_sessions_root(sessions_root)  # before any device is opened
    check_estimator(getattr(args, "estimator", None))
    params = None
    if not resume:
        from benchlab.protocols.params import load_params

        # Every parameter problem, bench limits included, is reported before a device is opened.
        params = load_params(args.procedure, args.params, config.limits())
    t0 = time.perf_counter()
    runner = None
    try:
        with Bench.open(config, simulate=args.simulate) as bench:
            kwargs = dict(bench=bench, prompt=_prompter(args.yes, progress, bench),
                          progress=progress,
                          estimator=getattr(args, "estimator", None))
            if resume:
                runner = resume_run(session_path, retake=retake,
                                    retake_reason=getattr(args, "reason", None) or "", **kwargs)
            else:
                runner = start_run(args.procedure, params=params, root=sessions_root,
                                   operator=args.operator, sample=args.sample,
                                   lot=args.lot, **kwargs)
            progress.line(f"session: {runner.session.path}")
            outcome = runner.run()
    except (StepFailed, RunAborted) as exc:
        from benchlab.drivers.trace import replay

        diverged = replay.divergence_behind(exc)
        if diverged is not None:  # not a measurement failure: the replay stopped matching
            step = f" (step {exc.step.id})" if isinstance(exc, StepFailed) else ""
            progress.line(f"benchlab: error: {diverged}{step}")
        elif isinstance(exc, StepFailed):  # safety is said once, on the line below
            progress.line(f"benchlab: step {exc.step.id} ({exc.step.title}) failed: "
                          f"{exc.cause}")
        else:
            progress.line(f"benchlab: {exc}")
        if runner is not None:
            progress.line(_safety(runner.unsafe, diverged) + "; "
                          + _continue_with(runner.session, args, retake))
        return exc.exit_status if isinstance(exc, RunInterrupted) else 1
    except KeyboardInterrupt as exc:
        if runner is None:
            raise
        from benchlab.drivers import shutdown

        progress.line(f"benchlab: interrupted ({shutdown.interrupt_reason(exc)}); "
                      + _safety(runner.unsafe, None) + "; "
                      + _continue_with(runner.session, args, retake))
        return shutdown.exit_status(exc)
    elapsed = time.perf_counter() - t0
    _print_tables(outcome.tables, sys.stdout)
    _print_notes(outcome.summary, sys.stdout)
    notes = chart_notes(outcome.summary)
    if notes:
        print("\n" + "\n".join(notes))
    if outcome.summary.get("summary", {}).get("procedure") == "characterise":
        from benchlab.protocols.characterise.steps import run_notes

        print("\n" + "\n".join(run_notes(outcome.session_path, outcome.summary)))
    if retake:
        from benchlab.session import Session

        done = Session.open(outcome.session_path).retakes()[-1]
        print(f"\nretake {done['id']} adopted: " + ", ".join(
            f"{s} take {n}" for s, n in sorted((done.get("current") or {}).items()))
              + " current; the earlier takes are kept in frames/ (never analysed)")
    print(f"\nsession: {outcome.session_path}")
    print(f"results: {outcome.results_path}")
    print(f"wall time: {elapsed:.1f} s")
    return 0


def _retake_arg(args: argparse.Namespace) -> list[str]:
    """``--retake STEP[,STEP...]`` as a list (empty without it); ``--reason`` needs it."""
    text = getattr(args, "retake", None)
    if text is None:
        if getattr(args, "reason", None):
            from benchlab.drivers.errors import UsageError

            raise UsageError("--reason: only with --retake (it says why steps are retaken)")
        return []
    return text.split(",")


def _safety(unsafe: str, diverged: str | None) -> str:
    """The one statement on safety after a run stopped, from the devices' read-back: the
    safe state confirmed, or why not."""
    if diverged is not None:
        return ("safe state not confirmed: the replayed devices stop answering where the "
                "replay diverged (no real device was driven)")
    if unsafe:
        why = unsafe.removeprefix("could not reach the safe state: ")
        return f"bench NOT confirmed safe ({why}); check the LEDs and the stage by hand"
    return "bench left safe (confirmed by the devices' read-back)"


def _continue_with(session: Session, args: argparse.Namespace, retake: list[str]) -> str:
    """What to type next after a stopped run; for a retake, which takes are current."""
    sim = " --simulate" if args.simulate else ""
    if not retake:
        return f"continue with: benchlab resume {session.path}{sim}"
    last = session.retakes()[-1] if session.retakes() else {}
    stale = session.results_stale()
    if last.get("status") == "adopted":
        told = "the retake's frames are current"
        return told + (f"; results are stale: {stale}" if stale else "")
    return (f"retake {last.get('id', '?')} stopped: the previous takes of "
            f"{', '.join(retake)} stay current; take them again with: benchlab resume "
            f"{session.path} --retake {','.join(retake)}{sim}")


def _resume_preflight(session_path: Path, retake: list[str]) -> bool:
    """Before any device is opened: True (nothing to do) for a completed session (unless
    steps are to be retaken: their ids are checked here against the plan); a session
    another live process writes is refused, naming it (opening the bench would switch its
    LEDs off under it)."""
    from benchlab.session import Session, SessionBusyError, describe_holder, session_holder

    session = Session.open(session_path)
    if retake:
        from benchlab.protocols.runs import retake_steps

        retake_steps(session, retake)  # an unknown or untaken step: exit 2, nothing changed
    elif session.status == "completed":
        stale = session.results_stale()
        print(f"{session.path}: session is complete; nothing to resume (unchanged)"
              + (f"; results are stale: {stale}" if stale else ""))
        return True
    holder = session_holder(session_path)
    if holder is not None:
        raise SessionBusyError(f"{session.path}: session is in use by {describe_holder(holder)}"
                               "; wait for it to end or stop that process")
    return False


def run_command(args: argparse.Namespace) -> int:
    return _run_or_resume(args, resume=False)


def resume_command(args: argparse.Namespace) -> int:
    return _run_or_resume(args, resume=True)


def _open_prefetching(folder: Path) -> Session | None:
    """The MTF session at ``folder``, its frames already loading on threads (inflating
    releases the GIL), so the loads overlap the import of the protocols and the analysis;
    None for anything else, which :func:`reanalyze` then opens and reports on as always (a
    folder that is not a session, another procedure)."""
    from benchlab.session import FRAME_LOAD_THREADS, Session, SessionError

    try:
        session = Session.open(folder)
        if session.procedure != "mtf":
            return None
        session.prefetch_frames(FRAME_LOAD_THREADS)
    except (SessionError, OSError, KeyError):
        return None
    return session


def analyze_session_command(args: argparse.Namespace) -> int:
    """Re-analyse a session folder (``args.target``) into a new results version."""
    target = next(
        (getattr(args, a) for a in ("target", "session", "image", "path")
         if getattr(args, a, None)),
        None,
    )
    if target is None:
        raise BenchlabError("analyze: no session folder given")
    t0 = time.perf_counter()
    started = datetime.now(UTC)  # a version created before this is one the analysis matched
    estimator = getattr(args, "estimator", None)
    early = _open_prefetching(Path(target))
    # The catalogue update runs on its own thread: it imports the catalogue (and SQLite) while
    # the analysis runs, records once the results are written, overlapping the printing; it
    # never raises, and the process waits for it before it ends. Nothing is recorded when the
    # re-analysis fails.
    recorder = _CatalogueRecorder(Path(target))
    recorder.start()
    try:
        from benchlab.protocols.runs import reanalyze

        out = reanalyze(early or Path(target), estimator=estimator, catalogue=False)
        recorder.record = True
    except KeyboardInterrupt:
        # Stopped: the catalogue thread (a daemon) is left to end without recording, not
        # waited for: a stop signal raised while this thread is inside the import machinery
        # can leave the import lock held, and that thread's import then never ends.
        recorder.abandoned = True
        raise
    finally:
        recorder.results_written.set()
        if not recorder.record and not recorder.abandoned:
            recorder.join()  # failed: it ends without recording
        if early is not None:
            early.stop_prefetch()
    elapsed = time.perf_counter() - t0
    try:
        return _print_reanalysis(args, out, elapsed, started)
    finally:
        recorder.join()


class _CatalogueRecorder(threading.Thread):
    """Records a session in its catalogue once :attr:`results_written` is set (and
    :attr:`record` is true), the catalogue imported beforehand."""

    def __init__(self, folder: Path) -> None:
        super().__init__(name="benchlab-catalogue", daemon=True)  # never holds the exit up
        self.folder = folder
        self.results_written = threading.Event()
        self.record = False
        self.abandoned = False

    def run(self) -> None:
        from benchlab.catalog.index import record_session  # beside the analysis

        self.results_written.wait()
        if self.record:
            record_session(self.folder)


def matched_version(summary: Mapping[str, Any], started: datetime) -> int | None:
    """The version a re-analysis that began at ``started`` matched (its results identical to
    an existing version's, so none was written): the one returned was created before it."""
    try:
        created = datetime.fromisoformat(str(summary.get("created_at")))
    except ValueError:
        return None
    version = summary.get("version")
    if created < started and isinstance(version, int):
        return version
    return None


def _print_reanalysis(args: argparse.Namespace, out: Path, elapsed: float,
                      started: datetime) -> int:
    from benchlab.session import read_results

    as_json = getattr(args, "json", False)
    if as_json:
        tables, summary = read_results(out)
    else:  # only the tables printed (the SFR curves, the largest file, are not)
        from benchlab.report.tables import TERMINAL_VIEWS

        tables, summary = read_results(out, TERMINAL_VIEWS)
    partial = bool(summary.get("partial"))
    note = (f"session {summary.get('session_status')}: {summary.get('steps_done')} of "
            f"{summary.get('steps_total')} steps done; tables are partial") if partial else ""

    def text() -> None:
        _print_tables(tables, sys.stdout, partial=partial)
        _print_notes(summary, sys.stdout)
        notes = chart_notes(summary)
        if notes:
            print("\n" + "\n".join(notes))
        if partial:
            print(f"\nbenchlab: note: {note}")
        print(f"\nresults: {out}  (frames verified unchanged; {elapsed:.2f} s)")
        matched = matched_version(summary, started)
        if matched is not None:
            print(f"identical to v{matched} (same frames, settings, software version and "
                  "results): no new version written")

    status = print_outcome(as_json, lambda: {
        "results": str(out), "tables": tables, "seconds": elapsed, "partial": partial,
        "matched_version": matched_version(summary, started)}, text)
    if as_json and partial:  # the JSON document says it; the note is for a person
        print(f"benchlab: note: {note}", file=sys.stderr)
    return status


def report_command(args: argparse.Namespace) -> int:
    from benchlab.cli.output import check_output, forced
    from benchlab.report.render import write_report

    session = Path(args.session)
    force = forced(args)
    target = check_output(args.out or session / "report.html", force=force,
                          option="--out" if args.out else "report")
    try:
        out = write_report(session, target, overwrite=force)
    except FileExistsError:  # appeared while the report was rendered
        check_output(target, force=False, option="--out" if args.out else "report")
        raise
    print(f"report: {out}")
    return 0


def benchmark_characterise_command(args: argparse.Namespace) -> int:
    """``benchlab benchmark characterise``: the characterisation figures (simulated bench)."""
    from benchlab.benchmarks.characterise import (
        all_pass,
        format_benchmark,
        run_benchmark,
    )

    out = run_benchmark(Path(args.keep) if args.keep else None)
    print(format_benchmark(out))
    print("\nall figures within the issue's tolerances" if all_pass(out)
          else "\nsome figures are outside the issue's tolerances")
    return 0


def benchmark_report_command(args: argparse.Namespace) -> int:
    """``benchlab benchmark report [SESSION]``: seconds to render a report, per section."""
    import statistics
    import tempfile

    from benchlab.report.render import render_report

    with tempfile.TemporaryDirectory() as tmp:
        if args.session:
            path = Path(args.session)
        else:
            from benchlab.bench import Bench, BenchConfig
            from benchlab.protocols import load_params, start_run

            print("simulating a Table 4.10 MTF session (default parameters) ...", flush=True)
            config = BenchConfig.load(None, simulate=True)
            params = load_params("mtf", None, config.limits())
            with Bench.open(config, simulate=True) as bench:
                path = start_run("mtf", bench=bench, params=params, root=tmp, operator="bench",
                                 prompt=lambda step, msg: True).run().session_path
        walls: list[float] = []
        cpus: list[float] = []
        sections: dict[str, list[float]] = {}
        for _ in range(args.repeats):
            timings: dict[str, float] = {}
            t0, c0 = time.perf_counter(), time.process_time()
            render_report(path, timings)
            walls.append(time.perf_counter() - t0)
            cpus.append(time.process_time() - c0)
            for k, v in timings.items():
                sections.setdefault(k, []).append(v)
    print(f"report of {path.name}: median {statistics.median(walls):.3f} s, "
          f"min {min(walls):.3f} s over {args.repeats} renders (imports excluded; target 1 s)")
    # CPU time does not grow with other processes' load as wall time does.
    print(f"  CPU time: median {statistics.median(cpus):.3f} s, min {min(cpus):.3f} s; "
          f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
    for name, secs in sections.items():
        print(f"  {name:<12} {1000 * statistics.median(secs):8.1f} ms")
    return 0


def register(commands: argparse._SubParsersAction, benchmarks: argparse._SubParsersAction) -> None:
    """Add ``run``, ``resume``, ``report`` and ``benchmark report``."""
    run = commands.add_parser(
        "run", help="run a procedure (Table 4.10 MTF, section 4.4 radiometry, the camera "
        "characterisation, depth of field through focus or the field of view)",
        description="Run a measurement procedure into a new session folder, with a progress "
        "bar. Manual steps are prompts; --yes answers them (unattended simulated runs).",
    )
    run.add_argument("procedure", choices=PROCEDURES,
                     help="mtf: the Table 4.10 MTF test; radiometry: section 4.4 relative "
                     "radiometry; characterise: EMVA 1288 photon transfer of the camera; depth: "
                     "MTF through focus on the stage (best focus, depth of field); fov: field "
                     "of view, direction of view, entrance pupil and image-height mapping of "
                     "the forward view from a dot-grid chart at several stage distances")
    run.add_argument("--simulate", action="store_true", help="use the simulated bench")
    run.add_argument("--config", help="bench configuration TOML (ports, ceilings, travel; "
                     "default: the user's, see `benchlab config show`)")
    run.add_argument("--params", help="procedure parameter TOML (default: packaged)")
    run.add_argument("--yes", action="store_true", help="confirm every manual step")
    run.add_argument("--out", help="folder for sessions (default: [paths] sessions of the "
                     "user's bench.toml, else ./sessions)")
    run.add_argument("--operator", default="", help="operator name for session.json")
    run.add_argument("--sample", "--serial", dest="sample", default="", metavar="ID",
                     help="serial number of the lens or unit under test (the catalogue "
                     "groups trends by it; benchlab verify groups sessions into units by it)")
    run.add_argument("--lot", default="", metavar="LOT",
                     help="production lot of the unit under test (benchlab lot LOT)")
    run.add_argument("--estimator", help="modulation estimator (default: params / library)")
    run.set_defaults(func=run_command)

    res = commands.add_parser(
        "resume", help="continue an interrupted session from its first incomplete step, or "
        "retake steps of any session (--retake)",
        description="Continue an interrupted run (Ctrl-C, crash, kill -9) from the first "
        "incomplete step; nothing acquired is repeated or lost. With --retake STEP[,STEP...] "
        "(also of a completed session): take those acquisition steps again (e.g. a bumped "
        "fibre spoilt a frame), then re-analyse. The earlier frames are never deleted or "
        "edited: the new ones are saved beside them as <step>__<name>.take<N>.tiff and "
        "become current only when every retaken step has its new frames (one journal line "
        "records which take is current, and why); a retake that is stopped leaves the "
        "previous takes current and says so, and a completed session stays completed.",
    )
    res.add_argument("session", help="session folder")
    res.add_argument("--simulate", action="store_true", help="use the simulated bench")
    res.add_argument("--config", help="bench configuration TOML (default: the session's)")
    res.add_argument("--yes", action="store_true", help="confirm every manual step")
    res.add_argument("--estimator", help="modulation estimator for the final analysis")
    res.add_argument("--retake", metavar="STEP[,STEP...]",
                     help="acquisition steps to take again (e.g. position-18 or forward); an "
                     "unknown id is refused, listing the valid ones")
    res.add_argument("--reason", metavar="TEXT",
                     help="why the steps are retaken (journalled, in session.json)")
    res.set_defaults(func=resume_command)

    rep = commands.add_parser(
        "report", help="write a self-contained HTML report of a session",
        description="Write a self-contained HTML report: tables; measured bar contrast against "
        "the simulated optics converted to CTF (never CTF against MTF); Table 4.15's verdict "
        "with the Monte Carlo bands; frames with their ROIs; for every ROI the evidence (crop, "
        "histogram with the levels, profile across the bars, reading with its 95 % interval, "
        "estimator, warnings); the radiometry fall-off and LED masks; parameters.",
    )
    rep.add_argument("session", help="session folder")
    add_output_option(rep, "--out", help="output file (default SESSION/report.html)")
    rep.set_defaults(func=report_command)

    bch = benchmarks.add_parser(
        "characterise", help="camera characterisation figures on the simulated bench",
        description="Run the characterisation on the simulated bench and compare K, read "
        "noise, saturation, linearity error, DSNU and PRNU with the simulator's truth (issue "
        "tolerances); then characterise a non-linear simulated camera and show radiometry "
        "readings without and with the response calibration against the linear camera. "
        "About 30 s.",
    )
    bch.add_argument("--keep", metavar="DIR", help="keep the sessions in DIR (default: temporary)")
    bch.set_defaults(func=benchmark_characterise_command)

    brep = benchmarks.add_parser(
        "report", help="seconds to render an HTML report, per section",
        description="Render the report of SESSION (default: a fresh simulated Table 4.10 MTF "
        "session) several times and print the median wall time and each section's share.",
    )
    brep.add_argument("session", nargs="?", help="session folder (default: simulate one)")
    brep.add_argument("--repeats", type=positive_int, default=5, help="renders to time (default 5)")
    brep.set_defaults(func=benchmark_report_command)
