"""`benchlab doctor`: passes on the simulated bench, names each injected fault and a
mismatched camera profile, and writes what it learned into the bench file after a backup."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchlab.bench import BenchConfig
from benchlab.cli.devices.doctor import set_toml_key
from benchlab.cli.main import main

BENCH = """[camera]
serial = ""

[led]
channel = 1
[led.ceiling_ma]
1 = 50.0

[stage]
travel_mm = [0.0, 50.0]
"""


def _doctor(tmp_path: Path, *extra: str) -> tuple[int, str, str]:
    report = tmp_path / "report.md"
    rc = main(["doctor", "--simulate", "--yes", "--report", str(report), "--force", *extra])
    return rc, report.read_text(encoding="utf-8"), str(report)


def test_the_simulated_bench_passes_every_check(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rc, report, _ = _doctor(tmp_path)
    out = capsys.readouterr().out
    assert rc == 0, out
    assert "bring-up passed" in out and "FAIL" not in report
    assert "plugged in by USB" not in out  # said only when the serial side fails
    for step in ("1 libusb", "3 camera enumerates", "4 exposure unit", "5 bit depths",
                 "6 LED controller", "7 LED on", "8 stage identity", "8 stage homing",
                 "8 stage scale"):
        assert f"| {step}" in report
    assert "frame period 100 ms at a set 100 ms" in out


@pytest.mark.parametrize(("fault", "named"), [
    ("camera-profile", 'set [camera] model = "MCE-B013-U/v1.0.6"'),
    ("camera-unit", "the camera's exposure unit is 2 x the profile's"),
    ("camera-no-12bit", "12-bit: bits 2 and 3 are never set"),
    ("stage-34304", 'this is Z8-34304 (34304), the bench file assumes 34555'),
    ("led-usb-hid", "plugged in by USB (HID, which benchlab cannot drive): SLC-MA04-U serial "
                    "04-251013-021 (usb 1-2, ffff:0001)"),
])
@pytest.mark.slow
def test_each_injected_fault_is_named(
    fault: str, named: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rc, report, _ = _doctor(tmp_path, "--inject", fault)
    out = capsys.readouterr().out
    assert rc == 1 and named in out and "Injected faults: " + fault in report


def test_lf_cr_replies_pass(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert _doctor(tmp_path, "--inject", "led-lf-cr")[0] == 0


@pytest.mark.slow
def test_learned_facts_go_into_the_bench_file_after_a_backup(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bench = tmp_path / "bench.toml"
    bench.write_text(BENCH, encoding="utf-8")
    rc, _, _ = _doctor(tmp_path, "--config", str(bench), "--inject", "stage-34304",
                       "--inject", "camera-profile")
    assert rc == 1
    [backup] = tmp_path.glob("bench.toml.bak-*")
    assert backup.read_text(encoding="utf-8") == BENCH
    cfg = BenchConfig.load(bench)
    assert cfg.camera.model == "MCE-B013-U/v1.0.6"
    assert cfg.stage is not None and cfg.stage.counts_per_mm == 34304.0
    assert cfg.stage.actuator == "Z8-34304"
    capsys.readouterr()
    # The bench file now fits the (still faulty) simulated stage's scale.
    assert "as the bench file says" in (_doctor(tmp_path, "--config", str(bench), "--inject",
                                                "stage-34304") and capsys.readouterr().out)


def test_set_toml_key_replaces_or_adds() -> None:
    text = set_toml_key(BENCH, "camera", "serial", "X1")
    assert 'serial = "X1"' in text and text.count("serial") == 1
    assert 'model = "M"' in set_toml_key(BENCH, "camera", "model", "M")
    assert set_toml_key("", "stage", "actuator", "Z8").strip() == '[stage]\nactuator = "Z8"'


def test_inject_needs_simulate(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["doctor", "--inject", "camera-unit", "--report", str(tmp_path / "r")]) == 1
    assert "--inject is for the simulated bench" in capsys.readouterr().err
