"""The scripting API at ``import benchlab`` (issue 26 item 5): a run on the simulated bench read
back through the API, bad inputs refused with messages that name what is wrong, aborted runs
left resumable, the analysis calls against known truth, and the import kept lazy."""

from __future__ import annotations

import ast
import doctest
import importlib
import json
import math
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.special import erf
from sim_runs import MTF_SMALL, events, only_session

import benchlab
from benchlab.analysis import ModulationResult
from benchlab.analysis.chart.finder import ChartNotFoundError
from benchlab.analysis.chart.reading import ChartReading
from benchlab.analysis.sfr.measure import SfrRefused, SfrResult
from benchlab.bench import Bench, BenchConfigError
from benchlab.drivers.errors import UsageError
from benchlab.protocols import ParamsError, RunAborted, RunOutcome
from benchlab.session import Session, SessionError

STUB = Path(benchlab.__file__).with_name("__init__.pyi")


@pytest.fixture(scope="module")
def bench() -> Iterator[Bench]:
    """One simulated bench for every run of this module (opening it costs ~0.3 s)."""
    with benchlab.open_bench(simulate=True) as opened:
        yield opened


@pytest.fixture(scope="module")
def small_run(bench: Bench, tmp_path_factory: pytest.TempPathFactory
              ) -> tuple[RunOutcome, list[benchlab.Prompt]]:
    """A short MTF run (two forward elements, two radial frequencies), every prompt answered
    yes and recorded."""
    asked: list[benchlab.Prompt] = []

    def answer(prompt: benchlab.Prompt) -> bool:
        asked.append(prompt)
        return True

    out = tmp_path_factory.mktemp("api") / "sessions"
    run = benchlab.run_procedure(bench, "mtf", params=MTF_SMALL, out=out, answer=answer,
                                 operator="ana", sample="proto-3")
    return run, asked


# --------------------------------------------------------------------------- a run, read back


@pytest.mark.slow
def test_a_run_answers_prompts_and_returns_its_outcome(
        small_run: tuple[RunOutcome, list[benchlab.Prompt]]) -> None:
    run, asked = small_run
    assert isinstance(run, RunOutcome)
    assert run.session_path.is_dir() and run.results_path == run.session_path / "results" / "v1"
    ids = [p.step_id for p in asked]
    assert ids[:3] == ["setup", "thread", "focus"]
    assert {"roll-0.5-sagittal", "roll-2-tangential"} <= set(ids)
    focus = asked[ids.index("focus")]
    assert focus.kind == "focus" and "Sharpness now" in focus.message
    assert all(str(p) == p.message and p.title for p in asked)
    meta = json.loads((run.session_path / "session.json").read_text())
    assert (meta["operator"], meta["sample"], meta["status"]) == ("ana", "proto-3", "completed")


def test_open_session_reads_the_tables_with_their_types(
        small_run: tuple[RunOutcome, list[benchlab.Prompt]]) -> None:
    run, _ = small_run
    session = benchlab.open_session(run.session_path)
    assert isinstance(session, Session)
    assert session.status == "completed" and session.procedure == "mtf"
    assert session.tables() == ["forward_view_modulation", "radial_view_modulation",
                                "image_heights_field_points", "averaged_mtf_vs_monte_carlo",
                                "table_sfr_curves", "table_sfr_edges", "table_sfr_vs_bars",
                                "simulator_truth"]  # the simulated bench's, after the rest
    rows = session.table("forward_view_modulation")
    assert [r["element"] for r in rows] == ["G1E5", "G2E1"]
    first = rows[0]
    assert isinstance(first["sagittal_modulation"], float)
    assert 0.3 < first["sagittal_modulation"] < 1.0
    assert isinstance(first["sagittal_resolved"], bool) and first["sagittal_resolved"]
    assert all(isinstance(v, int) for v in first["sagittal_roi"])
    # the thesis label names the same table; both are what the run handed back
    assert session.table("table_4_11") == rows == list(run.tables["table_4_11"])


