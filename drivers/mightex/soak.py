"""Fault soak of the camera driver against its firmware-level simulator.

:func:`run_soak` grabs ``n_frames`` frames through :class:`~benchlab.drivers.mightex.camera.
MightexCamera` on a :class:`~benchlab.drivers.mightex.sim.SimulatedCamera` while injecting USB
faults at ``fault_rate`` per grab, one kind at a time, drawn uniformly from:

``timeout``      a query reply never arrives (the host's read times out);
``garbage``      a query reply with a wrong length byte;
``short``        a frame transfer ends 4 kB early;
``unplug``       the camera leaves the bus in the middle of a frame transfer (it comes back,
                 freshly powered on, after ``downtime_attempts`` failed reconnects);
``stale``        the next settings change leaves 3 frames with the old settings in the buffer
                 (the soak changes exposure at once when it injects this).

The recovery policy is the one a procedure uses: a timeout or protocol error retries the grab,
a lost device is reopened (:meth:`MightexCamera.reopen`, which restores every setting) until
it is back. Exposure also alternates every ``settings_every`` frames, so stale frames happen.

The verdict comes from the simulator's own records (:class:`~benchlab.drivers.mightex.sim.
SentFrame`: its frame counter, the SHA-256 of each frame's pixels as rendered and how each
transfer ended), never from the driver under test:

Frames are matched by what the host can see - the power-on generation (the reconnects it
made), the trailer's timestamp and exposure - and then compared by pixel hash:

* **lost** - a frame the simulator sent intact, with the settings the host wanted at the
  time, that the driver never handed over;
* **duplicated** - a simulator frame handed over twice;
* **corrupted** - a frame handed over whose pixels differ from what the simulator rendered
  for it, or that matches no intact transfer;
* **out of order** - frames handed over not in the simulator's counter order.
"""

from __future__ import annotations

import bisect
import hashlib
import random
import statistics
import time
from collections import Counter, defaultdict
from dataclasses import dataclass, field

from benchlab.drivers.errors import (
    DeviceLostError,
    DeviceNotFoundError,
    DeviceTimeoutError,
    ProtocolError,
)
from benchlab.drivers.mightex import protocol as p
from benchlab.drivers.mightex.camera import MightexCamera
from benchlab.drivers.mightex.sim import (
    SentFrame,
    SimCameraBackend,
    SimulatedCamera,
    flat_field_scene,
)
from benchlab.drivers.sensor import rate_for_dn8

FAULT_KINDS = ("timeout", "garbage", "short", "unplug", "stale")
#: Exposures the soak alternates between (ms), so stale frames have other settings.
EXPOSURES_MS = (1.0, 1.5)


