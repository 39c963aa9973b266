"""Camera commands: ``devices``, ``snap`` and ``benchmark camera``.

``--simulate`` uses a simulated MCE-B013-U behind the same pyusb code path as the real camera
(:class:`benchlab.drivers.mightex.sim.SimCameraBackend`).
"""

from __future__ import annotations

import argparse
import array
import statistics
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from benchlab.cli import UsageError, positive_int
from benchlab.cli.output import print_outcome, session_part
from benchlab.drivers.errors import BenchlabError, DeviceNotFoundError

if TYPE_CHECKING:  # the driver stack (numpy, pyusb) is imported by the commands that use it
    from benchlab.drivers.mightex.sim import SimCameraBackend


def _pid(text: str) -> int:
    try:
        value = int(text, 0)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a USB product id: {text!r} (e.g. 0x0428)") from None
    if not 0 <= value <= 0xFFFF:
        raise argparse.ArgumentTypeError(f"USB product id out of range 0..0xFFFF: {text}")
    return value


def _sim_backend(pid: int | None, scene: Any = None, seed: int | None = None
                 ) -> SimCameraBackend:
    from benchlab.drivers.mightex import protocol as proto
    from benchlab.drivers.mightex.sim import SimCameraBackend, SimulatedCamera
    cam = SimulatedCamera(scene=scene, pid=proto.DEFAULT_PID if pid is None else pid,
                          seed=seed)
    return SimCameraBackend([cam])


# --------------------------------------------------------------------------- devices


def list_devices(simulate: bool, pid: int | None = None) -> tuple[list[dict[str, Any]], list[str]]:
    """Cameras, then serial devices, as dicts (kind, model, serial, firmware, ...) and notes."""
    from benchlab.drivers.mightex.camera import find_cameras
    notes: list[str] = []
    rows: list[dict[str, Any]] = []
    backend = _sim_backend(pid) if simulate else None
    try:
        cams = find_cameras(backend=backend, pid=pid)
        for info in cams:
            row = {"kind": "camera", **info.to_dict()}
            row["port"] = f"usb {info.bus}:{info.address} pid 0x{info.pid:04X}"
            rows.append(row)
    except DeviceNotFoundError as exc:  # no libusb: still list the serial devices
        notes.append(f"cameras: {exc}")
    other_rows, other_notes = cameras_elsewhere(backend, pid)
    rows += other_rows
    notes += other_notes
    try:
        from benchlab.cli.devices.serial import list_serial_devices
    except ImportError:
        notes.append("serial devices: listing not available in this build")
    else:
        rows.extend(list_serial_devices(simulate))
    return rows, notes


def cameras_elsewhere(backend: Any, pid: int | None) -> tuple[list[dict[str, Any]], list[str]]:
    """USB devices of the camera's vendor id (or naming Mightex) with another product id than
    the one searched, as rows, and for each a note with the bench-file and udev lines that
    make it the camera."""
    from benchlab.drivers.mightex import protocol as proto
    from benchlab.drivers.mightex.camera import udev_rule_line, vendor_devices

    wanted = proto.DEFAULT_PID if pid is None else pid
    rows: list[dict[str, Any]] = []
    notes: list[str] = []
    for d in vendor_devices(backend):
        if d.pid == wanted:
            continue
        rows.append({"kind": "camera?", "model": d.product or "?", "serial": d.serial or "?",
                     "firmware": "", "port": f"usb {d.bus}:{d.address} "
                     f"{d.vid:04x}:{d.pid:04x}", **{"usb": d.to_dict()}})
        notes.append(f"{d.describe()} was not searched (PID 0x{wanted:04X}): if it is the "
                     f"camera, put `pid = 0x{d.pid:04X}` under [camera] in the bench file and "
                     f"add the udev rule line: {udev_rule_line(d.vid, d.pid)}")
    return rows, notes


def _cmd_devices(args: argparse.Namespace) -> int:
    rows, notes = list_devices(args.simulate, args.pid)
    status = print_outcome(args.json, lambda: rows, lambda: _devices_table(rows), indent=2,
                           default=str)
    for note in notes:
        print(f"note: {note}", file=sys.stderr)
    return status


def _devices_table(rows: list[dict[str, Any]]) -> str:
    """One line per device, in aligned columns."""
    if not rows:
        return "no devices found"
    header = ("KIND", "MODEL", "SERIAL", "FIRMWARE", "WHERE")
    table = [header] + [
        (str(r.get("kind", "")), str(r.get("model", "")), str(r.get("serial", "")),
         str(r.get("firmware", "")), str(r.get("port", "")) + (
             f"  ({r['error']})" if r.get("error") else ""))
        for r in rows
    ]
    widths = [max(len(row[i]) for row in table) for i in range(len(header))]
    return "\n".join("  ".join(cell.ljust(w) for cell, w in zip(row, widths, strict=True)).rstrip()
                     for row in table)


# --------------------------------------------------------------------------- snap


