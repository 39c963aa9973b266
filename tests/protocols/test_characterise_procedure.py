"""``benchlab run characterise`` on the simulated bench: results, truth, calibration, abort and
resume, parameter errors, and radiometry linearised with the calibration."""

from __future__ import annotations

import json
import shutil
import threading
from pathlib import Path
from typing import Any

import pytest
from sim_runs import FIXTURES, RAD_SMALL, TINY, events, run_sim, yes

from benchlab.bench import Bench, BenchConfig
from benchlab.calibration import (
    CalibrationError,
    curve_for,
    load_calibration,
    set_camera_reference,
)
from benchlab.cli.main import main
from benchlab.drivers.mightex.sim_sensor import SensorTruth
from benchlab.protocols import ParamsError, RunAborted, load_params, reanalyze, resume_run
from benchlab.protocols.characterise.steps import sweep_exposures
from benchlab.protocols.engine import Step
from benchlab.protocols.params import BenchLimits, parse_params
from benchlab.session import read_results

SMALL = FIXTURES / "characterise-small.toml"


@pytest.fixture
def tiny(tmp_path: Path) -> Path:
    path = tmp_path / "tiny.toml"
    path.write_text(TINY)
    return path
KEYS = ("system_gain_dn_per_e", "read_noise_e", "read_noise_dn", "saturation_e",
        "saturation_dn", "linearity_error_pct", "dark_current_e_per_s", "dsnu_dn", "prnu_pct")


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Any:
    root = tmp_path_factory.mktemp("char")
    return run_sim("characterise", root, SMALL)


@pytest.mark.slow
def test_results_carry_every_key_and_the_simulator_truth(run: Any) -> None:
    rows = run.tables["characterisation"]
    assert [(r["gain"], r["bits"]) for r in rows] == [(1.0, 12), (1.0, 8)]
    truth = {(r["gain"], r["bits"]): r for r in run.tables["simulator_truth"]}
    for row in rows:
        assert all(k in row for k in KEYS)
        assert all(k in truth[(row["gain"], row["bits"])] for k in KEYS)
    r12, t12 = rows[0], truth[(1.0, 12)]
    assert r12["system_gain_dn_per_e"] == pytest.approx(t12["system_gain_dn_per_e"], rel=0.03)
    assert r12["read_noise_e"] == pytest.approx(8.0, rel=0.08)
    assert r12["saturation_dn"] == pytest.approx(t12["saturation_dn"], rel=0.03)
    assert r12["dark_current_e_per_s"] == pytest.approx(500.0, rel=0.1)
    assert r12["msb_aligned"] is False
    assert rows[1]["read_noise_resolved"] is False  # 8-bit dark noise < 1 DN, flagged
    curve_rows = run.tables["photon_transfer"]
    assert sum(r["saturation_step"] for r in curve_rows) == 2  # one per configuration
    results = Path(run.results_path)
    assert (results / "characterisation.csv").read_text().startswith("gain,bits,")


def test_sweep_is_log_spaced_near_dark_and_dense_at_saturation() -> None:
    params = load_params("characterise", SMALL)
    t = sweep_exposures(params, 50.0)
    assert t == sorted(set(t)) and t[0] == pytest.approx(0.1)  # probe start / 4, 0.05 ms steps
    assert t[1] / t[0] > 2 and t[3] <= 0.05 * 50.0  # log-spaced up to 5 % of t_sat
    assert max(t) == pytest.approx(57.5)  # 1.15 x t_sat
    near = [x for x in t if x >= 0.87 * 50.0]
    assert len(near) == 12 and max(b - a for a, b in zip(near, near[1:], strict=False)) < 1.5


@pytest.mark.slow
def test_calibration_written_beside_a_bench_copy_and_led_left_off(run: Any) -> None:
    session = Path(run.session_path)
    calib_dir = session.parent / "calibration"
    bench_file = calib_dir / "bench-v1.toml"
    cfg = BenchConfig.load(bench_file, simulate=True)
    assert cfg.camera.response_calibration == str(calib_dir / "response-v1.json")
    doc = load_calibration(bench_file)
    assert {(c["gain"], c["bits"]) for c in doc["curves"]} == {(1.0, 12), (1.0, 8)}
    assert curve_for(doc, 1.0, 8).bits == 8
    with pytest.raises(CalibrationError, match="no curve for gain 2"):
        curve_for(doc, 2.0, 8)
    kinds = [e["kind"] for e in events(session)]
    assert "response_calibration_written" in kinds and "simulator_truth" in kinds


def test_reanalysis_reproduces_the_results(run: Any) -> None:
    out = reanalyze(run.session_path)
    tables, _ = read_results(out)
    assert out.name == "v1"  # the run's own results byte for byte: matched, none added
    assert tables["characterisation"] == run.tables["characterisation"]


