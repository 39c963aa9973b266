"""`benchlab snap --simulate --scene`: every bench target through the real camera path."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from benchlab.analysis import estimate_modulation
from benchlab.cli.main import main
from benchlab.storage import load_frame_tiff


def _snap(tmp_path: Path, scene: str, exposure_ms: float = 300.0) -> np.ndarray:
    out = tmp_path / f"{scene.replace(':', '_')}.tiff"
    assert main(["snap", "--simulate", "--scene", scene, "--exposure-ms", str(exposure_ms),
                 "--gain", "1", str(out)]) == 0
    pixels, meta = load_frame_tiff(out)
    assert meta["simulated"] is True and meta["exposure_ms"] == exposure_ms
    return pixels


def test_default_bars_read_back_with_known_period(tmp_path: Path) -> None:
    pixels = _snap(tmp_path, "bars")
    r = estimate_modulation(pixels[400:500, 500:660], estimator="sinefit")
    assert r.resolved and r.diagnostics.px_per_period == pytest.approx(32.0, rel=0.01)


def test_bench_targets_differ_as_their_scenes_say(tmp_path: Path) -> None:
    dark = _snap(tmp_path, "dark")
    led = _snap(tmp_path, "led", exposure_ms=375.0)
    radial = _snap(tmp_path, "radial:0.5:sagittal")
    assert dark.max() <= 10  # read noise only
    assert led.max() > 60 and (led > 30).sum() < 5000  # a small lit spot
    roi = radial[249:290, 999:1050]
    r = estimate_modulation(roi, estimator="histogram")
    assert r.resolved and r.modulation == pytest.approx(0.81, abs=0.05)


def test_unknown_scene_is_refused_by_name(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "x.tiff"
    assert main(["snap", "--simulate", "--scene", "nope", "--exposure-ms", "300", "--gain", "1",
                 str(out)]) == 1
    assert "--scene nope" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.slow
def test_snap_seed_gives_the_same_simulated_frame_every_time(tmp_path: Path) -> None:
    import tifffile

    def frame(name: str, *seed: str) -> np.ndarray:
        out = tmp_path / name
        assert main(["snap", "--simulate", "--exposure-ms", "300", "--gain", "1", *seed,
                     str(out)]) == 0
        return np.asarray(tifffile.imread(out))

    a, b = frame("a.tiff", "--seed", "7"), frame("b.tiff", "--seed", "7")
    assert np.array_equal(a, b)
    assert not np.array_equal(a, frame("c.tiff", "--seed", "8"))
    # Without a seed every snap is a fresh noise draw.
    assert not np.array_equal(frame("d.tiff"), frame("e.tiff"))