def test_frames_are_listed_and_loaded_checked(
        small_run: tuple[RunOutcome, list[benchlab.Prompt]]) -> None:
    run, _ = small_run
    session = benchlab.open_session(run.session_path)
    assert "frames/forward__forward.tiff" in session.frames()
    assert len(session.frames()) == 5  # the forward frame and four radial ones
    frame = session.frame("forward__forward.tiff")
    assert frame.shape == (1024, 1280) and frame.dtype == np.uint8
    pixels, _ = session.load_frame("forward", "forward")
    np.testing.assert_array_equal(frame, pixels)
    # the keys of frames() are accepted as they are
    np.testing.assert_array_equal(session.frame("frames/forward__forward.tiff"), pixels)


def test_the_api_reads_the_session_frame_as_the_procedure_did(
        small_run: tuple[RunOutcome, list[benchlab.Prompt]]) -> None:
    """measure_chart + measure_bars on the saved frame give Table 4.11's numbers (the small
    run reads the forward view with the histogram estimator at the found sets' ROIs)."""
    run, _ = small_run
    session = benchlab.open_session(run.session_path)
    frame = session.frame("forward__forward.tiff")
    chart = benchlab.measure_chart(frame)
    assert isinstance(chart, ChartReading)
    assert len(chart.readings) == len(chart.fit.found) == len(chart.labels) > 20
    assert all(isinstance(r, ModulationResult) for r in chart.readings)
    compared = 0
    for row in session.table("forward_view_modulation"):
        group, element = int(row["element"][1]), int(row["element"][3])
        for side in ("sagittal", "tangential"):
            r0, c0, r1, c1 = row[f"{side}_roi"]
            found = chart.fit.element(group, element, side)
            result = benchlab.measure_bars(frame[r0:r1, c0:c1], estimator="histogram",
                                           **found.estimator_priors())
            assert row[f"{side}_estimator"] == "histogram"
            assert round(result.modulation, 6) == row[f"{side}_modulation"]
            compared += 1
    assert compared == 4


def test_a_changed_frame_is_refused(small_run: tuple[RunOutcome, list[benchlab.Prompt]],
                                    tmp_path: Path) -> None:
    run, _ = small_run
    copy = shutil.copytree(run.session_path, tmp_path / "copy")
    tiff = copy / "frames" / "radial-2-sagittal__radial.tiff"
    data = bytearray(tiff.read_bytes())
    data[-1] ^= 0xFF
    tiff.write_bytes(bytes(data))
    session = benchlab.open_session(copy)
    with pytest.raises(SessionError, match=r"radial-2-sagittal__radial\.tiff: frame modified "
                                           r"since it was saved \(sha256 mismatch\)"):
        session.frame("radial-2-sagittal__radial.tiff")


# --------------------------------------------------------------------------- refused inputs


def test_missing_table_names_it_and_lists_the_tables(
        small_run: tuple[RunOutcome, list[benchlab.Prompt]]) -> None:
    session = benchlab.open_session(small_run[0].session_path)
    with pytest.raises(SessionError) as err:
        session.table("forward_view_modulatoin")
    text = str(err.value)
    assert "results/v1: no table 'forward_view_modulatoin'; its tables: " \
           "forward_view_modulation, radial_view_modulation, image_heights_field_points," in text


def test_missing_frame_names_it_and_lists_the_frames(
        small_run: tuple[RunOutcome, list[benchlab.Prompt]]) -> None:
    session = benchlab.open_session(small_run[0].session_path)
    with pytest.raises(SessionError) as err:
        session.frame("forward.tiff")
    assert (f"{session.path}: no frame 'forward.tiff' in this session; its frames: "
            "forward__forward.tiff, radial-0.5-sagittal__radial.tiff,") in str(err.value)


def test_unknown_procedure_is_refused_before_anything_is_made(bench: Bench,
                                                               tmp_path: Path) -> None:
    with pytest.raises(UsageError, match=r"^run_procedure: unknown procedure 'mft'; choose "
                                         r"mtf, radiometry, characterise, depth, fov$"):
        benchlab.run_procedure(bench, "mft", out=tmp_path / "s", answer=lambda p: True)
    assert not (tmp_path / "s").exists()


def test_an_answer_that_is_no_callable_is_refused(bench: Bench, tmp_path: Path) -> None:
    with pytest.raises(UsageError, match=r"^run_procedure: answer must be a callable taking a "
                                         r"Prompt, got bool$"):
        benchlab.run_procedure(bench, "mtf", out=tmp_path / "s", answer=True)  # type: ignore[arg-type]
    assert not (tmp_path / "s").exists()


