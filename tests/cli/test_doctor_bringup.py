"""`benchlab doctor` on a first-day bench (issue 36): each simulated fault is named in one
line of the report with what to put in the bench file, every independent later check still
runs, the report is always written, and the recorded cassette replays the run byte for byte.
"""

from __future__ import annotations

import base64
import gzip
import json
import re
from pathlib import Path

import pytest

from benchlab.cli.main import main

#: fault -> (exit status, text of its one report line, checks that must not have been run)
FAULTS: dict[str, tuple[int, str, tuple[str, ...]]] = {
    "camera-pid": (1, "set [camera] pid = 0x0528 (in your bench file; `benchlab doctor --config "
                      "FILE` writes it) and add the udev "
                      'rule line SUBSYSTEM=="usb", ATTR{idVendor}=="04b4", '
                      'ATTR{idProduct}=="0528"', ()),
    "camera-trailer-swapped": (1, "trailer gives the line count first (1024, 1280): not the "
                                  "row_column order assumed -> set [camera] trailer_order = "
                                  '"column_row"', ()),
    "camera-timestamp-100us": (1, "the trailer counts 0.1 ms, not 1 ms (the exposure unit is "
                                  "not in question) -> set [camera] timestamp_unit_ms = 0.1",
                               ()),
    "camera-roi-refused": (1, "camera keeps sending 1280x1024 frames (bin 0x00) after 256x256 "
                              "was set", ()),
    "camera-grab-timeout": (1, "no frame came on EP 0x82", ("5 bit depths decode",)),
    "camera-exposure-4byte-ignored-length": (1, 'set [camera] model = "MCE-B013-U/v1.0.6"',
                                             ()),
    "stage-home-timeout": (1, "the controller never reported homed within 2.04 s, the time "
                              "homing from anywhere in 50 mm takes at its home velocity of 2 "
                              "mm/s (read from it)", ("8 stage scale",)),
    "stage-travel-offset": (0, "by a relative move of 20 mm from home (travel 2..27 mm): Z8 "
                               "(34555, 0.00 % off), as the bench file says", ()),
    "stage-parks-off": (0, "the move settled +12 counts off its target (within the bench "
                           "file's tolerance of 30 counts)", ()),
}
#: Every check of a run; the camera's "3 frame trailer order" comes with its first frame.
ALL_STEPS = ("1 libusb backend", "2 udev rule and group", "3 camera enumerates and answers",
             "4 exposure unit and linearity", "5 bit depths decode", "6 LED controller identity",
             "7 LED on at its lowest current, off", "8 stage identity", "8 stage homing",
             "8 stage scale")


def _rows(report: str) -> list[tuple[str, str]]:
    """(step, result) of each row of the report's check table."""
    return [(m[1], m[2]) for m in re.finditer(r"^\| (\d[^|]*?) \| (ok|FAIL|warn|skip) \|",
                                              report, re.M)]


def _traffic(cassette: Path) -> dict[tuple[str, str], bytes]:
    """Every byte each device sent and got, in order (keep-alives and timeouts left out)."""
    parts: dict[tuple[str, str], list[bytes]] = {}
    with gzip.open(cassette, "rt") if cassette.suffix == ".gz" else open(cassette) as fh:
        for line in list(fh)[1:]:
            item = json.loads(line)
            if "dir" not in item or item.get("timeout"):
                continue
            data = (bytes.fromhex(item["hex"]) if "hex" in item
                    else base64.b64decode(item["b64"]))
            parts.setdefault((item["dev"], item["dir"]), []).append(data)
    keepalive = bytes.fromhex("92 04 00 00 50 01")  # APT keep-alives: on a timer, left out
    return {key: b"".join(chunks).replace(keepalive, b"") for key, chunks in parts.items()}


