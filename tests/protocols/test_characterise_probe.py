"""The saturation probe when the probe start already saturates: halved until a probe is clearly
unsaturated (saved as ``probe-hNN``), refused naming the parameter when it never is."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from benchlab.drivers.errors import SettingOutOfRangeError
from benchlab.protocols.characterise.steps import MAX_PROBE_HALVINGS, probe_saturation
from benchlab.protocols.params import parse_params

DARK_DN = 64.0


def _params(**sweep: Any) -> Any:
    return parse_params("characterise", {"procedure": "characterise", "sweep": sweep})


def _sensor(rate_dn_per_unit: float, ceiling_dn: float, grabbed: list[tuple[str, float]]
            ) -> Any:
    """A linear flat field clipped at ``ceiling_dn``; records what was grabbed."""
    def grab(name: str, x: float, lit: bool) -> Any:
        grabbed.append((name, x))
        level = min(DARK_DN + (rate_dn_per_unit * x if lit else 0.0), ceiling_dn)
        return np.full((4, 4), level)
    return grab


@pytest.mark.parametrize("ceiling", [4095.0, 3900.0])  # the top code, or full well below it
def test_a_saturated_probe_start_is_halved(ceiling: float) -> None:
    grabbed: list[tuple[str, float]] = []
    # Saturates at (ceiling - 64) / 100 ms: 40.3 or 38.4 ms; the probe starts at 600 ms.
    x_sat, found = probe_saturation(_sensor(100.0, ceiling, grabbed),
                                    _params(probe_start_ms=600.0), 12)
    assert found and x_sat == pytest.approx((ceiling - DARK_DN) / 100.0, rel=1e-6)
    halved = [x for name, x in grabbed if name.startswith("probe-h")]
    # 37.5 ms reads 93 % of saturation (not clearly under it); 18.75 ms is the first below 90 %.
    assert halved == [300.0, 150.0, 75.0, 37.5, 18.75]
    # Before the fix the extrapolation was never reached: x_sat was the probe start itself.


def test_an_unsaturated_probe_start_is_not_halved() -> None:
    grabbed: list[tuple[str, float]] = []
    x_sat, found = probe_saturation(_sensor(100.0, 4095.0, grabbed),
                                    _params(probe_start_ms=0.5), 12)
    assert found and x_sat == pytest.approx(40.31, rel=1e-6)
    assert not any(name.startswith("probe-h") for name, _ in grabbed)


def test_a_probe_saturated_at_every_exposure_is_refused() -> None:
    grabbed: list[tuple[str, float]] = []
    with pytest.raises(SettingOutOfRangeError, match=r"sweep\.probe_start_ms 600 ms"):
        probe_saturation(_sensor(1e7, 4095.0, grabbed), _params(probe_start_ms=600.0), 12)
    halved = [x for name, x in grabbed if name.startswith("probe-h")]
    assert len(halved) == MAX_PROBE_HALVINGS and halved[-1] == pytest.approx(
        round(600.0 / 2**MAX_PROBE_HALVINGS / 0.05) * 0.05)


def test_a_current_sweep_probe_names_its_parameter() -> None:
    grabbed: list[tuple[str, float]] = []
    params = _params(vary="led_current", probe_start_ma=10.0)
    x_sat, found = probe_saturation(_sensor(1000.0, 4095.0, grabbed), params, 12, 0.1)
    assert found and x_sat == pytest.approx(4.031, rel=1e-6)  # halved to 5 mA, then 2.5
    with pytest.raises(SettingOutOfRangeError, match=r"sweep\.probe_start_ma 10 mA"):
        probe_saturation(_sensor(1e7, 4095.0, []), params, 12, 0.1)