#: Scenes ``snap --simulate`` can show: the two simple ones, or a target of the simulated bench.
SNAP_SCENES_HELP = (
    "bars (32 px period test target), flat, or a bench target: usaf, edge, led, dark, "
    "radial:LP_PER_MM:sagittal|tangential (e.g. radial:4:sagittal), "
    "card[:RADIUS_MM] (grid-and-text card rolled at RADIUS_MM from the axis, default 19.88); "
    "the USAF chart at a pose: usaf:dx=PX,dy=PX,scale=S,rot=DEG[,vignetting=V][,negative=1] "
    "(any subset)"
)


def simulated_snap_scene(name: str) -> Any:
    """The scene for ``snap --simulate --scene NAME``; a clear error names a bad NAME."""
    from benchlab.drivers.mightex.sim import bar_target_scene, flat_field_scene
    if name == "bars":
        return bar_target_scene()
    if name == "flat":
        return flat_field_scene()
    from benchlab.scenes.world import SimWorld  # the bench scenes are only needed here

    if name.startswith("usaf:"):
        from benchlab.scenes.usaf import usaf_scene_from_spec

        try:
            return SimWorld("usaf", usaf=usaf_scene_from_spec(name))
        except ValueError as exc:
            raise BenchlabError(f"--scene {name}: {exc}") from exc
    try:
        # An LED with no stage sits at 20 mm and no controller: light it as the procedure does.
        world = SimWorld(name, led_position_mm=20.0)
    except ValueError as exc:
        raise BenchlabError(f"--scene {name}: {exc}; choose {SNAP_SCENES_HELP}") from exc
    return lambda state: world(
        type(state)(**{**state.__dict__, "bench": {"led_current_ma": 20.0, **state.bench}})
    )


def snap(out: Path, *, exposure_ms: float, gain: float, bits: int = 8, serial: str | None = None,
         pid: int | None = None, simulate: bool = False, scene: str = "bars",
         seed: int | None = None) -> dict[str, Any]:
    """Grab one frame and save it as lossless TIFF with its metadata; returns the metadata.
    ``seed``: the simulated camera's noise seed (None: a fresh draw every time)."""
    from benchlab import __version__
    from benchlab.drivers.mightex.camera import MightexCamera
    from benchlab.storage import save_frame_tiff
    part = session_part(out)
    if part is not None:
        raise UsageError(f"snap {out}: is part of {part}, which only benchlab's session "
                         "commands write; nothing written (name a file outside it)")
    if out.exists():
        raise BenchlabError(f"{out} already exists; frames are never overwritten")
    backend = _sim_backend(pid, simulated_snap_scene(scene), seed) if simulate else None
    with MightexCamera.open(serial, backend=backend, pid=pid) as cam:
        cam.configure(bits=bits)
        cam.set_exposure_ms(exposure_ms)
        cam.set_gain(gain)
        frame = cam.grab(timeout_s=max(5.0, 3 * exposure_ms / 1e3 + 2.0))
        meta = {
            **frame.meta.to_dict(),
            "camera": {"model": cam.info.model, "serial": cam.info.serial,
                       "firmware": cam.info.firmware, "pid": cam.info.pid},
            "simulated": simulate,
            "software": {"name": "benchlab", "version": __version__},
        }
    try:
        save_frame_tiff(out, frame.pixels, meta)
    except FileExistsError:
        raise BenchlabError(f"{out} already exists; frames are never overwritten") from None
    except OSError as exc:
        raise BenchlabError(f"cannot write {out}: {exc.strerror or exc}") from exc
    return meta


def _cmd_snap(args: argparse.Namespace) -> int:
    meta = snap(Path(args.out), exposure_ms=args.exposure_ms, gain=args.gain, bits=args.bits,
                serial=args.serial, pid=args.pid, simulate=args.simulate, scene=args.scene,
                seed=args.seed)
    cam = meta["camera"]
    print(f"saved {args.out}: {meta['width']}x{meta['height']} {meta['bits']}-bit, exposure "
          f"{meta['exposure_ms']:g} ms, gain {meta['gain']:g}x, {cam['model']} {cam['serial']} "
          f"(firmware {cam['firmware']}){' [simulated]' if args.simulate else ''}")
    return 0


# --------------------------------------------------------------------------- benchmark


def _raw_frame(backend: SimCameraBackend) -> tuple[bytes, int]:
    """One raw frame transfer read by plain pyusb calls (the camera must be configured)."""
    import usb.core

    from benchlab.drivers.mightex import protocol as proto
    dev = usb.core.find(idVendor=proto.VENDOR_ID, idProduct=proto.DEFAULT_PID, backend=backend)
    dev.write(proto.EP_COMMAND_OUT, proto.encode_query_buffer())
    proto.decode_reply(bytes(dev.read(proto.EP_REPLY_IN, 255)), "buffer query", 6)
    dev.write(proto.EP_COMMAND_OUT, proto.encode_get_image(1))
    raw = bytes(dev.read(proto.EP_FRAME_IN, 4 * 1024 * 1024))
    return raw, len(raw)


