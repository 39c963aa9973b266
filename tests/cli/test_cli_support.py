"""What lab users expect: user config (platformdirs), logging, an I/O trace, serial URLs and
a udev hint that names the installed rule. XDG_CONFIG_HOME is a temp folder (conftest)."""

from __future__ import annotations

import errno
import json
import os
from pathlib import Path

import pytest
import usb.core

from benchlab.bench import BenchConfig
from benchlab.cli.config import bench_file_in_force, sessions_in_force, template, user_bench_file
from benchlab.cli.main import main
from benchlab.drivers.errors import DeviceError, DeviceLostError
from benchlab.drivers.mightex.camera import _usb_errors, udev_rule_path
from benchlab.drivers.slc.controller import SlcController
from benchlab.drivers.slc.sim import SimulatedSlc


def test_config_init_writes_a_commented_valid_bench_file(capsys: pytest.CaptureFixture[str]
                                                         ) -> None:
    path = user_bench_file()
    assert str(path).startswith(os.environ["XDG_CONFIG_HOME"])
    assert main(["config", "init"]) == 0
    assert f"wrote {path}" in capsys.readouterr().out
    text = path.read_text(encoding="utf-8")
    assert text == template() and "hwgrep://" in text and "# " in text
    cfg = BenchConfig.load(path)
    assert cfg.led is not None and cfg.led.ceilings_ma == {1: 50.0}
    assert cfg.stage is not None and cfg.stage.counts_per_mm == 34554.96
    assert cfg.sessions_dir == Path("~/benchlab-sessions").expanduser()
    # never replaced unless asked
    path.write_text(text + "\n# my edit\n", encoding="utf-8")
    assert main(["config", "init"]) == 2  # a usage error naming the file (issue 38)
    assert f"config init {path}: already exists" in capsys.readouterr().err
    assert path.read_text(encoding="utf-8").endswith("# my edit\n")
    assert main(["config", "init", "--force"]) == 0
    assert path.read_text(encoding="utf-8") == template()


