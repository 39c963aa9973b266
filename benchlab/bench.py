"""The bench: which devices are open, and the one place that puts them in a safe state.

``Bench.open(config, simulate=...)`` is a context manager. On the real bench it opens the
Mightex camera (USB), the SLC LED controller and the APT stage (serial ports from the config).
Simulated, it builds the simulated world (scenes), a firmware-level camera on a pyusb backend
and the LED controller and stage simulators on real pseudo-terminals, and connects the *same
drivers* to them, so every procedure runs through the real code paths.

Safety: :meth:`Bench.safe_state` (every LED channel off, stage stopped) runs on every way out
of the context - normal end, exception, Ctrl-C - before the devices are closed; the drivers'
own exit hooks repeat it if the process dies in between.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import os
import threading
import tomllib
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from benchlab.drivers.apt.protocol import (
    ACTUATOR_TRAVEL_MM,
    COMPLETION_TOLERANCE_COUNTS,
    Z8_COUNTS_PER_MM,
    actuator_counts_per_mm,
)
from benchlab.drivers.errors import BenchlabError, DeviceError, DeviceLostError
from benchlab.drivers.interfaces import Camera, FrameMetadata, LightSource, LinearStage
from benchlab.drivers.mightex.profile import TIMESTAMP_UNITS_MS, TRAILER_ORDERS

if TYPE_CHECKING:
    from benchlab.drivers.apt.sim import SimulatedAptStage
    from benchlab.drivers.mightex.sim import SimulatedCamera
    from benchlab.drivers.slc.sim import SimulatedSlc
    from benchlab.scenes.world import SimWorld
from benchlab.checks import BenchLimits, ParamsError, TableChecker

log = logging.getLogger(__name__)

#: Reply timeout of the in-process LED and stage simulators, s. They are threads of this process:
#: on a loaded CPU one was seen to answer after a real device's 1 s (issue 30), failing a step
#: for a reason no bench has. Tests that inject a silent simulator shorten it.
SIM_REPLY_TIMEOUT_S = 10.0
#: Simulated seconds per wall second on the simulated bench: stage moves take milliseconds.
SIM_TIME_SCALE = 2000.0


class BenchConfigError(ParamsError):
    """A bench configuration file has problems (all listed)."""


@dataclass(frozen=True)
class CameraConfig:
    serial: str | None = None
    pid: int | None = None
    model: str | None = None
    #: Response calibration file (``benchlab run characterise``), absolute once loaded.
    response_calibration: str | None = None
    #: Profile facts ``benchlab doctor`` settled on this bench (None: the model's own).
    trailer_order: str | None = None
    timestamp_unit_ms: float | None = None
    #: The bit depths whose frames decode on this camera (``benchlab doctor`` writes them);
    #: runs take their default depths from here and refuse the others.
    bit_depths: tuple[int, ...] | None = None

    def profile(self) -> Any:
        """The camera profile: the model's (MCE-B013-U by default) with the facts above."""
        from benchlab.drivers.mightex import protocol as p

        spec = p.spec_for(self.model or "MCE-B013-U")
        if self.trailer_order is not None:
            spec = dataclasses.replace(spec, trailer_order=self.trailer_order)
        if self.timestamp_unit_ms is not None:
            spec = dataclasses.replace(spec, timestamp_unit_ms=self.timestamp_unit_ms)
        if self.bit_depths is not None:
            spec = dataclasses.replace(spec, bit_depths=self.bit_depths)
        return spec


@dataclass(frozen=True)
class LedConfig:
    port: str | None = None
    channel: int = 1
    ceilings_ma: Mapping[int, float] = field(default_factory=lambda: {1: 50.0})


@dataclass(frozen=True)
class StageConfig:
    port: str | None = None
    counts_per_mm: float = Z8_COUNTS_PER_MM
    travel_mm: tuple[float, float] = (0.0, 25.0)
    #: ``stage.actuator``: "Z8" (34554.96 counts/mm), "Z8-34304" or "Z6" (see apt.protocol).
    actuator: str | None = None
    velocity_mm_s: float = 2.0
    #: A completed move must end this close to its target (``stage.tolerance_counts``).
    tolerance_counts: int = COMPLETION_TOLERANCE_COUNTS