@dataclass
class SoakReport:
    """Figures of one soak run (see the module docstring for the definitions)."""

    n_frames: int
    fault_rate: float
    seed: int
    width: int
    height: int
    delivered: int = 0
    lost: int = 0
    duplicated: int = 0
    corrupted: int = 0
    out_of_order: int = 0
    injected: Counter[str] = field(default_factory=Counter)
    errors: Counter[str] = field(default_factory=Counter)
    #: Seconds from a fault's error to the next frame handed over, per fault kind.
    recovery_s: dict[str, list[float]] = field(default_factory=lambda: defaultdict(list))
    sim_frames: Counter[str] = field(default_factory=Counter)
    stale_discarded: int = 0
    reconnects: int = 0
    wall_s: float = 0.0

    @property
    def ok(self) -> bool:
        return (self.delivered == self.n_frames and self.lost == 0 and self.duplicated == 0
                and self.corrupted == 0 and self.out_of_order == 0)

    def recovery_all_s(self) -> list[float]:
        return [t for times in self.recovery_s.values() for t in times]

    def format(self) -> str:
        """The report as a plain-text table."""
        lines = [
            f"camera soak: {self.n_frames} frames of {self.width}x{self.height} 8-bit, "
            f"fault rate {self.fault_rate:.1%} per grab ({', '.join(FAULT_KINDS)}), "
            f"seed {self.seed}, {self.wall_s:.1f} s",
            f"delivered {self.delivered}   lost {self.lost}   duplicated {self.duplicated}   "
            f"corrupted {self.corrupted}   out of order {self.out_of_order}   "
            f"-> {'PASS' if self.ok else 'FAIL'}",
            "simulator transfers: " + ", ".join(f"{k} {v}" for k, v in
                                                sorted(self.sim_frames.items()))
            + f"; stale frames discarded {self.stale_discarded}; reconnects {self.reconnects}",
            "",
            f"{'fault':10s} {'injected':>8s} {'errors':>7s} {'recovery median ms':>19s} "
            f"{'max ms':>8s}",
        ]
        for kind in FAULT_KINDS:
            times = self.recovery_s.get(kind, [])
            med = f"{statistics.median(times) * 1e3:.3f}" if times else "-"
            top = f"{max(times) * 1e3:.3f}" if times else "-"
            lines.append(f"{kind:10s} {self.injected[kind]:8d} {self.errors[kind]:7d} "
                         f"{med:>19s} {top:>8s}")
        if self.errors["none"]:
            lines.append(f"errors without an injected fault: {self.errors['none']}")
        every = self.recovery_all_s()
        if every:
            lines.append(f"{'all':10s} {sum(self.injected.values()):8d} "
                         f"{sum(self.errors.values()):7d} "
                         f"{statistics.median(every) * 1e3:19.3f} {max(every) * 1e3:8.3f}")
        return "\n".join(lines)


def run_soak(
    n_frames: int = 10_000, *, fault_rate: float = 0.05, seed: int = 0, width: int = 160,
    height: int = 120, settings_every: int = 50, downtime_attempts: int = 2,
) -> SoakReport:
    """Grab ``n_frames`` frames with faults injected; see the module docstring."""
    if n_frames < 1 or not 0.0 <= fault_rate <= 1.0:
        raise ValueError("n_frames must be >= 1 and fault_rate in [0, 1]")
    rng = random.Random(seed)
    report = SoakReport(n_frames, fault_rate, seed, width, height)
    sim = SimulatedCamera(flat_field_scene(rate_for_dn8(100, EXPOSURES_MS[0])), seed=seed,
                          noise=True)
    sim.sent_frames = []
    backend = SimCameraBackend([sim])
    wanted: list[tuple[int, int]] = []  # (first simulator record index, exposure counts)
    #: (generation, timestamp ms, exposure counts, gain raw, pixel hash) of each frame handed over
    delivered: list[tuple[int, int, int, int, str]] = []
    t_start = time.perf_counter()
    cam = MightexCamera.open(backend=backend)
    try:
        cam.configure(width=width, height=height, bits=8, buffer_count=4)
        gain_raw = p.gain_raw(1.0, cam.spec)
        cam.set_gain(1.0)
        epoch = 0

        def set_exposure(k: int) -> None:
            cam.set_exposure_ms(EXPOSURES_MS[k % 2])
            counts = p.exposure_counts(cam.exposure_ms, cam.spec)
            wanted.append((len(sim.sent_frames or []), counts))

        set_exposure(epoch)
        pending: tuple[str, float] | None = None  # (fault kind, time of its error)
        while len(delivered) < n_frames:
            if len(delivered) and len(delivered) % settings_every == 0 and \
                    wanted[-1][0] != len(sim.sent_frames or []):
                epoch += 1
                set_exposure(epoch)
            kind = None
            if pending is None and rng.random() < fault_rate:
                kind = rng.choice(FAULT_KINDS)
                report.injected[kind] += 1
                _inject(sim, kind)
                if kind == "stale":
                    epoch += 1
                    set_exposure(epoch)  # the change that leaves old frames in the buffer
            # Stale frames are read and dropped, or cleared unread when newer ones wait.
            discarded_before = cam.discarded_frames + cam.skipped_frames
            try:
                # Not fresh: a fresh grab reads and drops the frame under way, which the
                # judge (simulator records only) would count as lost.
                frame = cam.grab(timeout_s=5.0, fresh=False)
            except (DeviceTimeoutError, ProtocolError, DeviceLostError) as exc:
                # Attribute the error to the fault just injected, or the one being recovered
                # from; "none" would be an error nobody injected (printed when it happens).
                cause = kind or (pending[0] if pending is not None else "none")
                report.errors[cause] += 1
                if pending is None:
                    pending = (cause, time.perf_counter())
                if isinstance(exc, DeviceLostError):
                    _reconnect(cam, sim, downtime_attempts)
                    report.reconnects += 1
                continue
            finally:
                report.stale_discarded += (cam.discarded_frames + cam.skipped_frames
                                           - discarded_before)
            pixels = frame.pixels
            delivered.append((report.reconnects, int(frame.meta.timestamp_ms),
                              frame.meta.exposure_counts, frame.meta.gain_raw,
                              hashlib.sha256(pixels.tobytes()).hexdigest()))
            if pending is not None:
                report.recovery_s[pending[0]].append(time.perf_counter() - pending[1])
                pending = None
    finally:
        cam.close()
    report.wall_s = time.perf_counter() - t_start
    _judge(report, sim.sent_frames or [], wanted, delivered, gain_raw)
    return report


