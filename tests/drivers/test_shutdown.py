"""The shared stop-signal mechanism (benchlab.drivers.shutdown), in-process."""

from __future__ import annotations

import gc
import os
import signal

import pytest

from benchlab.drivers import shutdown


class _Lamp:
    def __init__(self) -> None:
        self.calls = 0

    def _on_stop_signal(self) -> None:
        self.calls += 1


def test_sigterm_raises_stopped_with_its_exit_status() -> None:
    before = signal.getsignal(signal.SIGTERM)
    lamp = _Lamp()
    with shutdown.handling_signals():
        shutdown.watch(lamp)
        gc.disable()  # a handler's exception raised inside a gc callback would be lost
        try:
            with pytest.raises(shutdown.Stopped) as info:
                os.kill(os.getpid(), signal.SIGTERM)  # handled before os.kill returns
        finally:
            gc.enable()
        shutdown.unwatch(lamp)
    assert isinstance(info.value, KeyboardInterrupt)  # every Ctrl-C path handles it
    assert info.value.exit_status == 143 and info.value.signal_name == "SIGTERM"
    assert shutdown.interrupt_reason(info.value) == "SIGTERM"
    assert lamp.calls == 1  # instruments act first
    assert signal.getsignal(signal.SIGTERM) == before  # handlers restored


def test_second_signal_while_stopping_is_ignored(capsys: pytest.CaptureFixture[str]) -> None:
    seen: list[int] = []
    with shutdown.handling_signals(on_signal=seen.append):
        os.kill(os.getpid(), signal.SIGHUP)
        os.kill(os.getpid(), signal.SIGTERM)
        assert shutdown.received() == signal.SIGHUP
    assert seen == [signal.SIGHUP]
    assert "SIGTERM ignored: already stopping" in capsys.readouterr().err


def test_bare_keyboard_interrupt_is_130() -> None:
    assert shutdown.exit_status(KeyboardInterrupt()) == 130
    assert shutdown.interrupt_reason(KeyboardInterrupt()) == "KeyboardInterrupt"


def test_watching_installs_default_handlers_and_unwatching_restores_them() -> None:
    previous = signal.signal(signal.SIGHUP, signal.SIG_DFL)
    try:
        lamp = _Lamp()
        shutdown.watch(lamp)  # a script using a driver directly, no CLI around it
        try:
            assert signal.getsignal(signal.SIGHUP) is shutdown._handle
        finally:
            shutdown.unwatch(lamp)
        assert signal.getsignal(signal.SIGHUP) == signal.SIG_DFL
    finally:
        signal.signal(signal.SIGHUP, previous)


def test_a_signal_after_the_grace_period_acts_again(monkeypatch: pytest.MonkeyPatch) -> None:
    """If the first stop was swallowed (raised inside a finaliser), a later signal works."""
    seen: list[int] = []
    clock = [1000.0]
    monkeypatch.setattr(shutdown.time, "monotonic", lambda: clock[0])
    with shutdown.handling_signals(on_signal=seen.append):
        os.kill(os.getpid(), signal.SIGTERM)
        clock[0] += shutdown.REPEAT_GRACE_S / 2
        os.kill(os.getpid(), signal.SIGTERM)  # within the grace period: ignored
        clock[0] += shutdown.REPEAT_GRACE_S
        os.kill(os.getpid(), signal.SIGHUP)  # later: acts again
    assert seen == [signal.SIGTERM, signal.SIGHUP]


class _SlowPort:
    """A serial port whose replies arrive only when read: after ``reset_input_buffer``, as a
    late reply to an interrupted command does on a real line."""

    def __init__(self) -> None:
        self.pending: list[bytes] = []
        self.arrived = b""
        self.in_waiting = 0
        self.interrupt_next_read = False

    def reset_input_buffer(self) -> None:
        self.arrived = b""

    def write(self, data: bytes) -> int:
        self.pending.append(b"#1\r\n" if data.startswith(b"?MODE") else b"##\r\n")
        return len(data)

    def read_until(self, end: bytes) -> bytes:
        if self.interrupt_next_read:
            self.interrupt_next_read = False
            raise shutdown.Stopped(signal.SIGTERM)  # the signal lands while waiting
        self.arrived += b"".join(self.pending)
        self.pending.clear()
        line, sep, rest = self.arrived.partition(end)
        self.arrived = rest
        return line + sep

    def read(self, size: int = 1) -> bytes:
        self.arrived += b"".join(self.pending)
        self.pending.clear()
        out, self.arrived = self.arrived[:size], self.arrived[size:]
        return out

    def close(self) -> None: ...


def test_slc_late_reply_of_an_interrupted_command_is_not_taken_for_the_next() -> None:
    from benchlab.drivers.slc.controller import SlcController, SlcMode

    slc = SlcController("fake", ceilings_ma={1: 50.0})
    port = _SlowPort()
    slc._ser = port  # type: ignore[assignment]
    slc._channel_count = 1
    port.interrupt_next_read = True
    with pytest.raises(shutdown.Stopped):
        slc.off(1)  # "MODE 1 0" went out; its "##" comes after the interrupt
    assert slc.get_mode(1) is SlcMode.NORMAL  # the "#1" it asked for, not the late "##"
