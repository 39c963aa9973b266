"""Radiometry frames that cannot give a clean number: clipped readings are flagged (never a
number in Table 4.16), frames with no LED in them are set aside and taken again on a retry,
and a re-analysis skips (and names) a position whose frames hold no reading."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from sim_runs import RAD_SMALL, events, run_sim, yes

from benchlab.analysis.radiometry import clipped_in_mask, reading_mask
from benchlab.bench import Bench, BenchConfig
from benchlab.cli.main import main
from benchlab.protocols import StepFailed, reanalyze, start_run
from benchlab.protocols.radiometry import FrameContentError, reading_mask_of
from benchlab.report.render import write_report
from benchlab.scenes.led import LedScene
from benchlab.session import Session, SessionError


def _params(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.slow
def test_clipped_rows_have_no_number_and_say_why(tmp_path: Path) -> None:
    """At 50 mA (allowed) the brightest positions clip at 255: flagged, not normalised;
    the clean rows are normalised among themselves and match the scene's fall-off."""
    params = _params(tmp_path, "i50.toml", RAD_SMALL.read_text().replace(
        "current_ma = 20.0", "current_ma = 50.0"))
    live: list[dict[str, Any]] = []
    out = run_sim("radiometry", tmp_path / "s", params,
                  on_result=lambda step, data: live.append(dict(data)))
    rows = {r["position_mm"]: r for r in out.tables["table_4_16"]}
    clipped = rows[18.0]
    assert [str(d["measured_mean_gray"])[:7] for d in live][1] == "clipped"  # the live view
    assert isinstance(live[0]["measured_mean_gray"], float)
    assert clipped["clipped_pixels"] > 100
    assert clipped["measured_mean_gray"] is None and clipped["measured_normalised"] is None
    assert clipped["difference"] is None
    assert "clipped" in clipped["note"] and "255" in clipped["note"]
    assert rows[15.0]["clipped_pixels"] == rows[25.0]["clipped_pixels"] == 0
    summary = out.summary["summary"]
    assert summary["clipped_positions_mm"] == [18.0]
    assert summary["normalised_over_mm"] == [15.0, 25.0]
    assert any(w.startswith("position-18: clipped") for w in summary["warnings"])
    falloff = LedScene().falloff
    assert rows[25.0]["measured_normalised"] == pytest.approx(
        falloff.at(25.0) / falloff.at(15.0), abs=0.01)
    assert rows[15.0]["measured_normalised"] == 1.0
    page = write_report(out.session_path, tmp_path / "r.html").read_text()
    assert "position-18: clipped" in page and "clipped px" in page


def test_clipping_counted_at_the_frames_bit_depth() -> None:
    frame = np.zeros((20, 20), np.uint16)
    frame[5:15, 5:15] = 4000
    frame[9, 9] = 4095
    mask = np.zeros_like(frame, dtype=bool)
    mask[5:15, 5:15] = True
    assert clipped_in_mask(frame, mask, 4095) == 1
    assert clipped_in_mask(frame, mask, 255) == 100
    with pytest.raises(ValueError, match="differ in shape"):
        clipped_in_mask(frame, mask[:10], 4095)


def test_reading_mask_ignores_a_clipped_locator_frame() -> None:
    """The mask is the same fraction of each spot's own level whether or not the gain-5
    frame clipped: a dim and a bright spot of one shape give the same mask."""
    yy, xx = np.mgrid[0:80, 0:80]
    shape = 1.0 / (1.0 + np.exp((np.hypot(yy - 40, xx - 40) - 15.0) / 1.5))
    masks = []
    for level in (60.0, 110.0):
        meas = level * shape
        locator = np.minimum(5 * meas, 255.0)  # clipped at gain 5
        masks.append(reading_mask(locator, meas, 0.5))
    assert np.array_equal(masks[0], masks[1])
    with pytest.raises(ValueError, match=r"in \(0, 1\)"):
        reading_mask(locator, meas, 1.0)
    with pytest.raises(ValueError, match="no brighter"):
        reading_mask(locator, np.zeros_like(meas), 0.5)