@dataclass(frozen=True)
class BenchConfig:
    """Bench wiring from a TOML file; every section optional.

    ``led`` / ``stage`` are ``None`` when the bench has no such device (the procedures then
    prompt the operator instead).
    """

    camera: CameraConfig = field(default_factory=CameraConfig)
    led: LedConfig | None = None
    stage: StageConfig | None = None
    source: str = "<defaults>"
    #: ``[paths] sessions``: where new sessions go when no ``--out`` is given (``~`` expanded).
    sessions_dir: Path | None = None

    @property
    def has_stage(self) -> bool:
        return self.stage is not None

    @property
    def stage_travel_mm(self) -> tuple[float, float] | None:
        return self.stage.travel_mm if self.stage is not None else None

    def led_ceiling_ma(self, channel: int) -> float | None:
        if self.led is None:
            return None
        return self.led.ceilings_ma.get(channel)

    def limits(self) -> BenchLimits:
        """What procedure parameters are checked against before a run."""
        return BenchLimits(
            led_ceilings_ma=dict(self.led.ceilings_ma) if self.led is not None else None,
            stage_travel_mm=self.stage.travel_mm if self.stage is not None else None,
            camera_bit_depths=self.camera.bit_depths,
        )

    # -- (de)serialisation ----------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"camera": {k: v for k, v in vars(self.camera).items()
                                          if v is not None}}
        if self.led is not None:
            out["led"] = {"channel": self.led.channel,
                          "ceiling_ma": {str(k): v for k, v in self.led.ceilings_ma.items()}}
            if self.led.port:
                out["led"]["port"] = self.led.port
        if self.stage is not None:
            out["stage"] = {"counts_per_mm": self.stage.counts_per_mm,
                            **({"actuator": self.stage.actuator} if self.stage.actuator else {}),
                            "travel_mm": list(self.stage.travel_mm),
                            "velocity_mm_s": self.stage.velocity_mm_s,
                            "tolerance_counts": self.stage.tolerance_counts}
            if self.stage.port:
                out["stage"]["port"] = self.stage.port
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], source: str = "<bench config>") -> BenchConfig:
        """Validate a parsed configuration; :class:`BenchConfigError` lists every problem."""
        c = TableChecker(data)
        cam = CameraConfig(
            serial=c.string("camera.serial", "") or None,
            pid=(c.integer("camera.pid", 0, 0, 0xFFFF) or None),
            model=c.string("camera.model", "") or None,
            response_calibration=c.string("camera.response_calibration", "") or None,
            trailer_order=c.choice("camera.trailer_order", None, TRAILER_ORDERS),
            timestamp_unit_ms=c.choice("camera.timestamp_unit_ms", None, TIMESTAMP_UNITS_MS),
            bit_depths=_bit_depths(c),
        )
        led = None
        found, _ = c.get("led", None)
        if found:
            ceilings: dict[int, float] = {}
            f2, table = c.get("led.ceiling_ma", {1: 50.0})
            if f2 and not isinstance(table, Mapping):
                c.fail("led.ceiling_ma", "must be a table: channel number -> mA")
            elif f2:
                for key in table:
                    dotted = f"led.ceiling_ma.{key}"
                    if not str(key).isdigit() or not 1 <= int(key) <= 16:
                        c.seen.add(dotted)
                        c.fail(dotted, "channel must be a number 1..16")
                        continue
                    ceilings[int(key)] = c.number(dotted, 0.0, 0.0, 5000.0)
            else:
                ceilings = {1: 50.0}
            led = LedConfig(port=c.string("led.port", "") or None,
                            channel=c.integer("led.channel", 1, 1, 16), ceilings_ma=ceilings)
        stage = None
        found, _ = c.get("stage", None)
        if found:
            actuator = c.string("stage.actuator", "")
            default_travel = (0.0, ACTUATOR_TRAVEL_MM.get(actuator, ACTUATOR_TRAVEL_MM["Z8"]))
            travel = c.numbers("stage.travel_mm", default_travel, -1000.0, 1000.0)
            if len(travel) != 2 or travel[0] >= travel[1]:
                c.fail("stage.travel_mm", f"must be [low, high] with low < high, got {travel}")
                travel = default_travel
            scale = Z8_COUNTS_PER_MM
            if actuator:
                try:
                    scale = actuator_counts_per_mm(actuator)
                except ValueError as exc:
                    c.fail("stage.actuator", str(exc))
            found_scale, _ = c.get("stage.counts_per_mm", None)
            counts = c.number("stage.counts_per_mm", scale, 0.0, 1e9, lo_open=True)
            if actuator and found_scale and counts != scale:
                c.fail("stage.actuator", f"{actuator} means {scale} counts/mm but "
                       f"stage.counts_per_mm says {counts}: give one of them")
            stage = StageConfig(
                port=c.string("stage.port", "") or None,
                counts_per_mm=counts, actuator=actuator or None,
                travel_mm=(travel[0], travel[1]),
                velocity_mm_s=c.number("stage.velocity_mm_s", 2.0, 0.0, 100.0, lo_open=True),
                tolerance_counts=c.integer("stage.tolerance_counts",
                                           COMPLETION_TOLERANCE_COUNTS, 1, 100_000),
            )
        sessions = c.string("paths.sessions", "")
        c.unknown_keys()
        if c.problems:
            raise BenchConfigError(source, c.problems)
        return cls(camera=cam, led=led, stage=stage, source=source,
                   sessions_dir=Path(sessions).expanduser() if sessions else None)

    @classmethod
    def from_session(cls, session_path: str | Path) -> BenchConfig:
        """The bench configuration a session was run with (its ``session.json`` snapshot)."""
        from benchlab.session import Session

        session = Session.open(Path(session_path))
        return cls.from_dict(dict(session.params.get("bench") or {}),
                             f"{session.path / 'session.json'}: bench")

    @classmethod
    def load(cls, path: str | Path | None, *, simulate: bool = False) -> BenchConfig:
        """Read a bench TOML file; ``None`` = the packaged simulated bench (``simulate``) or an
        empty configuration (camera only)."""
        if path is None:
            if not simulate:
                return cls()
            path = Path(str(resources.files("benchlab.protocols") / "defaults"
                            / "bench-simulated.toml"))
        p = Path(path)
        try:
            data = tomllib.loads(p.read_text(encoding="utf-8"))
        except FileNotFoundError as exc:
            raise BenchConfigError(str(p), ["file: no such bench configuration"]) from exc
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise BenchConfigError(str(p), [f"file: not valid TOML ({exc})"]) from exc
        cfg = cls.from_dict(data, str(p))
        calib = cfg.camera.response_calibration
        if calib is not None and not Path(calib).is_absolute():  # relative to the bench file
            # absolute: a session records it, and a re-analysis may run from another folder
            cam = dataclasses.replace(cfg.camera,
                                      response_calibration=os.path.abspath(p.parent / calib))
            cfg = dataclasses.replace(cfg, camera=cam)
        return cfg


