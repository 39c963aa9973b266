"""``led`` and ``stage`` obey the bench file's safety limits like every other command that
drives a device (issue 38): its ceiling / travel apply, an option may narrow them, never widen.

Each case talks to a simulator on a real pseudo-terminal through the real driver, and checks
what reached the device.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from benchlab.cli.main import main
from benchlab.drivers.apt.sim import SimulatedAptStage
from benchlab.drivers.slc.sim import SimulatedSlc

pytestmark = pytest.mark.timeout(60)


@pytest.fixture
def slc() -> Iterator[SimulatedSlc]:
    sim = SimulatedSlc()
    sim.start()
    yield sim
    sim.stop()


@pytest.fixture
def apt() -> Iterator[SimulatedAptStage]:
    with SimulatedAptStage(travel_mm=(0.0, 50.0), homed=True, time_scale=200.0) as sim:
        yield sim


def _led_bench(tmp_path: Path, port: str, ceilings: str = "1 = 50.0") -> Path:
    path = tmp_path / "bench.toml"
    path.write_text(f'[led]\nport = "{port}"\nchannel = 1\n[led.ceiling_ma]\n{ceilings}\n',
                    encoding="utf-8")
    return path


def _lit(slc: SimulatedSlc) -> list[bytes]:
    """Commands that set a current or switch a channel on."""
    return [ln for ln in slc.host_lines() if ln.startswith((b"NORMAL", b"MODE 1 1"))]


def test_led_takes_the_ceiling_from_the_bench_file(
        tmp_path: Path, slc: SimulatedSlc, capsys: pytest.CaptureFixture[str]) -> None:
    bench = _led_bench(tmp_path, slc.port)  # the port comes from the bench file too
    assert main(["led", "--config", str(bench), "--on", "--current-ma", "80",
                 "--for-s", "0"]) == 1
    assert "80.0 mA exceeds the ceiling 50.0 mA; nothing sent" in capsys.readouterr().err
    assert _lit(slc) == [] and slc.channel_output_ma(1) == 0.0
    assert main(["led", "--config", str(bench), "--on", "--current-ma", "40",
                 "--for-s", "0"]) == 0
    assert "led channel 1 on at 40 mA (ceiling 50 mA)" in capsys.readouterr().out


def test_a_higher_ceiling_option_than_the_bench_file_is_refused(
        tmp_path: Path, slc: SimulatedSlc, capsys: pytest.CaptureFixture[str]) -> None:
    bench = _led_bench(tmp_path, slc.port)
    assert main(["led", "--config", str(bench), "--ceiling-ma", "100", "--on",
                 "--current-ma", "80", "--for-s", "0"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("benchlab: error: --ceiling-ma 100 mA is "
                                                   "above the bench file's ceiling 50 mA")
    assert str(bench) in err
    assert slc.host_lines() == []  # refused before the controller was opened


def test_a_lower_ceiling_option_narrows_the_bench_file(
        tmp_path: Path, slc: SimulatedSlc, capsys: pytest.CaptureFixture[str]) -> None:
    bench = _led_bench(tmp_path, slc.port)
    assert main(["led", "--config", str(bench), "--ceiling-ma", "30", "--on",
                 "--current-ma", "40", "--for-s", "0"]) == 1
    assert "exceeds the ceiling 30.0 mA; nothing sent" in capsys.readouterr().err
    assert _lit(slc) == []


def test_a_channel_without_a_ceiling_is_never_lit(
        tmp_path: Path, slc: SimulatedSlc, capsys: pytest.CaptureFixture[str]) -> None:
    bench = _led_bench(tmp_path, slc.port)
    assert main(["led", "--config", str(bench), "--channel", "2", "--ceiling-ma", "10",
                 "--on", "--current-ma", "5", "--for-s", "0"]) == 2
    assert "LED channel 2 has no ceiling" in capsys.readouterr().err
    assert slc.host_lines() == []
    assert main(["led", "--config", str(bench), "--channel", "2", "--off"]) == 0  # off is safe


def test_no_bench_file_and_no_ceiling_option_is_refused(
        slc: SimulatedSlc, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["led", "--port", slc.port, "--on", "--current-ma", "5", "--for-s", "0"]) == 2
    assert "led --on needs a current ceiling" in capsys.readouterr().err
    assert slc.host_lines() == []


def test_the_user_bench_file_applies_without_config(
        tmp_path: Path, slc: SimulatedSlc, capsys: pytest.CaptureFixture[str]) -> None:
    from benchlab.cli.config import user_bench_file

    user = user_bench_file()
    user.parent.mkdir(parents=True, exist_ok=True)
    user.write_text(_led_bench(tmp_path, slc.port).read_text(encoding="utf-8"), encoding="utf-8")
    assert main(["led", "--ceiling-ma", "100", "--on", "--current-ma", "80"]) == 2
    assert f"ceiling 50 mA for LED channel 1 ({user})" in capsys.readouterr().err


def test_simulated_led_uses_the_simulated_bench_ceiling(
        capsys: pytest.CaptureFixture[str]) -> None:
    """The issue's case: ``led --simulate --current-ma 80`` was lit under a 100 mA default."""
    assert main(["led", "--simulate", "--on", "--current-ma", "80", "--for-s", "0"]) == 1
    assert "exceeds the ceiling 50.0 mA; nothing sent" in capsys.readouterr().err


def _stage_bench(tmp_path: Path, port: str) -> Path:
    path = tmp_path / "bench.toml"
    path.write_text(f'[stage]\nport = "{port}"\ntravel_mm = [0.0, 20.0]\nvelocity_mm_s = 1.5\n',
                    encoding="utf-8")
    return path


def test_stage_keeps_to_the_bench_file_travel(
        tmp_path: Path, apt: SimulatedAptStage, capsys: pytest.CaptureFixture[str]) -> None:
    bench = _stage_bench(tmp_path, apt.port)
    assert main(["stage", "--config", str(bench), "move", "22"]) == 1
    assert "outside travel [0.0, 20.0] mm; nothing sent" in capsys.readouterr().err
    assert apt.position_mm == 0.0
    assert main(["stage", "--config", str(bench), "--travel-mm", "0", "50", "move", "22"]) == 2
    err = capsys.readouterr().err
    assert "--travel-mm 0 50 reaches beyond the bench file's travel 0 .. 20 mm" in err
    assert apt.position_mm == 0.0
    assert main(["stage", "--config", str(bench), "--counts-per-mm", "34304", "where"]) == 2
    assert "contradicts the bench file's" in capsys.readouterr().err
    assert main(["stage", "--config", str(bench), "move", "12.5"]) == 0
    assert "position 12.5000 mm" in capsys.readouterr().out
    assert apt.position_mm == pytest.approx(12.5, abs=1e-4)
