"""A replay that tells the truth (issue 38): a damaged cassette is a one-line error naming the
file; a replayed run reproduces the recorded one (same frames, same results) or stops with
"replay diverged at exchange N"; after a run stops, one line says whether the bench was made
safe, from the devices' read-back - never two that contradict each other.
"""

from __future__ import annotations

import gzip
import json
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from sim_runs import RAD_SMALL

from benchlab.cli.main import main
from benchlab.drivers.slc.sim import SimulatedSlc
from benchlab.session import Session
from benchlab.storage import load_frame_tiff

pytestmark = pytest.mark.timeout(120)

RUN = ["run", "radiometry", "--simulate", "--yes"]


# ---- damaged cassettes -----------------------------------------------------------------------
def _good_lines() -> list[str]:
    return ['{"cassette": 1}',
            '{"n": 1, "t": 0.0, "dev": "led", "open": {"port": "/dev/pts/9", "baud": 9600}}']


def _truncated_gzip(path: Path) -> Path:
    data = gzip.compress(("\n".join(_good_lines() * 200) + "\n").encode("ascii"))
    path.write_bytes(data[: len(data) // 2])
    return path


@pytest.mark.parametrize("make, says", [
    (_truncated_gzip, "damaged cassette: the compressed data ends early (truncated file)"),
    (lambda p: p.write_text("\n".join([*_good_lines(), '{"n": 2, "dev": '])) and p,
     "line 3 is not JSON"),
    (lambda p: p.write_text("\n".join([*_good_lines(), "[1, 2]"])) and p,
     "line 3 is not a JSON object"),
    (lambda p: p.write_bytes(b'{"cassette": 1}\n\xff\xfe\n') and p,
     "damaged cassette: byte 0xff at offset 16 is not text"),
    (lambda p: p.write_bytes(b"not gzip at all") and p, "cannot read the cassette: Not a gzipped"),
], ids=["truncated-gzip", "cut-json-line", "json-array", "binary", "not-gzip"])
def test_a_damaged_cassette_is_one_line_naming_the_file(
        tmp_path: Path, make: object, says: str, capsys: pytest.CaptureFixture[str]) -> None:
    suffix = ".jsonl.gz" if "gzip" in says or "compressed" in says else ".jsonl"
    path = tmp_path / f"case{suffix}"
    make(path)  # type: ignore[operator]
    assert main(["--replay", str(path), "led", "--simulate", "--off"]) == 1
    err = capsys.readouterr().err
    assert err == f"benchlab: error: {path}: " + err.split(f"{path}: ", 1)[1]
    assert err.count("\n") == 1 and says in err, err


# ---- a replayed run --------------------------------------------------------------------------
@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Path, Path]]:
    """A simulated radiometry run recorded into a cassette: (cassette, its session)."""
    root = tmp_path_factory.mktemp("recorded")
    cassette = root / "rad.jsonl.gz"
    assert main(["--trace-io", str(cassette), *RUN, "--params", str(RAD_SMALL),
                 "--out", str(root / "s")]) == 0
    (session,) = [p for p in (root / "s").iterdir() if (p / "session.json").is_file()]
    yield cassette, session


def _only_session(root: Path) -> Path:
    (path,) = [p for p in root.iterdir() if (p / "session.json").is_file()]
    return path


def test_a_replayed_simulated_run_reproduces_frames_and_results(
        tmp_path: Path, recorded: tuple[Path, Path]) -> None:
    """Before: the camera was simulated afresh while the LED answered from the cassette, so
    the camera never saw the LED lit ("no LED found" at the first position)."""
    cassette, first = recorded
    assert main(["--replay", str(cassette), *RUN, "--params", str(RAD_SMALL),
                 "--out", str(tmp_path)]) == 0
    again = _only_session(tmp_path)
    frames = sorted(p.name for p in (first / "frames").glob("*.tiff"))
    assert len(frames) == 6
    for name in frames:
        a, _ = load_frame_tiff(first / "frames" / name)
        b, _ = load_frame_tiff(again / "frames" / name)
        assert np.array_equal(a, b), name
    table = "results/v1/relative_radiometry.json"
    assert (json.loads((first / table).read_text())
            == json.loads((again / table).read_text()))


def test_a_diverging_replay_says_where_not_a_measurement_failure(
        tmp_path: Path, recorded: tuple[Path, Path], capsys: pytest.CaptureFixture[str]) -> None:
    cassette, _ = recorded
    params = tmp_path / "rad25.toml"  # another LED current: the SLC command differs
    params.write_text(RAD_SMALL.read_text().replace("current_ma = 20.0", "current_ma = 25.0"))
    assert main(["--replay", str(cassette), *RUN, "--params", str(params),
                 "--out", str(tmp_path / "s")]) == 1
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if not ln.startswith(("[", "  ", "session: "))]
    assert lines[0].startswith("benchlab: error: replay diverged at exchange ")
    assert "sent 4e 4f 52 4d 41 4c 20 31 20 35 30 20 32 35" in lines[0]  # NORMAL 1 50 25
    assert "recorded 4e 4f 52 4d 41 4c 20 31 20 35 30 20 32 30" in lines[0]  # ... 20
    assert lines[0].endswith("(step position-15)")
    assert lines[1].startswith("safe state not confirmed: the replayed devices stop answering")
    assert len(lines) == 2
    assert "no LED found" not in err and "bench left safe" not in err


# ---- the one safety line ---------------------------------------------------------------------
def test_one_safety_line_when_the_led_controller_is_lost(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The LED controller's link drops while it is lit: the step fails, the safe state cannot
    be confirmed, and the last line says so - never also "bench left safe"."""
    led = SimulatedSlc()
    led.start()
    try:
        bench = tmp_path / "bench.toml"
        bench.write_text(f'[camera]\nserial = ""\n[led]\nport = "{led.port}"\nchannel = 1\n'
                         '[led.ceiling_ma]\n1 = 50.0\n[stage]\ntravel_mm = [0.0, 50.0]\n',
                         encoding="utf-8")
        silenced = threading.Event()

        def silence_when_lit() -> None:
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline and led.channel_output_ma(1) == 0.0:
                time.sleep(0.005)
            led.faults.drop_on_command = "MODE"  # the next switching: the link drops
            silenced.set()

        watcher = threading.Thread(target=silence_when_lit, daemon=True)
        watcher.start()
        status = main([*RUN, "--config", str(bench), "--params", str(RAD_SMALL),
                       "--out", str(tmp_path / "s")])
        watcher.join(5)
        assert silenced.is_set() and status == 1
    finally:
        led.stop()
    err = capsys.readouterr().err
    assert "bench left safe" not in err
    last = err.splitlines()[-1]
    assert last.startswith("bench NOT confirmed safe (LED")
    assert "continue with: benchlab resume" in last
    assert err.count("safe state") + err.count("confirmed safe") == 1
    assert Session.open(_only_session(tmp_path / "s")).status == "failed"
