"""SafeInstrument: close (= make safe) on every exit path, original errors kept."""

from __future__ import annotations

import atexit

import pytest

from benchlab.drivers.errors import DeviceError
from benchlab.drivers.safety import SafeInstrument


class Lamp(SafeInstrument):
    SAFE_ACTION = "switching the lamp off"

    def __init__(self, fail_close: bool = False) -> None:
        self.open_ = False
        self.closed = 0
        self.fail_close = fail_close

    def open(self) -> Lamp:
        self.open_ = True
        self._register_atexit()
        return self

    def close(self) -> None:
        self.closed += 1
        self.open_ = False
        self._unregister_atexit()
        if self.fail_close:
            raise DeviceError("port gone")

    @property
    def is_open(self) -> bool:
        return self.open_


def test_context_opens_and_closes() -> None:
    with Lamp() as lamp:
        assert lamp.is_open and lamp._atexit_cb is not None
    assert lamp.closed == 1 and not lamp.is_open and lamp._atexit_cb is None


def test_exception_inside_closes_and_keeps_the_error() -> None:
    lamp = Lamp()
    with pytest.raises(RuntimeError, match="boom"), lamp:
        raise RuntimeError("boom")
    assert lamp.closed == 1


def test_failed_safe_state_is_noted_on_the_original_error() -> None:
    lamp = Lamp(fail_close=True)
    with pytest.raises(KeyboardInterrupt) as info, lamp:
        raise KeyboardInterrupt
    assert info.value.__notes__ == ["switching the lamp off also failed: port gone"]


def test_failed_safe_state_without_error_raises() -> None:
    with pytest.raises(DeviceError, match="port gone"), Lamp(fail_close=True):
        pass


def test_atexit_hook_closes_an_open_instrument(monkeypatch: pytest.MonkeyPatch) -> None:
    registered: list = []
    monkeypatch.setattr(atexit, "register", registered.append)
    monkeypatch.setattr(atexit, "unregister", lambda cb: registered.remove(cb))
    lamp = Lamp().open()
    assert len(registered) == 1
    registered[0]()  # what the interpreter does at exit
    assert lamp.closed == 1 and registered == []