class BenchError(BenchlabError):
    """The bench cannot do what was asked (e.g. no LED controller configured)."""


class Bench:
    """Open devices of one bench. Create with :meth:`open`."""

    def __init__(self, config: BenchConfig, *, simulated: bool) -> None:
        self.config = config
        #: The camera's frames at this bit depth are still to be checked for never-set bits.
        self._depth_unchecked = False
        self.simulated = simulated
        self.camera: Camera[FrameMetadata] | None = None
        self.led: LightSource | None = None
        self.stage: LinearStage | None = None
        #: Simulated bench only: the world, and the simulators (for tests and scenes).
        self.world: SimWorld | None = None
        self.sim_camera: SimulatedCamera | None = None
        self.sim_led: SimulatedSlc | None = None
        self.sim_stage: SimulatedAptStage | None = None
        self._mounted: object = None
        #: Where a stage-carried target sits: object distance = this + stage position (mm).
        self._object_offset_mm: float | None = None
        self._camera_settings: dict[str, Any] = {}
        self._camera_lost = False

    # -- lifecycle ------------------------------------------------------------------------------
    @classmethod
    @contextlib.contextmanager
    def open(
        cls, config: BenchConfig | None = None, *, simulate: bool = False, seed: int | None = 0,
        noise: bool = True, time_scale: float = SIM_TIME_SCALE,
    ) -> Iterator[Bench]:
        """Open every configured device (or its simulator); safe state on every way out.

        ``seed`` and ``noise`` apply to the simulated camera only (``noise=False``: exact,
        noise-free frames); ``time_scale`` is the simulated stage's seconds per wall second.
        """
        cfg = config if config is not None else BenchConfig.load(None, simulate=simulate)
        bench = cls(cfg, simulated=simulate)
        with contextlib.ExitStack() as stack:
            if simulate:
                open_simulated(bench, stack, seed=seed, noise=noise, time_scale=time_scale)
            else:
                _open_real(bench, stack)
            try:
                yield bench
            except BaseException as exc:
                try:
                    bench.safe_state()
                except BenchError as safe_exc:  # keep the error that got us here
                    exc.add_note(str(safe_exc))
                raise
            bench.safe_state()

    def recover(self) -> None:
        """Before retrying a failed step: reconnect a camera that was lost (unplugged and
        plugged back in); raises ``DeviceNotFoundError`` while it is still missing."""
        if self._camera_lost:
            self._open_camera().reopen()
            self._camera_lost = False

    def safe_state(self) -> None:
        """Every LED channel off and the stage stopped; tries both even if one fails."""
        log.debug("safe state: LEDs off, stage stopped")
        errors: list[str] = []
        done: list[str] = []
        if self.led is not None:
            try:
                self.led.all_off()
                done.append("LEDs off")
            except DeviceError as exc:
                errors.append(_named("LEDs", exc))
        if self.stage is not None:
            try:
                self.stage.stop(immediate=True)
                done.append("stage stopped")
            except DeviceError as exc:
                errors.append(_named("stage", exc))
        if errors:
            reached = f" ({', '.join(done)})" if done else ""
            log.info("could not reach the safe state: %s%s", "; ".join(errors), reached)
            raise BenchError("could not reach the safe state: " + "; ".join(errors) + reached)

    # -- identities -----------------------------------------------------------------------------
    def identities(self) -> dict[str, Any]:
        """Device identities (model, serial, firmware) for ``session.json``."""
        out: dict[str, Any] = {"simulated": self.simulated}
        for key, device in (("camera", self.camera), ("led", self.led), ("stage", self.stage)):
            if device is not None:
                out[key] = device.identity.to_dict()
        return out

    # -- camera ---------------------------------------------------------------------------------
    def _open_camera(self) -> Camera[FrameMetadata]:
        if self.camera is None:
            raise BenchError("the bench has no open camera")
        return self.camera

    def configure_camera(self, *, bits: int = 8, width: int = 1280,
                         height: int = 1024) -> dict[str, Any]:
        """Table 4.10 step 1: continuous (normal) mode, full 1280 x 1024 (no decimation) unless
        a smaller frame is asked for (the characterisation reads a 128 x 128 frame).

        A depth the bench file's ``[camera] bit_depths`` (what ``benchlab doctor`` found to
        decode) leaves out is refused; the frames of a depth above 8 are checked for bits
        that are never set (a mode the sensor does not really have) until one shows enough
        signal to tell."""
        allowed = self.config.camera.bit_depths
        if allowed is not None and bits not in allowed:
            raise BenchError(
                f"bit depth {bits} is not one this camera decodes: {self.config.source} "
                f"[camera] bit_depths = {list(allowed)} (settled by `benchlab doctor`); "
                "measure at one of those")
        self._open_camera().configure(width=width, height=height, bits=bits, mode="normal")
        self._depth_unchecked = bits > 8
        self._camera_settings = {"mode": "normal (continuous)", "width": width, "height": height,
                                 "decimation": "off", "bits": bits}
        return dict(self._camera_settings)

    def grab(
        self, *, exposure_ms: float, gain: float, fresh: bool = True
    ) -> tuple[npt.NDArray[np.uint8] | npt.NDArray[np.uint16], dict[str, Any]]:
        """One frame at these settings: ``(pixels, metadata)``.

        ``fresh`` (``Camera.grab``'s default): the frame is exposed wholly after this call, so
        it shows the set-up as it is now (a target just mounted, the LED just switched on).
        Without ``fresh`` the camera's newest buffered frame, possibly exposed before.
        """
        camera = self._open_camera()
        try:
            camera.set_exposure_ms(exposure_ms)
            camera.set_gain(gain)
            frame = camera.grab(fresh=fresh)
        except DeviceLostError:
            self._camera_lost = True
            raise
        if self._depth_unchecked:
            self._check_depth(frame.pixels, frame.meta.bits)
        meta = dict(frame.meta.to_dict())
        meta.update({"requested_exposure_ms": exposure_ms, "requested_gain": gain,
                     "bench": self.state(), "simulated": self.simulated})
        return frame.pixels, meta

    def _check_depth(self, pixels: npt.NDArray[Any], bits: int) -> None:
        """Refuse a bit depth whose frame shows bits that are never set (once one frame has
        the signal spread to tell)."""
        from benchlab.drivers.mightex.diagnose import never_set_bits_finding

        finding, decided = never_set_bits_finding(pixels, bits)
        if finding:
            raise BenchError(f"{bits}-bit frames: {finding}. This is not a real {bits}-bit "
                             "mode: measure at a depth `benchlab doctor` found to decode "
                             "(it writes [camera] bit_depths into the bench file)")
        self._depth_unchecked = not decided

    # -- LED and stage --------------------------------------------------------------------------
    @property
    def has_stage(self) -> bool:
        return self.stage is not None

    def led_on(self, channel: int, current_ma: float) -> None:
        if self.led is None:
            raise BenchError("no LED controller configured ([led] in the bench file)")
        self.led.on(channel, current_ma)

    def led_current_step_ma(self, channel: int) -> float:
        """The LED controller's current step on ``channel`` (mA): every current set is a whole
        multiple of it; another is refused (``SettingOutOfRangeError``)."""
        if self.led is None:
            raise BenchError("no LED controller configured ([led] in the bench file)")
        return self.led.current_step_ma(channel)

    def led_max_current_ma(self, channel: int) -> float | None:
        """The highest current ``channel`` can be set to: its ceiling on the current step."""
        if self.led is None:
            raise BenchError("no LED controller configured ([led] in the bench file)")
        return self.led.max_current_ma(channel)

    def led_off(self, channel: int) -> None:
        if self.led is not None:
            self.led.off(channel)

    def home_stage(self, abort: threading.Event | None = None) -> None:
        """Home the stage unless it is homed, and wait; when ``abort`` is set meanwhile, the
        stage is stopped at once (homing then ends with the driver's interrupted-move error)."""
        stage = self.stage
        if stage is not None and not stage.is_homed:
            with _stopped_on(stage, abort):
                stage.home()

    def move_stage_mm(self, position_mm: float, abort: threading.Event | None = None) -> None:
        """Move and wait; when ``abort`` is set meanwhile, the stage is stopped at once (the
        move then ends with the driver's interrupted-move error)."""
        stage = self.stage
        if stage is None:
            raise BenchError("no stage configured ([stage] in the bench file)")
        with _stopped_on(stage, abort):
            stage.move_to_mm(position_mm, wait=True)

    # -- the mounted target ---------------------------------------------------------------------
    def mount(self, target: object) -> None:
        """A manual set-up step was confirmed: on the simulated bench, mount ``target`` in the
        world ("usaf", ("radial", lp_per_mm, orientation), "led", "dark"); real bench: record.
        A target just mounted is not on the stage carriage until :meth:`carry_target` says so."""
        self._mounted = target
        self._object_offset_mm = None
        if self.world is not None:
            self.world.mount(target)

    def carry_target(self, object_offset_mm: float | None) -> None:
        """The mounted target rides on the stage carriage: its object distance is
        ``object_offset_mm`` + the stage position (depth of field). None: it does not."""
        self._object_offset_mm = None if object_offset_mm is None else float(object_offset_mm)

    @property
    def object_offset_mm(self) -> float | None:
        return self._object_offset_mm

    def place_led_by_hand(self, position_mm: float) -> None:
        """The operator moved the LED (no stage): the simulated world follows."""
        if self.world is not None:
            self.world.led_position_mm = position_mm

    @property
    def mounted(self) -> object:
        return self._mounted

    def state(self) -> dict[str, Any]:
        """What the bench knows about itself right now (frame metadata, scenes)."""
        st: dict[str, Any] = {"target": plain_target(self._mounted)}
        if self._object_offset_mm is not None:
            st["object_offset_mm"] = self._object_offset_mm
        if self.sim_led is not None:
            st["led_current_ma"] = {str(ch): self.sim_led.channel_output_ma(ch)
                                    for ch in range(1, self.sim_led.channel_count + 1)}
        elif self.simulated and self.led is not None and self.config.led is not None:
            st["led_current_ma"] = _led_output_ma(self.led, self.config.led.channel)
        if self.sim_stage is not None:
            st["stage_position_mm"] = self.sim_stage.position_mm
        elif self.stage is not None:
            with contextlib.suppress(DeviceError):
                st["stage_position_mm"] = self.stage.position_mm
        return st


