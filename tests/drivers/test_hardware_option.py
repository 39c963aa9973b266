"""`pytest --hardware bench.toml`: the contract suites run on the devices the bench file
names; here the "hardware" is a simulator on a pseudo-terminal, named only by its port."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from conftest import hardware_environment

from benchlab.drivers.slc.sim import SimulatedSlc

ROOT = Path(__file__).parents[2]


def test_the_bench_file_names_the_devices_and_their_limits(tmp_path: Path) -> None:
    bench = tmp_path / "bench.toml"
    bench.write_text('[camera]\nserial = "13-000123"\nmodel = "MCE-B013-U"\n'
                     '[led]\nport = "/dev/ttyUSB0"\n[led.ceiling_ma]\n1 = 50.0\n'
                     '[stage]\nport = "hwgrep://0403:FAF0"\nactuator = "Z8-34304"\n'
                     "travel_mm = [0.0, 25.0]\n", encoding="utf-8")
    assert hardware_environment(str(bench)) == {
        "BENCHLAB_HW_CAMERA_SERIAL": "13-000123", "BENCHLAB_HW_CAMERA_MODEL": "MCE-B013-U",
        "BENCHLAB_HW_LED_PORT": "/dev/ttyUSB0", "BENCHLAB_HW_LED_CEILING_MA": "10",
        "BENCHLAB_HW_STAGE_PORT": "hwgrep://0403:FAF0", "BENCHLAB_HW_STAGE_TRAVEL_MM": "0,25",
        "BENCHLAB_HW_STAGE_COUNTS_PER_MM": "34304.0"}


@pytest.mark.slow
def test_the_light_source_contract_runs_on_the_named_port(tmp_path: Path) -> None:
    with SimulatedSlc(channels=4) as sim:
        bench = tmp_path / "bench.toml"
        bench.write_text(f'[led]\nport = "{sim.port}"\n[led.ceiling_ma]\n1 = 10.0\n',
                         encoding="utf-8")
        run = subprocess.run(
            [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--hardware",
             str(bench), "tests/drivers/test_contract_light_source.py", "-k", "hw-slc"],
            cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stdout[-2000:]
    assert " passed" in run.stdout and "skipped" not in run.stdout