def benchmark_camera(frames: int = 200, decode_repeats: int = 40) -> list[dict[str, Any]]:
    """Full-frame 8- and 12-bit figures: end-to-end fps, decode vs plain copy (medians)."""
    import numpy as np

    from benchlab.drivers.mightex import protocol as proto
    from benchlab.drivers.mightex.camera import MightexCamera
    from benchlab.drivers.mightex.sim import SimCameraBackend, SimulatedCamera, flat_field_scene
    results = []
    for bits in (8, 12):
        sim = SimulatedCamera(scene=flat_field_scene(), seed=0)
        backend = SimCameraBackend([sim])
        with MightexCamera.open(backend=backend) as cam:
            cam.configure(bits=bits)
            cam.set_exposure_ms(10.0)
            for _ in range(3):
                cam.grab()  # warm-up: noise bank and the scene cache
            t0 = time.perf_counter()
            for _ in range(frames):
                cam.grab()
            fps = frames / (time.perf_counter() - t0)
            raw, received = _raw_frame(backend)
            layout = cam.layout
        source = np.frombuffer(raw, dtype=np.uint8)
        decode_s, copy_s = [], []
        for _ in range(decode_repeats):
            buf = array.array("B", raw)  # fresh writable buffer, as the driver receives it
            t0 = time.perf_counter()
            proto.decode_frame(buf, layout, received)
            decode_s.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            source.copy()
            copy_s.append(time.perf_counter() - t0)
        decode_ms, copy_ms = statistics.median(decode_s) * 1e3, statistics.median(copy_s) * 1e3
        results.append({"bits": bits, "width": layout.width, "height": layout.height,
                        "frames": frames, "fps": fps, "decode_ms": decode_ms,
                        "copy_ms": copy_ms, "decode_over_copy": decode_ms / copy_ms})
    return results


def _cmd_benchmark(args: argparse.Namespace) -> int:
    rows = benchmark_camera(args.frames)
    return print_outcome(args.json, lambda: rows, lambda: _benchmark_text(rows, args.frames),
                         indent=2)


def _benchmark_text(rows: list[dict[str, Any]], frames: int) -> None:
    """The camera benchmark's table (printed)."""
    print(f"camera: simulated MCE-B013-U through pyusb + benchlab driver, "
          f"{rows[0]['width']}x{rows[0]['height']}, {frames} frames per row")
    print(f"{'bits':>4}  {'fps end-to-end':>14}  {'decode ms':>9}  {'copy ms':>7}  "
          f"{'decode/copy':>11}")
    for r in rows:
        print(f"{r['bits']:>4}  {r['fps']:>14.1f}  {r['decode_ms']:>9.3f}  {r['copy_ms']:>7.3f}  "
              f"{r['decode_over_copy']:>11.2f}")
    print("targets: >= 60 fps at 8-bit full frame; decode <= 3x a plain copy of the same bytes")


# --------------------------------------------------------------------------- registry


def register(commands: argparse._SubParsersAction, benchmarks: argparse._SubParsersAction) -> None:
    """Add ``devices``, ``snap`` and ``benchmark camera``."""
    dev = commands.add_parser(
        "devices", help="list cameras and serial bench devices",
        description="List Mightex cameras (model, serial, firmware) and serial bench devices.")
    dev.add_argument("--simulate", action="store_true", help="list the simulated bench")
    dev.add_argument("--json", action="store_true", help="print JSON instead of a table")
    dev.add_argument("--pid", type=_pid, default=None,
                     help="camera USB product id (default 0x0428)")
    dev.set_defaults(func=_cmd_devices)

    snap_p = commands.add_parser(
        "snap", help="save one camera frame as lossless TIFF",
        description="Grab one frame and save it as TIFF with its acquisition metadata "
                    "(frame settings, camera model/serial/firmware, benchlab version).")
    snap_p.add_argument("out", metavar="OUT.tiff", help="output file (never overwritten)")
    snap_p.add_argument("--simulate", action="store_true",
                        help="use the simulated camera (see --scene)")
    snap_p.add_argument("--scene", default="bars",
                        help=f"what the simulated camera sees: {SNAP_SCENES_HELP}")
    snap_p.add_argument("--exposure-ms", type=float, required=True,
                        help="exposure in ms (0.05 ms steps)")
    snap_p.add_argument("--gain", type=float, required=True,
                        help="gain multiplier 0.125..8 (1 = unity)")
    snap_p.add_argument("--bits", type=int, choices=(8, 12), default=8, help="bit depth")
    snap_p.add_argument("--seed", type=int, default=None,
                        help="the simulated camera's noise seed, for a frame that is the same "
                             "every time (default: a fresh noise draw)")
    snap_p.add_argument("--serial", default=None, help="camera serial number (default: first)")
    snap_p.add_argument("--pid", type=_pid, default=None,
                        help="camera USB product id (default 0x0428)")
    snap_p.set_defaults(func=_cmd_snap)

    bench = benchmarks.add_parser(
        "camera", help="camera frame rate and decode speed (simulated camera via pyusb)",
        description="Frames per second end to end and decode time vs a plain copy, 8 and "
                    "12-bit full frames, simulated camera through the real pyusb code path.")
    bench.add_argument("--frames", type=positive_int, default=200,
                       help="frames timed per bit depth")
    bench.add_argument("--json", action="store_true", help="print JSON")
    bench.set_defaults(func=_cmd_benchmark)
