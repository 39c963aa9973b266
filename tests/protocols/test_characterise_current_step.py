"""The characterisation's LED current sweep on the LED controller's own current step: an SLC
"CA" module (5 mA steps, simulated on a real pseudo-terminal) gets only currents it can drive,
the journal says which, and a current it cannot drive is refused before any light."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from sim_runs import TINY, events, yes

from benchlab.bench import Bench, BenchConfig
from benchlab.drivers.errors import SettingOutOfRangeError
from benchlab.drivers.slc.sim import SimulatedSlc
from benchlab.protocols import StepFailed, load_params, start_run
from benchlab.protocols.characterise.steps import CURRENTS_EVENT, sweep_points
from benchlab.storage import load_frame_tiff

pytestmark = pytest.mark.timeout(120)

# Saturation near 200 mA at 5 ms: a 5 mA grid has points enough for the response calibration.
CURRENT_SWEEP = TINY.replace("[sweep]", '[led]\ncurrent_ma = 250.0\n[sweep]\n'
                             'vary = "led_current"\nexposure_ms = 5.0\nprobe_start_ma = 0.5')


@pytest.fixture
def ca_sim() -> Iterator[SimulatedSlc]:
    with SimulatedSlc(module="SLC-CA04-MU") as sim:
        yield sim


def _run(root: Path, text: str, sim: SimulatedSlc) -> Any:
    params = root / "params.toml"
    root.mkdir(parents=True, exist_ok=True)
    params.write_text(text)
    cfg = BenchConfig.from_dict({"led": {"port": sim.port, "channel": 1,
                                         "ceiling_ma": {"1": 250.0}}})
    with Bench.open(cfg, simulate=True) as bench:
        assert bench.led_current_step_ma(1) == 5.0 and bench.led_max_current_ma(1) == 250.0
        runner = start_run("characterise", bench=bench, params=params, root=root,
                           operator="test", prompt=yes)
        return runner.run()


def test_current_sweep_on_a_ca_module_sets_only_its_5_ma_steps(
        tmp_path: Path, ca_sim: SimulatedSlc) -> None:
    out = _run(tmp_path / "s", CURRENT_SWEEP, ca_sim)
    session = Path(out.session_path)
    (said,) = [e for e in events(session) if e["kind"] == CURRENTS_EVENT]
    assert said["current_step_ma"] == 5.0
    assert said["currents_ma"] and all(c % 5 == 0 and 5 <= c <= 250 for c in said["currents_ma"])
    assert said["stack_current_ma"] % 5 == 0
    lit = 0
    for tiff in sorted((session / "frames").glob("sweep-*lit*.tiff")):
        meta = load_frame_tiff(tiff)[1]
        lit += 1
        # The controller drove exactly what was asked - the 0.5 mA probe start used to be
        # sent as 0 mA (a dark "lit" frame, silently).
        assert meta["led_current_ma"] % 5 == 0 and meta["led_current_ma"] >= 5
        assert meta["led_current_set_ma"] == meta["led_current_ma"]
        assert meta["bench"]["led_current_ma"]["1"] == meta["led_current_ma"]
    assert lit > 20
    (config,) = out.summary["summary"]["configs"]  # results/vN/summary.json says it too
    assert config["current_step_ma"] == 5.0 and config["currents_set_ma"] == said["currents_ma"]
    row = out.tables["characterisation"][0]
    assert row["system_gain_dn_per_e"] == pytest.approx(0.20475, rel=0.03)  # the truth
    assert row["saturation_reached"] is True
    assert ca_sim.channel_output_ma(1) == 0.0


def test_a_fixed_current_the_ca_module_cannot_drive_fails_before_any_light(
        tmp_path: Path, ca_sim: SimulatedSlc) -> None:
    text = TINY.replace("[sweep]", "[led]\ncurrent_ma = 12.0\n[sweep]")
    with pytest.raises(StepFailed, match=r"led.current_ma 12 mA cannot be set.*5 mA steps"):
        _run(tmp_path / "s", text, ca_sim)
    assert not any(b.startswith(b"NORMAL") for b in ca_sim.host_lines())


def test_sweep_points_stay_on_the_current_step(tmp_path: Path) -> None:
    path = tmp_path / "p.toml"
    path.write_text(CURRENT_SWEEP)
    params = load_params("characterise", path)
    for step in (0.1, 1.0, 5.0):
        points = sweep_points(params, 23.0, step)
        assert all(abs(x / step - round(x / step)) < 1e-9 for x in points)
        assert min(points) == step and max(points) <= 250.0
    assert sweep_points(params, 23.0, 0.1) == sweep_points(params, 23.0)  # default grid
    path.write_text(CURRENT_SWEEP.replace("current_ma = 250.0", "current_ma = 3.0")
                    .replace("probe_start_ma = 0.5", "probe_start_ma = 0.2"))
    low = load_params("characterise", path)
    with pytest.raises(SettingOutOfRangeError, match="3 mA is below the LED controller's 5 mA"):
        sweep_points(low, 2.0, 5.0)
