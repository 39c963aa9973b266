"""Session details from the review: results folders follow the umask, radiometry positions
that would be one step are refused before any folder exists, a reader asking who holds a
session never makes hold() fail, and results are partial only when frames are missing."""

from __future__ import annotations

import json
import multiprocessing
import os
import stat
from pathlib import Path
from typing import Any

import pytest
from sim_runs import FIXTURES, RAD_SMALL, run_sim, yes

from benchlab.bench import Bench, BenchConfig
from benchlab.cli.main import main
from benchlab.protocols import ParamsError, load_params, reanalyze, resume_run, start_run
from benchlab.protocols.runs import make_procedure, session_params
from benchlab.session import Session, SessionBusyError, session_holder

RAD_DEFAULT = FIXTURES.parent.parent / "benchlab" / "protocols" / "defaults" / "radiometry.toml"


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _new_session(root: Path) -> Session:
    return Session.create(root, procedure="radiometry", params={}, operator="t", devices={},
                          software_version="0")


def test_results_folders_follow_the_umask(tmp_path: Path) -> None:
    session = _new_session(tmp_path)
    out = session.write_results({"t": [{"a": 1}]}, summary={}, estimator="x")
    want = 0o777 & ~_umask()
    assert want != 0o700  # the test means something only with a group- or world-readable mask
    assert stat.S_IMODE(os.stat(out).st_mode) == want
    from benchlab.storage import make_staging_dir  # the unwrapped views' staging folder too

    assert stat.S_IMODE(os.stat(make_staging_dir(tmp_path, ".u-")).st_mode) == want


def _rad(tmp_path: Path, **replace: str) -> Path:
    text = RAD_DEFAULT.read_text()
    for old, new in replace.items():
        assert old in text
        text = text.replace(old, new)
    path = tmp_path / "p.toml"
    path.write_text(text)
    return path


def test_positions_that_would_be_one_step_are_refused(tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    for positions in ("[15, 15.0000001, 20, 25, 32]", "[15, 15, 20, 25, 32]"):
        params = _rad(tmp_path, **{"[15, 18, 20, 25, 32]": positions})
        with pytest.raises(ParamsError, match=r"positions.field_mm\[1\]: .*position-15"):
            load_params("radiometry", params)
        assert main(["run", "radiometry", "--simulate", "--yes", "--params", str(params),
                     "--out", str(tmp_path / "s")]) == 1
        err = capsys.readouterr().err
        assert "positions.field_mm[1]" in err and "Traceback" not in err
    assert not list((tmp_path / "s").glob("*_radiometry"))  # no session folder was made


def test_equal_irradiance_values_are_valid(tmp_path: Path) -> None:
    params = _rad(tmp_path, **{"19.40, 14.34": "19.40, 19.40"})
    assert load_params("radiometry", params).simulated_irradiance_mw_per_mm2[3] == 19.4
    zero = _rad(tmp_path, **{"[22.48, 21.21, 19.40, 14.34, 3.014]": "[0, 0.0, 0.0, 0.0, 0.0]"})
    with pytest.raises(ParamsError, match="simulated_irradiance_mw_per_mm2: needs a value "
                                          "above 0"):
        load_params("radiometry", zero)


def test_mask_threshold_fraction_is_open_at_one(tmp_path: Path) -> None:
    for bad in ("1.0", "0.0"):
        params = _rad(tmp_path, **{"mask_threshold_fraction = 0.5":
                                   f"mask_threshold_fraction = {bad}"})
        with pytest.raises(ParamsError, match=r"mask_threshold_fraction: must be in \(0.0, "
                                              r"1.0\)"):
            load_params("radiometry", params)
    params = _rad(tmp_path, **{"mask_threshold_fraction = 0.5": "mask_threshold_fraction = 0.99"})
    assert load_params("radiometry", params).mask_threshold_fraction == 0.99


def _ask_who_holds(folder: str, stop: Any) -> None:
    while not stop.is_set():
        session_holder(folder)


def test_a_reader_asking_who_holds_never_makes_hold_fail(tmp_path: Path) -> None:
    session = _new_session(tmp_path)
    session.release()
    ctx = multiprocessing.get_context("fork")
    stop = ctx.Event()
    reader = ctx.Process(target=_ask_who_holds, args=(str(session.path), stop))
    reader.start()
    busy = 0
    try:
        for _ in range(400):
            s = Session.open(session.path)
            try:
                s.hold("test")
            except SessionBusyError:
                busy += 1
            s.release()
    finally:
        stop.set()
        reader.join()
    assert busy == 0
    # A live holder is still reported, by pid.
    holder = Session.open(session.path)
    holder.hold("benchlab run radiometry")
    with pytest.raises(SessionBusyError, match=f"pid {os.getpid()}"):
        Session.open(session.path).hold()
    holder.release()


def _stopped_after_last_step(root: Path) -> Path:
    """A run interrupted just after its last step completed (Ctrl-C while "done" prints)."""
    def progress(done: int, total: int, step: Any) -> None:
        if step is None:
            raise KeyboardInterrupt("SIGINT")

    with Bench.open(BenchConfig.load(None, simulate=True), simulate=True) as bench:
        runner = start_run("radiometry", bench=bench, params=RAD_SMALL, root=root, prompt=yes,
                           progress=progress)
        with pytest.raises(KeyboardInterrupt):
            runner.run()
    return Path(runner.session.path)


@pytest.mark.slow
def test_every_frame_taken_is_not_partial_and_resume_finishes_partial_results(
        tmp_path: Path) -> None:
    path = _stopped_after_last_step(tmp_path)
    assert Session.open(path).status == "interrupted"
    again = reanalyze(path)
    doc = json.loads((again / "summary.json").read_text())
    assert doc["partial"] is False  # every acquisition step is done
    assert again.name == "v1"  # the run's own results, byte for byte: no new version
    # Results an older version wrote as partial for such a session: the resume that finds
    # every step done writes final results instead of ending on partial ones.
    session = Session.open(path)
    session.hold()
    session.mark_results_partial("interrupted", 5, 5)
    make_procedure(session_params(session)).analyze(session, None)
    session.release()
    with Bench.open(BenchConfig.load(None, simulate=True), simulate=True) as bench:
        outcome = resume_run(path, bench=bench, prompt=yes).run()
    assert outcome.results_path.name == "v3"  # v1 the run (and the re-analysis), v2 partial
    assert outcome.summary["partial"] is False
    assert Session.open(path).status == "completed"


@pytest.mark.slow
def test_a_run_stopped_before_its_frames_is_still_partial(tmp_path: Path) -> None:
    out = run_sim("radiometry", tmp_path, RAD_SMALL)
    meta = json.loads((out.session_path / "session.json").read_text())
    assert meta["status"] == "completed"
    with Bench.open(BenchConfig.load(None, simulate=True), simulate=True) as bench:
        def progress(done: int, total: int, step: Any) -> None:
            if step is not None and step.id == "position-25":
                raise KeyboardInterrupt("SIGINT")

        runner = start_run("radiometry", bench=bench, params=RAD_SMALL, root=tmp_path / "b",
                           prompt=yes, progress=progress)
        with pytest.raises(KeyboardInterrupt):
            runner.run()
    doc = json.loads((reanalyze(runner.session.path) / "summary.json").read_text())
    assert doc["partial"] is True and doc["steps_done"] == 3
