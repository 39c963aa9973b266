"""Light-source contract: every LightSource implementation behaves the same (simulator always,
hardware on opt-in; see tests/device_implementations.py)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from device_implementations import LED_CEILING_MA, LIGHT_SOURCES, Implementation

from benchlab.drivers.errors import DeviceError, SafetyLimitError, SettingOutOfRangeError
from benchlab.drivers.interfaces import LightSource

pytestmark = pytest.mark.timeout(60)


@pytest.fixture(params=LIGHT_SOURCES, ids=str)
def led(request: pytest.FixtureRequest) -> Iterator[LightSource]:
    impl: Implementation[LightSource] = request.param
    with impl.opener() as source:
        yield source


def _all_dark(led: LightSource) -> bool:
    return not any(led.is_on(ch) for ch in range(1, led.channel_count + 1))


def test_opens_dark_with_an_identity(led: LightSource) -> None:
    assert isinstance(led, LightSource)
    assert led.is_open and led.channel_count >= 2
    ident = led.identity
    assert ident.model and ident.serial and ident.firmware and ident.port
    assert _all_dark(led)
    assert led.ceiling_ma(1) == LED_CEILING_MA and led.ceiling_ma(2) is None


def test_on_sets_the_current_and_off_darkens(led: LightSource) -> None:
    current = LED_CEILING_MA / 2
    led.on(1, current)
    assert led.is_on(1)
    assert led.current_ma(1) == pytest.approx(current, abs=1.0)
    led.off(1)
    assert not led.is_on(1)


def test_all_off_darkens_every_channel(led: LightSource) -> None:
    led.on(1, LED_CEILING_MA)
    led.all_off()
    assert _all_dark(led)


@pytest.mark.parametrize("current_ma", [LED_CEILING_MA + 0.5, 1e9])
def test_above_the_ceiling_is_refused_and_stays_dark(led: LightSource, current_ma: float) -> None:
    with pytest.raises(SafetyLimitError, match="ceiling"):
        led.on(1, current_ma)
    assert not led.is_on(1)


def test_channel_without_ceiling_stays_dark(led: LightSource) -> None:
    with pytest.raises(SafetyLimitError, match="no configured ceiling"):
        led.on(2, 1.0)
    assert not led.is_on(2)


@pytest.mark.parametrize("current_ma", [float("nan"), float("inf"), -1.0, True])
def test_bad_current_is_refused(led: LightSource, current_ma: float) -> None:
    with pytest.raises(SettingOutOfRangeError):
        led.on(1, current_ma)
    assert not led.is_on(1)


@pytest.mark.parametrize("ch", [0, -1, 99, True, 1.0])
def test_missing_channel_is_refused(led: LightSource, ch: int) -> None:
    with pytest.raises(SettingOutOfRangeError, match="does not exist"):
        led.on(ch, 1.0)
    with pytest.raises(SettingOutOfRangeError, match="does not exist"):
        led.off(ch)


def test_closed_source_refuses_commands(led: LightSource) -> None:
    led.on(1, LED_CEILING_MA)
    led.close()
    assert not led.is_open
    with pytest.raises(DeviceError, match="not open"):
        led.on(1, 1.0)