def _inject(sim: SimulatedCamera, kind: str) -> None:
    f = sim.faults
    if kind == "timeout":
        f.drop_replies = 1
    elif kind == "garbage":
        f.garbage_replies = 1
    elif kind == "short":
        f.short_frames = 1
    elif kind == "unplug":
        f.unplug_mid_frame = True
    elif kind == "stale":
        f.stale_frames = 3
    else:  # pragma: no cover - FAULT_KINDS is closed
        raise ValueError(kind)


def _reconnect(cam: MightexCamera, sim: SimulatedCamera, downtime_attempts: int) -> None:
    """Reopen until the camera is back; it is replugged after ``downtime_attempts`` misses
    (the person or the hub bringing it back)."""
    misses = 0
    while True:
        try:
            cam.reopen()
            return
        except (DeviceNotFoundError, DeviceLostError, DeviceTimeoutError, ProtocolError):
            misses += 1
            if misses >= downtime_attempts and not sim.connected:
                sim.replug()
            if misses > downtime_attempts + 20:
                raise


def _judge(report: SoakReport, sent: list[SentFrame], wanted: list[tuple[int, int]],
           delivered: list[tuple[int, int, int, int, str]], gain_raw: int) -> None:
    report.delivered = len(delivered)
    report.sim_frames = Counter(r.outcome for r in sent)
    by_key: dict[tuple[int, int, int, int], list[SentFrame]] = defaultdict(list)
    for r in sent:
        if r.outcome == "intact":
            by_key[(r.generation, r.timestamp_ms, r.exposure_counts, r.gain_raw)].append(r)
    seen: Counter[int] = Counter()
    last_seq = -1
    for generation, timestamp_ms, exposure_counts, gain, pixels_sha in delivered:
        candidates = by_key.get((generation, timestamp_ms, exposure_counts, gain), [])
        rec = next((r for r in candidates if r.pixels_sha256 == pixels_sha), None)
        if rec is None:
            report.corrupted += 1
            continue
        seen[rec.seq] += 1
        if rec.seq <= last_seq:
            report.out_of_order += 1
        last_seq = max(last_seq, rec.seq)
    report.duplicated = sum(n - 1 for n in seen.values() if n > 1)
    # Which exposure the host wanted when each transfer began (records are in order).
    starts = [w[0] for w in wanted]
    for i, r in enumerate(sent):
        if r.outcome != "intact" or r.seq in seen:
            continue
        epoch = max(bisect.bisect_right(starts, i) - 1, 0)
        if (r.exposure_counts, r.gain_raw) == (wanted[epoch][1], gain_raw):
            report.lost += 1