def test_what_is_in_force_and_where_from(tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    assert bench_file_in_force(None, simulate=False).value is None
    assert sessions_in_force(None).value == Path("sessions")
    user = user_bench_file()
    user.parent.mkdir(parents=True)
    user.write_text('[paths]\nsessions = "/data/bench-sessions"\n[led]\nport = "hwgrep://FT1"\n',
                    encoding="utf-8")
    chosen = bench_file_in_force(None, simulate=False)
    assert chosen.value == user and "user config" in chosen.source
    assert bench_file_in_force(tmp_path / "b.toml", simulate=False).source == "--config"
    assert bench_file_in_force(None, simulate=True).value is None  # the packaged simulated bench
    sessions = sessions_in_force(None)
    assert sessions.value == Path("/data/bench-sessions") and "[paths] sessions" in sessions.source
    assert sessions_in_force(tmp_path, "--out").value == tmp_path
    assert main(["config", "show"]) == 0
    out = capsys.readouterr().out
    assert str(user) in out and "/data/bench-sessions" in out and "hwgrep://FT1" in out
    assert str(udev_rule_path()) in out


def test_real_bench_without_any_bench_file_says_how_to_make_one(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["run", "mtf", "--yes"]) == 1
    assert "benchlab config init" in capsys.readouterr().err


def test_log_level_and_io_trace(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    trace = tmp_path / "io.jsonl"
    argv = ["--log-level", "info", "--trace-io", str(trace), "led", "--simulate", "--channel",
            "1", "--current-ma", "5", "--on", "--for-s", "0"]
    assert main(argv) == 0
    err = capsys.readouterr().err
    assert "benchlab.drivers.slc.controller: INFO: LED controller SLC-SA04-U/S" in err
    lines = trace.read_text(encoding="ascii").splitlines()
    assert json.loads(lines[0])["cassette"] == 1  # a cassette (docs/hardware/replay.md)
    events = [json.loads(ln) for ln in lines[1:]]
    sent = [e for e in events if e.get("dev") == "led" and e.get("dir") == ">"]
    got = [e for e in events if e.get("dev") == "led" and e.get("dir") == "<"]
    assert any(e["text"].startswith("NORMAL 1 ") for e in sent)
    assert any(e["text"].startswith("MODE 1 1") for e in sent)
    assert any(e["hex"].startswith("4d 4f 44 45 20 31 20 31") for e in sent)  # the bytes
    assert any(e["text"] == "## .." for e in got)  # "## \r\n" read back as one line
    assert main(["led", "--simulate", "--channel", "1", "--off"]) == 0  # trace stopped
    assert len(trace.read_text(encoding="ascii").splitlines()) == len(lines)


def test_camera_exchanges_are_traced(tmp_path: Path) -> None:
    trace = tmp_path / "cam.jsonl"
    out = tmp_path / "f.tiff"
    assert main(["--trace-io", str(trace), "snap", "--simulate", "--exposure-ms", "5", "--gain",
                 "1", str(out)]) == 0
    events = [json.loads(ln) for ln in trace.read_text(encoding="ascii").splitlines()[1:]]
    assert {(e.get("dev"), e.get("dir")) for e in events} >= {("camera", ">"), ("camera", "<")}
    assert any(e.get("ep") == 0x82 and "b64" in e for e in events)  # the frame, whole


def test_serial_ports_accept_pyserial_urls(tmp_path: Path) -> None:
    spy = tmp_path / "spy.txt"
    with SimulatedSlc() as sim, SlcController(f"spy://{sim.port}?file={spy}",
                                              ceilings_ma={1: 10.0}) as led:
        led.on(1, 5.0)
        assert sim.channel_output_ma(1) == 5.0
    assert "MODE 1 1" in spy.read_text(encoding="ascii", errors="replace")
    with pytest.raises(DeviceLostError, match="cannot open hwgrep://NO-SUCH-PORT-XYZ"):
        SlcController("hwgrep://NO-SUCH-PORT-XYZ", ceilings_ma={}).open()


def test_permission_error_names_the_installed_rule_and_commands() -> None:
    rule = udev_rule_path()
    assert rule.is_file() and rule.name == "99-benchlab-mightex.rules"
    with pytest.raises(DeviceError) as info, _usb_errors("open"):
        raise usb.core.USBError("Access denied", errno=errno.EACCES)
    text = str(info.value)
    assert f"sudo install -m 644 {rule} /etc/udev/rules.d/" in text
    assert "sudo udevadm control --reload-rules && sudo udevadm trigger" in text


@pytest.mark.slow
def test_benchmark_startup_times_both_commands(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    from benchlab.session import Session

    session = Session.create(tmp_path, procedure="mtf", params={}, operator="t", devices={},
                             software_version="0", name="s")
    # A session without frames re-analyses quickly (empty tables): this checks the command.
    assert main(["benchmark", "startup", str(session.path), "--repeats", "1"]) == 0
    out = capsys.readouterr().out
    assert "--help" in out and "analyze SESSION" in out and "cached" in out and "no .pyc" in out
    assert session.result_versions() == []  # each run analysed its own copy
    assert main(["benchmark", "startup", str(tmp_path / "nope")]) == 1


def test_help_imports_no_heavy_library() -> None:
    """`benchlab --help` builds every command's parser: none may import numpy and friends at
    module level (start-up time); they are imported by the commands that use them."""
    import subprocess
    import sys

    code = ("import sys; from benchlab.cli.main import build_parser; build_parser(); "
            "print(sorted({m.split('.')[0] for m in sys.modules} & {'numpy', 'cv2', 'tifffile', "
            "'scipy', 'skimage', 'serial', 'usb', 'textual', 'matplotlib', 'platformdirs'}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=60).stdout.strip()
    assert out == "[]"


def test_reanalysis_path_imports_no_scipy() -> None:
    """`benchlab analyze SESSION` needs numpy only, not scipy.ndimage/stats/interpolate/
    optimize/signal, scikit-image, matplotlib or textual (each costs more to import than a
    re-analysis takes); tests/test_analyze_startup.py runs it and checks OpenCV and tifffile
    too."""
    import subprocess
    import sys

    code = ("import sys; import benchlab.cli.frames.analysis, benchlab.cli.runs.procedures, "
            "benchlab.protocols.runs, benchlab.protocols.mtf.analysis, benchlab.report.tables; "
            "from benchlab.protocols.mtf.curves import load_curves; load_curves(None); "
            "heavy = {'scipy.ndimage', 'scipy.stats', 'scipy.interpolate', "
            "'scipy.optimize', 'scipy.signal', 'skimage', 'matplotlib', 'textual'}; "
            "print(sorted(m for m in sys.modules if m in heavy))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=60).stdout.strip()
    assert out == "[]"


def test_config_init_makes_the_user_folder_but_not_a_mistyped_one(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "not" / "yet" / "config"))
    assert main(["config", "init"]) == 0
    assert (tmp_path / "not/yet/config/benchlab/bench.toml").read_text(encoding="utf-8") \
        == template()
    wrong = tmp_path / "typo" / "bench.toml"
    assert main(["config", "init", "--path", str(wrong)]) == 1
    assert f"folder {wrong.parent} does not exist" in capsys.readouterr().err
    assert not wrong.parent.exists()
