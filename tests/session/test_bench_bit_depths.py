"""Issue 36, point 8: 10 bits end to end. Every procedure accepts 10-bit frames; a run refuses
a depth the bench file's [camera] bit_depths (what `benchlab doctor` found to decode) leaves
out, and a depth whose frames show bits that are never set."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from benchlab.bench import Bench, BenchConfig, BenchError
from benchlab.checks import BenchLimits, ParamsError
from benchlab.drivers.mightex.diagnose import never_set_bits_finding
from benchlab.drivers.mightex.sim import flat_field_scene
from benchlab.protocols.params import parse_params


@pytest.mark.parametrize("procedure", ["mtf", "radiometry", "depth", "characterise"])
def test_every_procedure_takes_10_bits(procedure: str) -> None:
    many = procedure == "characterise"
    params = parse_params(procedure, {"camera": {"bits": [10, 8] if many else 10}})
    assert params.bits == ((10, 8) if many else 10)  # type: ignore[union-attr]
    with pytest.raises(ParamsError, match="camera.bits"):
        parse_params(procedure, {"camera": {"bits": [14] if many else 14}})


def test_a_depth_left_out_of_the_bench_file_is_refused_before_any_frame() -> None:
    cfg = BenchConfig.load(None, simulate=True)
    cfg = replace(cfg, camera=replace(cfg.camera, bit_depths=(8, 10)))
    with Bench.open(cfg, simulate=True) as bench:
        with pytest.raises(BenchError, match=r"bit depth 12 is not one this camera decodes.*"
                                             r"bit_depths = \[8, 10\]"):
            bench.configure_camera(bits=12, width=128, height=128)
        bench.configure_camera(bits=10, width=128, height=128)
        pixels, meta = bench.grab(exposure_ms=20.0, gain=1.0)
        assert meta["bits"] == 10 and int(pixels.max()) <= 1023


def test_a_depth_whose_frames_never_set_some_bits_is_refused_at_run_time() -> None:
    with Bench.open(BenchConfig.load(None, simulate=True), simulate=True) as bench:
        sim = bench.sim_camera
        assert sim is not None
        sim.spec = replace(sim.spec, bit_depths=(8, 10))  # a sensor with no real 12-bit mode
        sim.scene = flat_field_scene()  # light on the sensor: codes spread enough to tell
        bench.configure_camera(bits=10, width=128, height=128)  # the camera takes 10...
        bench.configure_camera(bits=12, width=128, height=128)  # ...and ignores 12
        with pytest.raises(BenchError, match="bits 2 and 3 are never set.*not a real 12-bit"):
            bench.grab(exposure_ms=20.0, gain=1.0)


def test_never_set_bits_are_told_only_from_frames_with_spread() -> None:
    rng = np.random.default_rng(1)
    real = rng.integers(100, 3000, 4096)
    assert never_set_bits_finding(real, 12) == (None, True)
    assert never_set_bits_finding(real & ~0b11, 12)[0] == (
        "the lowest 2 bits never change: the data has 10 significant bits, not 12 "
        "(MSB-aligned)")
    assert never_set_bits_finding(np.full(4096, 2000), 12) == (None, False)  # flat: undecided


def test_the_settled_depths_are_the_characterisations_default_and_checked_up_front() -> None:
    limits = BenchLimits(led_ceilings_ma={1: 50.0}, camera_bit_depths=(8, 10))
    assert parse_params("characterise", {}, limits=limits).bits == (10, 8)  # type: ignore[union-attr]
    assert parse_params("characterise", {}).bits == (12, 8)  # type: ignore[union-attr]
    for procedure, bits in (("characterise", [12]), ("radiometry", 12), ("depth", 12)):
        with pytest.raises(ParamsError, match=r"camera.bits: 12 bits is not a depth this "
                                              r"bench's camera decodes"):
            parse_params(procedure, {"camera": {"bits": bits}}, limits=limits)