def test_bad_parameters_are_refused_before_anything_is_made(bench: Bench,
                                                            tmp_path: Path) -> None:
    params = tmp_path / "p.toml"
    params.write_text('procedure = "mtf"\n[camera]\nexposure_ms = -3\n')
    with pytest.raises(ParamsError, match=r"p\.toml: 1 problem:\n  camera\.exposure_ms"):
        benchlab.run_procedure(bench, "mtf", params=params, out=tmp_path / "s",
                               answer=lambda p: True)
    assert not (tmp_path / "s").exists()


def test_bad_bench_files_are_named(tmp_path: Path) -> None:
    missing = tmp_path / "nope.toml"
    with pytest.raises(BenchConfigError,
                       match=rf"^{missing}: 1 problem:\n  file: no such bench configuration$"):
        with benchlab.open_bench(missing, simulate=True):
            pass
    bad = tmp_path / "bench.toml"
    bad.write_text("[stage]\ntravel_mm = [40.0, 10.0]\n")
    with pytest.raises(BenchConfigError, match=r"bench\.toml: 1 problem:\n  stage\.travel_mm: "
                                               r"must be \[low, high\] with low < high"):
        with benchlab.open_bench(bad):
            pass
    with pytest.raises(UsageError, match=r"the real bench needs a bench file"):
        with benchlab.open_bench():
            pass


def test_a_folder_that_is_no_session_is_named(tmp_path: Path) -> None:
    with pytest.raises(SessionError, match=r"session\.json: no session file \(is .* a session"):
        benchlab.open_session(tmp_path)


# --------------------------------------------------------------------------- stopped runs


def _stopped(bench: Bench, out: Path, answer: Any) -> tuple[RunAborted, Session]:
    with pytest.raises(RunAborted) as err:
        benchlab.run_procedure(bench, "mtf", params=MTF_SMALL, out=out, answer=answer)
    folder = only_session(out)
    assert err.value.session_path == folder
    return err.value, benchlab.open_session(folder)


def test_an_answer_of_false_leaves_an_aborted_session(bench: Bench, tmp_path: Path) -> None:
    exc, session = _stopped(bench, tmp_path, lambda p: p.step_id != "radial-setup")
    assert str(exc) == "operator declined at step radial-setup"
    assert session.status == "aborted"
    assert [e["step"] for e in events(session.path) if e["kind"] == "aborted"] == ["radial-setup"]
    # what was acquired before is kept; no results were written
    assert list(session.frames()) == ["frames/forward__forward.tiff"]
    assert session.tables() == []
    with pytest.raises(SessionError, match=r"no results yet \(session aborted\), so no table "
                                           r"'forward_view_modulation'"):
        session.table("forward_view_modulation")
    # the bench was left safe: every LED channel off, the stage at rest
    assert bench.sim_led is not None and bench.sim_stage is not None
    assert [bench.sim_led.channel_output_ma(ch)
            for ch in range(1, bench.sim_led.channel_count + 1)] == [0.0] * 4
    assert not bench.sim_stage.moving


def test_no_answer_stops_at_the_first_prompt(bench: Bench, tmp_path: Path) -> None:
    exc, session = _stopped(bench, tmp_path, None)
    assert str(exc).startswith("step setup needs the operator (")
    assert str(exc).endswith("); pass answer=... to run_procedure to answer prompts")
    assert session.status == "aborted"


def test_an_answer_that_is_not_a_bool_aborts(bench: Bench, tmp_path: Path) -> None:
    exc, session = _stopped(bench, tmp_path, lambda p: print(p))  # forgot to return
    assert str(exc) == "step setup: answer returned None, not True (go on) or False (abort)"
    assert session.status == "aborted"


# --------------------------------------------------------------------------- analysis calls


def test_measure_bars_reads_a_known_square_wave() -> None:
    rng = np.random.default_rng(1)
    roi = np.tile([30.0] * 5 + [170.0] * 5, (40, 6)) + rng.normal(0.0, 2.0, (40, 60))
    for estimator in ("histogram", "variance"):
        result = benchlab.measure_bars(roi, orientation="sagittal", estimator=estimator)
        assert isinstance(result, ModulationResult) and result.estimator == estimator
        assert result.modulation == pytest.approx(140 / 200, abs=0.01)
    assert benchlab.measure_bars(roi).estimator == "profilefit"  # None: the default
    with pytest.raises(ValueError, match=r"unknown estimator 'nope'"):
        benchlab.measure_bars(roi, estimator="nope")


