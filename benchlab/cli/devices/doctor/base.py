"""The doctor's state and what every step uses: recording a check, running one so that a
device error is its FAIL, skipping the checks that depend on a failed one."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from benchlab.cli.devices.doctor.record import Outside
from benchlab.cli.devices.doctor.report import Check
from benchlab.drivers.errors import BenchlabError

if TYPE_CHECKING:
    from benchlab.bench import BenchConfig


EXPOSURE_MS = 100.0  # longer than a full-frame readout (27 ms): the period is the exposure
ROI = 256  # linearity and depths read a 256 x 256 frame when the camera takes it: fast
SIM_LED_E_PER_MS_PER_MA = 40.0
SIM_STAGE_TIME_SCALE = 2000.0  # the simulated stage moves this much faster than real time
#: Free-running frames timed against the host clock when the timestamp unit is in question.
TIMESTAMP_FRAMES = 5
#: A dial gauge's own error (a 0.01 mm gauge: about +-0.01 mm over the move), mm.
GAUGE_ERROR_MM = 0.01
#: A measured scale is taken as a known actuator's within this fraction.
SCALE_MATCH = 0.004
#: The scale step's longest move: 20 mm on a 25 mm actuator (a gauge's range, and clear of
#: the far limit switch).
SCALE_MOVE_MAX_MM = 20.0
_T = TypeVar("_T")


@dataclass
class DoctorBase:
    """What every step uses: the bench file, the answers, the checks so far, what was learned;
    ``ask`` gets a yes/no question, ``measure`` a number (None: skip)."""

    config: BenchConfig
    simulate: bool
    ask: Callable[[str], bool]
    measure: Callable[[str], float | None]
    inject: tuple[str, ...] = ()
    say: Callable[[str], None] = print
    outside: Outside = field(default_factory=Outside)
    checks: list[Check] = field(default_factory=list)
    learned: dict[tuple[str, str], Any] = field(default_factory=dict)
    sims: dict[str, Any] = field(default_factory=dict)
    usb_sysfs: Path | None = None  # where USB devices are listed (default: Linux sysfs)
    #: The step running now (the report names it when the run is interrupted).
    current_step: str | None = None
    stage_time_scale: float = 1.0
    #: Whether what is learned goes into a bench file (``--config`` given, not a replay).
    writes_bench_file: bool = False
    #: The camera opened with the profile that fits, when the configured one did not.
    _fitted: Any = field(default=None, init=False, repr=False)

    @property
    def learned_note(self) -> str:
        """How a learned fact reaches the bench file, for the report's "what to do" lines."""
        return ("(written to the bench file)" if self.writes_bench_file
                else "(in your bench file; `benchlab doctor --config FILE` writes it)")

    def add(self, step: str, status: str, detail: str, todo: str = "") -> None:
        self.checks.append(Check(step, status, detail, todo))
        self.say(f"[{status:>4}] {step}: {detail}" + (f"\n       -> {todo}" if todo else ""))

    @property
    def failed(self) -> bool:
        return any(c.status == "FAIL" for c in self.checks)

    @property
    def replaying(self) -> bool:
        return self.outside.replaying

    def attempt(self, step: str, meaning: str, check: Callable[[], _T]) -> _T | None:
        """Run one check; a device error is its FAIL (with what it means on the bench) and
        None, so the run goes on with the checks that do not depend on it."""
        self.current_step = step
        try:
            return check()
        except (BenchlabError, OSError) as exc:
            self.add(step, "FAIL", _replay_reason() or _one_line(exc), meaning)
            return None

    def skip(self, steps: tuple[str, ...], why: str) -> None:
        for step in steps:
            self.add(step, "skip", f"not run: {why}")

    @property
    def _channel(self) -> int:
        """The LED channel the bench file names (1 without an ``[led]`` section)."""
        return self.config.led.channel if self.config.led is not None else 1

    def _ask(self, question: str) -> bool:
        return bool(self.outside.get(f"ask: {question}", lambda: self.ask(question)))

    def _measure(self, question: str) -> float | None:
        return self.outside.get("measure", lambda: self.measure(question))

    # ---- serial ports (the LED controller and the stage) -----------------------------------
    def _serial_port(self, device: str, configured: str | None) -> str | None:
        if self.replaying:
            return configured or f"replay://{device}"  # the replay's pseudo-terminal
        if self.simulate:
            return str(self.sims[device].port)
        return configured

    def _ports_seen(self) -> str:
        return str(self.outside.get("serial-ports", _ports_seen))


def _replay_reason() -> str | None:
    """While a cassette is replayed, why a serial device dropped the line (it diverged)."""
    from benchlab.drivers.trace import replay

    return replay.divergence() if replay.active() else None


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


def _ports_seen() -> str:
    """USB serial ports on this machine, as hwgrep URLs that find them again after a reboot."""
    from serial.tools import list_ports

    seen = [f"{q.device} ({q.description}; port = \"hwgrep://{q.serial_number}\")"
            if q.serial_number else f"{q.device} ({q.description})"
            for q in sorted(list_ports.comports(), key=lambda q: q.device) if q.vid is not None]
    return "; USB serial ports seen: " + ", ".join(seen) if seen else "; no USB serial port seen"