@pytest.mark.slow
def test_user_bench_file_is_pointed_at_each_new_version(tmp_path: Path, tiny: Path) -> None:
    bench = tmp_path / "bench.toml"
    shutil.copy(Path(BenchConfig.load(None, simulate=True).source), bench)
    for version in (1, 2):
        with Bench.open(BenchConfig.load(bench, simulate=True), simulate=True) as b:
            from benchlab.protocols import start_run

            start_run("characterise", bench=b, params=tiny, root=tmp_path / "s",
                      prompt=yes).run()
        text = bench.read_text()
        assert text.count("response_calibration") == 1
        assert f'response_calibration = "calibration/response-v{version}.json"' in text
    assert (tmp_path / "calibration" / "response-v1.json").is_file()  # never overwritten


def test_set_camera_reference_adds_or_replaces_only_that_line() -> None:
    assert set_camera_reference('[led]\nchannel = 1\n', "c.json") == (
        '[led]\nchannel = 1\n\n[camera]\nresponse_calibration = "c.json"\n')
    text = '[camera]\nserial = "X"\nresponse_calibration = "old.json"\n[led]\nchannel = 2\n'
    out = set_camera_reference(text, "new.json")
    assert out == text.replace("old.json", "new.json")


def test_abort_mid_sweep_leaves_led_off_and_resume_finishes(tmp_path: Path, tiny: Path) -> None:
    abort = threading.Event()

    def on_result(step: Step, data: Any) -> None:
        if "saturation_exposure_ms" in data:
            abort.set()  # probe done: the next lit frame is refused

    config = BenchConfig.load(None, simulate=True)
    with Bench.open(config, simulate=True) as bench:
        from benchlab.protocols import start_run

        runner = start_run("characterise", bench=bench, params=tiny, root=tmp_path / "s",
                           prompt=yes, abort=abort, on_result=on_result)
        with pytest.raises(RunAborted):
            runner.run()
        assert all(bench.sim_led.channel_output_ma(ch) == 0.0 for ch in range(1, 5))
        session = runner.session.path
        probes = len(runner.session.step_frames("sweep-g1-b12"))
    assert probes > 2
    with Bench.open(config, simulate=True) as bench:
        outcome = resume_run(session, bench=bench, prompt=yes).run()
        assert all(bench.sim_led.channel_output_ma(ch) == 0.0 for ch in range(1, 5))
        assert bench.sim_camera.sensor.truth == SensorTruth()  # the bench's own sensor again
    reused = [e for e in events(Path(session)) if e["kind"] == "frame_reused"]
    assert len(reused) == probes  # the probe frames were read back, not taken again
    assert outcome.tables["characterisation"][0]["saturation_dn"] > 0


def test_parameter_problems_are_all_listed() -> None:
    bad = {"procedure": "characterise", "camera": {"bits": [14], "width": 66, "gains": [9.0]},
           "led": {"current_ma": 80.0}, "sweep": {"log_steps": 1}, "simulator": {"gain": 2},
           "typo": 1}
    with pytest.raises(ParamsError) as err:
        parse_params("characterise", bad, "x.toml", BenchLimits(led_ceilings_ma={1: 50.0}))
    text = str(err.value)
    for field in ("camera.bits", "camera.width", "camera.gains[0]", "led.current_ma",
                  "sweep.log_steps", "simulator", "typo"):
        assert field in text


def test_cli_run_prints_the_session(tmp_path: Path, tiny: Path,
                                   capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["run", "characterise", "--simulate", "--yes", "--params", str(tiny),
                 "--out", str(tmp_path / "s")])
    assert code == 0
    assert "results:" in capsys.readouterr().out


@pytest.mark.slow
def test_radiometry_records_and_applies_the_calibration(run: Any, tmp_path: Path) -> None:
    bench_file = Path(run.session_path).parent / "calibration" / "bench-v1.toml"
    plain = run_sim("radiometry", tmp_path / "a", RAD_SMALL)
    with Bench.open(BenchConfig.load(bench_file, simulate=True), simulate=True) as bench:
        from benchlab.protocols import start_run

        cal = start_run("radiometry", bench=bench, params=RAD_SMALL, root=tmp_path / "b",
                        prompt=yes).run()
    assert plain.summary["summary"]["linearised"] is None
    record = cal.summary["summary"]["linearised"]
    assert record["file"].endswith("response-v1.json") and record["bits"] == 8
    # A linear camera's calibration barely moves the readings (< 1 %), but it is applied.
    for a, b in zip(plain.tables["table_4_16"], cal.tables["table_4_16"], strict=True):
        assert b["measured_mean_gray"] == pytest.approx(a["measured_mean_gray"], rel=0.01)
    assert json.loads((Path(cal.session_path) / "session.json").read_text())["params"]["bench"][
        "camera"]["response_calibration"] == record["file"]