@pytest.mark.slow
@pytest.mark.parametrize("fault", sorted(FAULTS))
def test_each_first_day_fault_is_named_and_the_run_replays(
    fault: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    status, named, not_run = FAULTS[fault]
    report = tmp_path / "bringup-report.md"
    rc = main(["doctor", "--simulate", "--yes", "--inject", fault, "--report", str(report)])
    out = capsys.readouterr().out
    assert rc == status, out
    text = report.read_text(encoding="utf-8")
    assert f"Injected faults: {fault}" in text
    one_line = [ln for ln in text.splitlines() if named in ln]
    assert one_line, f"{named!r} not in the report:\n{text}"
    rows = dict(_rows(text))
    for step in ALL_STEPS:  # every check is listed: run, or skipped as a dependent one
        assert step in rows, (step, text)
        if not step.startswith(("1 ", "2 ")):  # (libusb and udev: not needed simulated)
            assert (rows[step] == "skip") == (step in not_run), (step, rows[step], text)
    assert "3 frame trailer order" in rows or fault == "camera-grab-timeout"
    cassette = tmp_path / "bringup-report.cassette.jsonl.gz"
    assert f"recording `{cassette}`" in text

    # The recording replays: the same checks, the same results, the same bytes on the wires.
    again = tmp_path / "replayed.md"
    traced = tmp_path / "replayed.jsonl"
    rc2 = main(["--trace-io", str(traced), "doctor", "--replay", str(cassette), "--yes",
                "--report", str(again)])
    capsys.readouterr()
    assert rc2 == status
    assert _rows(again.read_text(encoding="utf-8")) == _rows(text)
    assert _traffic(traced) == _traffic(cassette)


def test_the_report_goes_next_to_the_bench_file_never_the_current_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    bench = tmp_path / "bench" / "bench.toml"
    bench.parent.mkdir()
    bench.write_text('[camera]\nserial = ""\n\n[led]\nchannel = 1\n\n[stage]\n'
                     "travel_mm = [0.0, 25.0]\n", encoding="utf-8")
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    monkeypatch.chdir(cwd)
    assert main(["doctor", "--simulate", "--yes", "--config", str(bench)]) == 0
    assert (bench.parent / "bringup-report.md").is_file()
    assert (bench.parent / "bringup-report.cassette.jsonl.gz").is_file()
    assert list(cwd.iterdir()) == []
    # Without a bench file (the packaged simulated one): the user's config folder.
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    assert main(["doctor", "--simulate", "--yes"]) == 0
    assert (tmp_path / "config/benchlab/bringup-simulated/bringup-report.md").is_file()
    assert list(cwd.iterdir()) == []
    capsys.readouterr()


def test_a_replay_that_diverges_says_where_and_still_writes_the_report(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    report = tmp_path / "r.md"
    assert main(["doctor", "--simulate", "--yes", "--report", str(report)]) == 0
    cassette = tmp_path / "r.cassette.jsonl.gz"
    lines = gzip.open(cassette, "rt").read().splitlines()
    # The camera's replies cut out of the recording: its check fails with the exchange where
    # the replay diverged, and the checks of the other devices still run.
    cut = [ln for ln in lines if '"dev": "camera"' not in ln or '"dir": ">"' in ln
           or "open" in ln]
    with gzip.open(cassette, "wt") as fh:
        fh.write("\n".join(cut) + "\n")
    capsys.readouterr()
    again = tmp_path / "again.md"
    rc = main(["doctor", "--replay", str(cassette), "--yes", "--report", str(again)])
    out = capsys.readouterr().out
    assert rc == 1
    assert re.search(r"\[FAIL\] 3 camera enumerates and answers: .*replay diverged at "
                     r"exchange \d+: read EP 0x81", out)
    assert again.is_file() and "| 8 stage scale | ok |" in again.read_text(encoding="utf-8")


@pytest.mark.slow
def test_the_facts_settled_go_into_the_bench_file_and_the_next_run_passes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bench = tmp_path / "bench.toml"
    bench.write_text('[camera]\nserial = ""\n\n[led]\nchannel = 1\n\n[stage]\n'
                     "travel_mm = [0.0, 25.0]\n", encoding="utf-8")
    faults = ("camera-pid", "camera-trailer-swapped", "camera-timestamp-100us",
              "camera-no-12bit")
    run = ["doctor", "--simulate", "--yes", "--config", str(bench)]
    for fault in faults:
        run += ["--inject", fault]
    assert main(run) == 1
    text = bench.read_text(encoding="utf-8")
    for line in ("pid = 0x0528", 'trailer_order = "column_row"', "timestamp_unit_ms = 0.1",
                 "bit_depths = [8, 10]"):
        assert line in text
    report = (tmp_path / "bringup-report.md").read_text(encoding="utf-8")
    assert report.count("| FAIL |") == 4
    assert "set [camera] pid = 0x0528 (written to the bench file)" in report
    assert "in your bench file;" not in report  # only said when nothing is written
    capsys.readouterr()
    assert main(run) == 0, capsys.readouterr().out  # the same camera, now as the file says


def test_a_bad_bench_file_is_named_in_the_report_too(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bench = tmp_path / "bench.toml"
    bench.write_text("[stage]\ntolerance_counts = 0\n", encoding="utf-8")
    assert main(["doctor", "--simulate", "--yes", "--config", str(bench)]) == 1
    assert "stage.tolerance_counts" in capsys.readouterr().err
    report = (tmp_path / "bringup-report.md").read_text(encoding="utf-8")
    assert "| 0 bench file | FAIL |" in report and "stage.tolerance_counts" in report


def test_no_camera_on_the_bus_is_one_fail_and_the_run_goes_on() -> None:
    from benchlab.bench import BenchConfig
    from benchlab.cli.devices.doctor import Doctor

    doctor = Doctor(BenchConfig(), False, lambda q: True, lambda q: None, say=lambda s: None)
    doctor.run()  # this machine: no camera (and maybe no libusb); no LED, no stage configured
    camera = [c for c in doctor.checks if c.step == "3 camera enumerates and answers"]
    assert [c.status for c in camera] == ["FAIL"]
    assert "no USB device of vendor 0x04B4 or naming Mightex is on the bus" in camera[0].detail
    steps = [(c.step, c.status) for c in doctor.checks]
    assert ("4 exposure unit and linearity", "skip") in steps
    assert ("6 LED controller identity", "skip") in steps and ("8 stage identity", "skip") in steps