def test_measure_edge_finds_the_mtf50_of_a_gaussian_edge() -> None:
    rows, cols = np.mgrid[0:80, 0:80]
    slope = 0.1
    across = (cols - 40) - slope * (rows - 40)
    roi = 20 + 180 * 0.5 * (1 + erf(across / 2.0))
    result = benchlab.measure_edge(roi)
    assert isinstance(result, SfrResult)
    # erf(x / 2) is a Gaussian LSF of sigma sqrt(2) along x, sqrt(2) / sqrt(1 + slope^2) along
    # the edge normal; its MTF exp(-2 pi^2 sigma^2 f^2) falls to 0.5 at:
    sigma = math.sqrt(2) / math.sqrt(1 + slope**2)
    mtf50 = math.sqrt(math.log(2) / (2 * math.pi**2 * sigma**2))
    assert result.mtf50_cycles_per_px == pytest.approx(mtf50, abs=0.002)
    assert result.edge_angle_deg == pytest.approx(math.degrees(math.atan(slope)), abs=0.05)
    assert result.direction == "horizontal"
    with pytest.raises(SfrRefused, match="no edge"):
        benchlab.measure_edge(np.full((40, 40), 100.0))


def test_measure_chart_refuses_a_frame_without_a_chart() -> None:
    noise = np.random.default_rng(0).normal(100.0, 5.0, (256, 256))
    with pytest.raises(ChartNotFoundError, match="no chart found"):
        benchlab.measure_chart(noise)
    with pytest.raises(ValueError, match=r"magnification must be > 0, got 0"):
        benchlab.measure_chart(noise, magnification=0)


@pytest.mark.slow
def test_a_chart_reading_is_looked_up_by_label() -> None:
    from benchlab.scenes.usaf import UsafScene

    chart = benchlab.measure_chart(UsafScene().render(1024, 1280))
    assert chart.reading(chart.labels[3]) is chart.readings[3]
    with pytest.raises(KeyError, match=r"no reading of bar set 'G9E9S'; read: G0E1S, G0E1T"):
        chart.reading("G9E9S")
    with pytest.raises(ValueError, match=r"31 readings for 32 found sets"):
        ChartReading(chart.fit, chart.readings[1:])


def test_the_docstring_examples_run() -> None:
    import benchlab.api

    outcome = doctest.testmod(benchlab.api, optionflags=doctest.ELLIPSIS)
    assert outcome.failed == 0
    assert outcome.attempted >= 20


# --------------------------------------------------------------------------- the package


def _stub_names() -> dict[str, str]:
    out = {}
    for node in ast.parse(STUB.read_text()).body:
        if isinstance(node, ast.ImportFrom):
            out.update({a.name: f"benchlab.{node.module}" for a in node.names})
    return out


def test_every_public_name_is_its_modules_object() -> None:
    names = _stub_names()
    assert sorted(names) == ["Bench", "ChartReading", "ModulationResult", "Prompt",
                             "RunOutcome", "Session", "SfrResult", "measure_bars",
                             "measure_chart", "measure_edge", "open_bench", "open_session",
                             "run_procedure"]
    assert sorted(benchlab.__all__) == sorted([*names, "__version__"]) == dir(benchlab)
    for name, module in names.items():
        assert getattr(benchlab, name) is getattr(importlib.import_module(module), name), name
    assert isinstance(benchlab.__version__, str) and benchlab.__version__
    with pytest.raises(AttributeError, match="no_such_name"):
        benchlab.no_such_name  # noqa: B018


def test_importing_benchlab_loads_nothing_heavy() -> None:
    done = subprocess.run(
        [sys.executable, "-c", "import benchlab, sys; print('\\n'.join(sys.modules))"],
        capture_output=True, text=True, check=True)
    loaded = set(done.stdout.split())
    assert "benchlab" in loaded
    assert not {m for m in loaded if m.startswith("benchlab.")}
    assert "numpy" not in loaded