def test_analyze_linearise_records_the_calibration(run: Any,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    session = Path(run.session_path)
    frame = session / "frames" / "sweep-g1-b8__e010-lit-a.tiff"
    bench_file = session.parent / "calibration" / "bench-v1.toml"
    argv = ["analyze", str(frame), "--roi", "0,0,32,32", "--peaks", "10,100", "--json"]
    assert main([*argv, "--linearise", str(bench_file)]) == 0
    payload = json.loads(capsys.readouterr().out)
    assert payload["linearised"]["file"].endswith("response-v1.json")
    assert (payload["linearised"]["gain"], payload["linearised"]["bits"]) == (1.0, 8)
    assert main(argv) == 0
    assert json.loads(capsys.readouterr().out)["linearised"] is None
    assert main([*argv, "--linearise", str(session / "nope.json")]) == 1
    err = capsys.readouterr().err
    assert err.startswith("benchlab: error:") and "nope.json" in err
    assert main(["analyze", str(session), "--linearise", str(bench_file)]) == 2  # usage
    assert "--linearise: for one image only" in capsys.readouterr().err


def test_led_current_sweep_option(tmp_path: Path) -> None:
    params = tmp_path / "current.toml"
    # 25 ms: saturation near 45 mA, so the SLC-SA's 1 mA steps give 12 distinct currents
    params.write_text(TINY.replace("[sweep]", '[led]\ncurrent_ma = 50.0\n[sweep]\n'
                                   'vary = "led_current"\nexposure_ms = 25.0')
                      + "[simulator]\ndark_offset_dn12 = 64.0\n")
    out = run_sim("characterise", tmp_path / "s", params)
    row = out.tables["characterisation"][0]
    assert row["dark_current_e_per_s"] is None and "no dark current" in row["warnings"]
    assert row["system_gain_dn_per_e"] == pytest.approx(0.20475, rel=0.03)
    curve = out.tables["photon_transfer"]
    assert {r["exposure_ms"] for r in curve} == {25.0}  # one exposure, the current swept
    signals = [r["signal_dn"] for r in curve]
    assert 0 < min(signals) < 0.05 * max(signals)  # dim (1 mA) and bright points both


@pytest.mark.slow
def test_report_renders_the_characterisation(run: Any) -> None:
    from benchlab.report.render import render_report

    page = render_report(run.session_path)
    assert "Camera characterisation (EMVA 1288)" in page
    assert "Simulator truth (same keys)" in page
    for alt in ("photon transfer curve", "linearity deviation", "dark signal and dark noise"):
        assert f"alt='{alt}'" in page
    assert "quantisation" in page  # the 8-bit warning is shown
    # The 8-bit dark figures are not resolved: no number, the reason (noise DN, e-, dark, DSNU).
    assert page.count("n/a (unresolved: dark noise &lt; 1 DN)") == 4


def test_unresolved_8_bit_dark_figures_are_na_in_json_and_csv(run: Any) -> None:
    r8 = run.tables["characterisation"][1]
    assert (r8["bits"], r8["read_noise_e"], r8["dark_current_e_per_s"], r8["dsnu_dn"]) == (
        8, None, None, None)
    assert (r8["dark_current_resolved"], r8["dsnu_resolved"]) == (False, False)
    assert r8["dark_current_unresolved"] == "dark noise < 1 DN"
    assert r8["prnu_pct"] == pytest.approx(1.0, rel=0.15)  # resolved, given
    import csv
    with (Path(run.results_path) / "characterisation.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert (rows[1]["read_noise_e"], rows[1]["dark_current_e_per_s"]) == ("NA", "NA")
    assert rows[1]["dark_current_unresolved"] == "dark noise < 1 DN"
    assert float(rows[0]["dark_current_e_per_s"]) == pytest.approx(500.0, rel=0.1)


def test_sweep_capped_below_saturation_says_so(tmp_path: Path) -> None:
    params = tmp_path / "short.toml"
    params.write_text(TINY.replace("[sweep]", "[sweep]\nmax_exposure_ms = 20.0"))
    out = run_sim("characterise", tmp_path / "s", params)
    row = out.tables["characterisation"][0]
    assert row["saturation_dn"] is None and row["saturation_e"] is None
    assert row["saturation_reached"] is False
    assert "never reached saturation" in row["warnings"]
    assert row["system_gain_dn_per_e"] == pytest.approx(0.20475, rel=0.05)