def _named(device: str, exc: BaseException) -> str:
    """``exc``'s message led by the device it concerns (once: driver messages often are)."""
    text = str(exc)
    lead = "LED" if device == "LEDs" else device
    return text if text.lower().startswith(lead.lower()) else f"{device}: {text}"


def _led_output_ma(led: LightSource, channel: int) -> dict[str, float]:
    """The simulated camera's view of an LED on an external controller: asked over the wire."""
    with contextlib.suppress(DeviceError):
        if led.is_on(channel):
            return {str(channel): float(led.current_ma(channel))}
    return {str(channel): 0.0}


def plain_target(target: object) -> object:
    """A mounted target as plain data (tuples become lists) for JSON, comparison and display."""
    return list(target) if isinstance(target, tuple) else target


def _open_real(bench: Bench, stack: contextlib.ExitStack) -> None:
    from benchlab.drivers.mightex.camera import MightexCamera

    cfg = bench.config
    missing = [f"{name}.port" for name, dev in (("led", cfg.led), ("stage", cfg.stage))
               if dev is not None and not dev.port]
    if missing:
        raise BenchError(f"{cfg.source}: {', '.join(missing)} required on the real bench")
    bench.camera = stack.enter_context(MightexCamera.open(
        serial=cfg.camera.serial, pid=cfg.camera.pid, profile=cfg.camera.profile(),
    ))
    if cfg.led is not None and cfg.led.port:
        from benchlab.drivers.slc.controller import SlcController

        bench.led = stack.enter_context(SlcController(cfg.led.port,
                                                      ceilings_ma=cfg.led.ceilings_ma))
    if cfg.stage is not None and cfg.stage.port:
        from benchlab.drivers.apt.stage import AptStage

        bench.stage = stack.enter_context(AptStage(
            cfg.stage.port, counts_per_mm=cfg.stage.counts_per_mm,
            travel_mm=cfg.stage.travel_mm,
            completion_tolerance_counts=cfg.stage.tolerance_counts,
        ))
        bench.stage.set_velocity_mm_s(cfg.stage.velocity_mm_s)


