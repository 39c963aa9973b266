"""``benchlab config init|show``: the user's bench file and what is in force, and from where.

The user configuration lives in the platform's config folder (platformdirs: on Linux
``$XDG_CONFIG_HOME/benchlab``, default ``~/.config/benchlab``). Its ``bench.toml`` is the bench
configuration used when a command gets no ``--config`` on the real bench, and its
``[paths] sessions`` sets where new sessions go when no ``--out`` / ``--sessions`` is given.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

from benchlab.cli.output import add_output_option
from benchlab.drivers.apt.protocol import Z8_COUNTS_PER_MM
from benchlab.drivers.errors import BenchlabError

APP_NAME = "benchlab"
BENCH_FILE = "bench.toml"
#: Where sessions go when neither an option nor the bench file says (relative to the cwd).
DEFAULT_SESSIONS = Path("sessions")


def user_config_dir() -> Path:
    """The platform's per-user configuration folder for benchlab."""
    import platformdirs

    return platformdirs.user_config_path(APP_NAME, appauthor=False)


def user_bench_file() -> Path:
    return user_config_dir() / BENCH_FILE


def template() -> str:
    """The commented bench.toml that ``config init`` writes (it validates as it stands)."""
    return f"""\
# benchlab bench configuration, written by `benchlab config init`.
# Used when a command is given no --config on the real bench; `benchlab config show` says
# which file and settings are in force. Every section is optional.
#
# Serial ports: a device path (/dev/ttyUSB0, COM3) or any pyserial URL, e.g.
#   port = "hwgrep://FT4ABCDE"   the port whose USB serial number or VID:PID matches: stays
#                                the same device when /dev/ttyUSB numbers change at boot
#   port = "spy:///dev/ttyUSB0?file=/tmp/led-traffic.txt"   the real port, every byte dumped

[paths]
# Where new sessions are written (default: ./sessions in the current folder).
sessions = "~/benchlab-sessions"

[camera]
# serial = "13-000123"    # which camera, when more than one is connected
# pid = 0x0428            # USB product id, if `lsusb` shows 04b4:xxxx with another id
# model = "MCE-B013-U"    # protocol profile; `benchlab doctor` finds the one that fits

[led]
port = "/dev/ttyUSB0"     # Mightex SLC LED controller (RS232, 9600 8N1)
channel = 1               # the channel the radiometry LED is on

[led.ceiling_ma]
# Highest current each channel may ever be driven at, in mA; checked before anything is sent.
# A channel without a ceiling is never lit.
1 = 50.0

[stage]
port = "/dev/ttyUSB1"     # Thorlabs KDC101 / TDC001 cube (APT, 115200 8N1)
travel_mm = [0.0, 25.0]   # Z825 actuator; [0.0, 50.0] for an MTS50-Z8 stage
actuator = "Z8"           # {Z8_COUNTS_PER_MM} counts/mm; "Z8-34304" for the other published
                          # Z8 scale (`benchlab doctor` measures which), or counts_per_mm = ...
velocity_mm_s = 2.0
"""


@dataclass(frozen=True)
class Setting:
    """One value in force (``None``: not set) and where it came from."""

    value: Path | None
    source: str


@dataclass(frozen=True)
class FolderSetting:
    """A folder in force and where it came from."""

    value: Path
    source: str


def bench_file_in_force(config: str | Path | None, *, simulate: bool) -> Setting:
    """The bench file a command uses: ``--config``, else the user's bench.toml on the real
    bench, else none (the packaged simulated bench with ``--simulate``)."""
    if config:
        return Setting(Path(config), "--config")
    user = user_bench_file()
    if simulate:
        return Setting(None, "the packaged simulated bench (--simulate)")
    if user.is_file():
        return Setting(user, "user config (benchlab config init)")
    return Setting(None, f"none: no --config and no {user}")


def sessions_in_force(option: str | Path | None, option_name: str = "--out") -> FolderSetting:
    """Where new sessions go: the option, else ``[paths] sessions`` of the user's bench.toml,
    else ``./sessions``."""
    if option:
        return FolderSetting(Path(option), option_name)
    user = user_bench_file()
    if user.is_file():
        from benchlab.bench import BenchConfig

        cfg = BenchConfig.load(user)
        if cfg.sessions_dir is not None:
            return FolderSetting(cfg.sessions_dir, f"{user} [paths] sessions")
    return FolderSetting(DEFAULT_SESSIONS, "default (./sessions)")