@pytest.mark.slow
def test_dark_frames_are_rejected_and_taken_again_on_retry(tmp_path: Path) -> None:
    """The LED failed to light at 18 mm (frames with no LED): the step fails, its frames are
    journalled as rejected and kept; the retry takes new ones and the results use those."""
    with Bench.open(BenchConfig.load(None, simulate=True), simulate=True) as bench:
        real_on = bench.led_on
        dark = {"position-18"}

        def progress(done: int, total: int, step: Any) -> None:
            bench.led_on = ((lambda ch, ma: None) if step is not None and step.id in dark
                            else real_on)  # type: ignore[method-assign]

        runner = start_run("radiometry", bench=bench, params=RAD_SMALL, root=tmp_path,
                           prompt=yes, progress=progress)
        with pytest.raises(StepFailed) as info:
            runner.run()
        assert isinstance(info.value.cause, FrameContentError)
        path = runner.session.path
        first = sorted(p.name for p in (path / "frames").glob("position-18__*"))
        assert first == ["position-18__mask.tiff", "position-18__measurement.tiff"]
        dark.clear()
        out = runner.run()
    rejected = [e for e in events(path) if e["kind"] == "frames_rejected"]
    assert [e["files"] for e in rejected] == [["frames/position-18__mask.tiff",
                                               "frames/position-18__measurement.tiff"]]
    assert "no LED" in rejected[0]["reason"]
    assert sorted(p.name for p in (path / "frames").glob("position-18__*")) == [
        "position-18__mask.take2.tiff", "position-18__mask.tiff",
        "position-18__measurement.take2.tiff", "position-18__measurement.tiff"]
    session = Session.open(path)
    assert session.step_frames("position-18")["mask"].name == "position-18__mask.take2.tiff"
    assert session.verify_frames() == []  # the rejected frames are still hash-checked
    row = {r["position_mm"]: r for r in out.tables["table_4_16"]}[18.0]
    mask, _ = session.load_frame("position-18", "mask")
    meas, _ = session.load_frame("position-18", "measurement")
    truth = LedScene().expected_mean_dn8(reading_mask_of(mask, meas, 0.5), 18.0, 20.0, 375.0)
    assert row["measured_mean_gray"] == pytest.approx(truth, abs=1.0)
    v2 = reanalyze(path)  # a re-analysis reads the same (new) frames
    assert json.loads((v2 / "relative_radiometry.json").read_text()) == out.tables["table_4_16"]


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "benchlab.cli.main", *args], text=True,
                          capture_output=True, timeout=120)


@pytest.mark.slow
def test_resume_retakes_frames_with_no_led_in_a_real_process(tmp_path: Path) -> None:
    """The LED at 45 mm is out of view: each run of the step takes new frames (rejecting the
    last), never reuses the bad ones; the old ones stay on disk; analyze names what it
    skipped and exits 0."""
    params = _params(tmp_path, "p45.toml", RAD_SMALL.read_text().replace(
        "field_mm = [15, 18, 25]", "field_mm = [15, 45]").replace(
        "[22.48, 21.21, 14.34]", "[22.48, 3.0]"))
    first = _cli("run", "radiometry", "--simulate", "--yes", "--params", str(params),
                 "--out", str(tmp_path / "s"))
    assert first.returncode == 1, first.stderr
    assert "position-45" in first.stderr and "retry takes new ones" in first.stderr
    (path,) = (tmp_path / "s").glob("*_radiometry")
    again = _cli("resume", str(path), "--simulate", "--yes")
    assert again.returncode == 1, again.stderr
    assert "Traceback" not in again.stderr
    evs = events(path)
    assert [e["kind"] for e in evs].count("frames_rejected") == 2
    assert not [e for e in evs if e["kind"] == "frame_reused" and e["step"] == "position-45"]
    names = sorted(p.name for p in (path / "frames").glob("position-45__*"))
    assert names == ["position-45__mask.take2.tiff", "position-45__mask.tiff",
                     "position-45__measurement.take2.tiff", "position-45__measurement.tiff"]
    with pytest.raises(SessionError, match="rejected .*no LED"):
        Session.open(path).load_frame("position-45", "mask")
    done = _cli("analyze", str(path))
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr and "partial" in done.stdout


def test_analyze_skips_a_position_with_no_reading(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """A session written before frames could be rejected holds the bad frames as its
    position's frames: analyze skips that row, names step and frame files, keeps the rest."""
    params = _params(tmp_path, "p45.toml", RAD_SMALL.read_text().replace(
        "field_mm = [15, 18, 25]", "field_mm = [15, 45, 18]").replace(
        "[22.48, 21.21, 14.34]", "[22.48, 3.0, 21.21]"))
    with Bench.open(BenchConfig.load(None, simulate=True), simulate=True) as bench:
        runner = start_run("radiometry", bench=bench, params=params, root=tmp_path / "s",
                           prompt=yes)
        with pytest.raises(StepFailed):
            runner.run()
    path = runner.session.path
    journal = path / "events.jsonl"
    journal.write_text("".join(line + "\n" for line in journal.read_text().splitlines()
                               if '"frames_rejected"' not in line))
    capsys.readouterr()
    assert main(["analyze", str(path)]) == 0
    out = capsys.readouterr().out
    assert "position-45: skipped (frames/position-45__mask.tiff, " \
           "frames/position-45__measurement.tiff)" in out
    summary = json.loads((path / "results" / "v1" / "summary.json").read_text())
    (skipped,) = summary["summary"]["skipped"]
    assert skipped["step"] == "position-45" and "no LED found" in skipped["reason"]
    rows = json.loads((path / "results" / "v1" / "relative_radiometry.json").read_text())
    assert [r["position_mm"] for r in rows] == [15.0]