def open_simulated(
    bench: Bench, stack: contextlib.ExitStack, *, seed: int | None = 0, noise: bool = True,
    time_scale: float = SIM_TIME_SCALE,
) -> None:
    """Build the simulated bench: world + camera firmware on a pyusb backend + SLC and APT
    simulators on pseudo-terminals, with the real drivers connected to them."""
    from benchlab.drivers.apt.sim import SimulatedAptStage
    from benchlab.drivers.apt.stage import AptStage
    from benchlab.drivers.mightex.camera import MightexCamera
    from benchlab.drivers.mightex.sim import SIM_CAMERA_SERIAL, SimCameraBackend, SimulatedCamera
    from benchlab.drivers.slc.controller import SlcController
    from benchlab.drivers.slc.sim import SimulatedSlc
    from benchlab.scenes.world import SimWorld

    cfg = bench.config
    bench.world = SimWorld("dark", led_channel=cfg.led.channel if cfg.led else None)
    if cfg.led is not None and cfg.led.port:
        # A serial simulator (or device) outside this process, e.g. `benchlab simulate`.
        bench.led = stack.enter_context(SlcController(cfg.led.port,
                                                      ceilings_ma=cfg.led.ceilings_ma))
    elif cfg.led is not None:
        sim_led = SimulatedSlc(channels=max(4, max(cfg.led.ceilings_ma, default=1)))
        sim_led.start()
        stack.callback(sim_led.stop)
        bench.sim_led = sim_led
        bench.led = stack.enter_context(
            SlcController(sim_led.port, ceilings_ma=cfg.led.ceilings_ma,
                          timeout_s=SIM_REPLY_TIMEOUT_S)
        )
    if cfg.stage is not None and cfg.stage.port:
        bench.stage = stack.enter_context(AptStage(
            cfg.stage.port, counts_per_mm=cfg.stage.counts_per_mm, travel_mm=cfg.stage.travel_mm,
        ))
        bench.stage.set_velocity_mm_s(cfg.stage.velocity_mm_s)
    elif cfg.stage is not None:
        sim_stage = SimulatedAptStage(
            counts_per_mm=cfg.stage.counts_per_mm, travel_mm=cfg.stage.travel_mm,
            velocity_mm_s=cfg.stage.velocity_mm_s, time_scale=time_scale,
        )
        sim_stage.start()
        stack.callback(sim_stage.stop)
        bench.sim_stage = sim_stage
        bench.stage = stack.enter_context(AptStage(
            sim_stage.port, counts_per_mm=cfg.stage.counts_per_mm, travel_mm=cfg.stage.travel_mm,
            timeout_s=SIM_REPLY_TIMEOUT_S,
        ))
        bench.stage.set_velocity_mm_s(cfg.stage.velocity_mm_s)
    from benchlab.drivers.trace import replay

    if replay.active():
        # A cassette is replayed: its camera answers (the recorded frames), as its LED
        # controller and stage do in place of the simulators above. A simulated camera would
        # image a world whose LED the replayed controller never lights (issue 38).
        bench.camera = stack.enter_context(
            MightexCamera.open(serial=cfg.camera.serial, pid=cfg.camera.pid))
        return
    cam_kwargs: dict[str, Any] = {"pid": cfg.camera.pid} if cfg.camera.pid else {}
    bench.sim_camera = SimulatedCamera(
        bench.world, serial=cfg.camera.serial or SIM_CAMERA_SERIAL, seed=seed, noise=noise,
        bench_state=bench.state, **cam_kwargs,
    )
    backend = SimCameraBackend([bench.sim_camera])
    bench.camera = stack.enter_context(
        MightexCamera.open(serial=cfg.camera.serial, backend=backend, pid=cfg.camera.pid)
    )


@contextlib.contextmanager
def _stopped_on(stage: LinearStage, abort: threading.Event | None) -> Iterator[None]:
    """While the body waits for a move or homing, stop ``stage`` at once when ``abort`` is set
    (from any thread: the abort key, a quitting UI); nothing to watch without ``abort``."""
    if abort is None:
        yield
        return
    finished = threading.Event()

    def watch() -> None:
        while not finished.wait(0.02):
            if abort.is_set():
                with contextlib.suppress(DeviceError):
                    stage.stop(immediate=True, wait=False)
                return

    watcher = threading.Thread(target=watch, name="stage-abort-watch", daemon=True)
    watcher.start()
    try:
        yield
    finally:
        finished.set()
        watcher.join()



def _bit_depths(c: TableChecker) -> tuple[int, ...] | None:
    """``camera.bit_depths``: a non-empty list of 8, 10 and 12 (None when absent)."""
    found, value = c.get("camera.bit_depths", None)
    if not found:
        return None
    if (not isinstance(value, list) or not value
            or any(v not in (8, 10, 12) or isinstance(v, bool) for v in value)):
        c.fail("camera.bit_depths", f"must be a list of 8, 10 and 12, got {value!r}")
        return None
    return tuple(int(v) for v in value)