#: ``--root`` of the commands that read the sessions folder (list, units, lot, ...).
SESSIONS_ROOT_HELP = ("sessions folder (default: where `run` puts new sessions - [paths] "
                      "sessions of the user's bench.toml, else ./sessions)")


def sessions_root(option: str | Path | None) -> Path:
    """The sessions folder a reading command uses: ``--root``, else the folder ``run`` writes
    new sessions to (:func:`sessions_in_force`); an error naming it when it does not exist."""
    setting = sessions_in_force(option, "--root")
    if not setting.value.is_dir():
        raise BenchlabError(f"{setting.value}: no such sessions folder (from {setting.source})")
    return setting.value


def _cmd_init(args: argparse.Namespace) -> int:
    from benchlab.cli.output import check_output, write_output

    path = Path(args.path) if args.path else user_bench_file()
    option = "--path" if args.path else "config init"
    check_output(path, force=args.force, option=option)
    if not args.path:  # the user config folder is ours to create; a --path folder is not
        path.parent.mkdir(parents=True, exist_ok=True)
    elif not path.parent.is_dir():
        raise BenchlabError(f"{path}: folder {path.parent} does not exist")
    write_output(path, template(), force=args.force, option=option)
    print(f"wrote {path}")
    print("edit the ports and ceilings, then check with: benchlab config show")
    return 0


def _cmd_show(args: argparse.Namespace) -> int:
    from benchlab.bench import BenchConfig
    from benchlab.drivers.mightex.camera import udev_rule_path

    bench = bench_file_in_force(args.config, simulate=args.simulate)
    sessions = sessions_in_force(None)
    rows = [
        ("config folder", str(user_config_dir()), "platformdirs"),
        ("bench file", str(bench.value) if bench.value else "-", bench.source),
        ("sessions folder", str(sessions.value), sessions.source),
        ("udev rule", str(udev_rule_path()), "installed with benchlab"),
    ]
    cfg = BenchConfig.load(bench.value, simulate=args.simulate)
    cam = cfg.camera
    rows.append(("camera", f"serial {cam.serial or 'any'}"
                 + (f", pid 0x{cam.pid:04X}" if cam.pid else ""), cfg.source))
    if cfg.led is not None:
        ceilings = ", ".join(f"ch {k} <= {v:g} mA" for k, v in sorted(cfg.led.ceilings_ma.items()))
        rows.append(("LED controller", f"{cfg.led.port or '(simulated)'}, channel "
                     f"{cfg.led.channel}; {ceilings}", cfg.source))
    else:
        rows.append(("LED controller", "none", cfg.source))
    if cfg.stage is not None:
        lo, hi = cfg.stage.travel_mm
        rows.append(("stage", f"{cfg.stage.port or '(simulated)'}, travel {lo:g} .. {hi:g} mm, "
                     f"{cfg.stage.counts_per_mm:g} counts/mm, {cfg.stage.velocity_mm_s:g} mm/s",
                     cfg.source))
    else:
        rows.append(("stage", "none", cfg.source))
    width = max(len(r[0]) for r in rows)
    for name, value, source in rows:
        print(f"{name:<{width}}  {value}\n{'':<{width}}    from {source}")
    return 0


def register(commands: argparse._SubParsersAction, benchmarks: argparse._SubParsersAction) -> None:
    """Add ``config init`` and ``config show``."""
    p = commands.add_parser(
        "config", help="the user's bench configuration: write a commented one, show what is in "
        "force",
        description=f"The user configuration folder ({user_config_dir_text()}) holds bench.toml: "
        "the bench used when no --config is given on the real bench, and the default sessions "
        "folder.",
    )
    sub = p.add_subparsers(dest="config_command", metavar="ACTION", required=True)
    init = sub.add_parser("init", help="write a commented bench.toml to the user config folder",
                          description="Write a commented bench.toml (ports, ceilings, travel, "
                          "sessions folder) to the user config folder; never replaces an "
                          "existing file unless --force.")
    add_output_option(init, "--path", help="write here instead of the user config folder")
    init.set_defaults(func=_cmd_init)
    show = sub.add_parser("show", help="print the configuration in force and where it came from",
                          description="Print the bench file, sessions folder, devices, limits "
                          "and udev rule in force, each with where it came from.")
    show.add_argument("--config", help="show this bench file instead of the user's")
    show.add_argument("--simulate", action="store_true",
                      help="show what --simulate commands use")
    show.set_defaults(func=_cmd_show)


def user_config_dir_text() -> str:
    """The config folder for help texts (without importing platformdirs at start-up)."""
    return "platformdirs user config: ~/.config/benchlab on Linux"
