"""Photon transfer analysis against the simulated sensor's truth, and its extremes."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from ptc_frames import TRUTH, Sweep, analyse, grab, make_sweep

from benchlab.analysis.camera.photon_transfer import (
    SweepPoint,
    linearise,
    msb_aligned,
    native_codes,
    pair_statistics,
    photon_transfer,
    response_curve,
    saturation_vertex,
    spatial_nonuniformity,
)
from benchlab.drivers.mightex.sim_sensor import SensorModel, SensorTruth
from benchlab.protocols.characterise.truth import truth_for


@pytest.fixture(scope="module")
def sweep12() -> Sweep:
    return make_sweep(size=96)


def test_figures_match_the_sensor_truth(sweep12: Sweep) -> None:
    _, r = analyse(sweep12)
    t = truth_for(TRUTH, gain=1.0, bits=12, width=96, height=96)
    assert r.system_gain_dn_per_e == pytest.approx(t["system_gain_dn_per_e"], rel=0.02)
    assert r.read_noise_e == pytest.approx(t["read_noise_e"], rel=0.05)
    assert r.read_noise_dn == pytest.approx(t["read_noise_dn"], rel=0.05)
    assert r.saturation_reached
    assert r.saturation_dn == pytest.approx(t["saturation_dn"], rel=0.02)
    assert r.saturation_e == pytest.approx(r.saturation_dn / r.system_gain_dn_per_e)
    assert r.dark_current_e_per_s == pytest.approx(500.0, rel=0.05)
    assert r.spatial is not None
    assert r.spatial.dsnu_dn == pytest.approx(t["dsnu_dn"], rel=0.1)
    assert r.spatial.prnu_pct == pytest.approx(t["prnu_pct"], rel=0.1)
    lo, hi = r.linearity_error_pct
    assert -0.2 < lo <= 0 <= hi < 0.2  # a linear sensor
    assert r.read_noise_resolved and not r.warnings
    # The K uncertainty is a real spread: smaller than 2 %, not zero.
    assert 0 < r.system_gain_uncertainty_dn_per_e < 0.02 * r.system_gain_dn_per_e


def test_compressed_sensor_linearity_error_matches_truth() -> None:
    truth = dataclasses.replace(TRUTH, compression_at_full_well=0.05, compression_knee=0.3)
    sweep = make_sweep(truth, size=64)
    points, r = analyse(sweep)
    t = truth_for(truth, gain=1.0, bits=12, width=64, height=64,
                  exposures_ms=sweep.exposures_ms,
                  light_e=[400.0 * x for x in sweep.exposures_ms])
    assert t["linearity_error_pct"][0] < -1.0  # the truth is clearly non-linear
    # A flat variance peak: the refined saturation still matches the standard's definition.
    assert r.saturation_dn == pytest.approx(t["saturation_dn"], rel=0.02)
    for m, tv in zip(r.linearity_error_pct, t["linearity_error_pct"], strict=True):
        assert m == pytest.approx(tv, abs=0.2)
    # The response curve undoes the compression: linearised step means lie on one line.
    curve = response_curve(points, r, gain=1.0, bits=12)
    pts = sorted(points, key=lambda p: p.exposure_ms)[: (r.saturation_index or 0) - 1]
    fixed = [float(linearise(np.array([p.mean_dn]), curve)[0]) - curve.black_level_dn
             for p in pts]
    ratio = np.array([f / p.exposure_ms for f, p in zip(fixed, pts, strict=True)
                      if p.signal_dn > 0.1 * r.saturation_dn])
    assert np.ptp(ratio) / ratio.mean() < 0.005
    raw = np.array([p.signal_dn / p.exposure_ms for p in pts
                    if p.signal_dn > 0.1 * r.saturation_dn])
    assert np.ptp(raw) / raw.mean() > 0.02  # without it the spread is several %


def test_sweep_that_never_saturates_gives_no_saturation_value() -> None:
    sweep = make_sweep(top=0.6, size=48)
    _, r = analyse(sweep)
    assert r.saturation_dn is None and r.saturation_e is None and not r.saturation_reached
    assert any("never reached saturation" in w for w in r.warnings)
    assert r.system_gain_dn_per_e == pytest.approx(TRUTH.dn12_per_e, rel=0.03)


def test_steps_where_both_frames_saturate_are_past_the_peak(sweep12: Sweep) -> None:
    points, r = analyse(sweep12)
    ordered = sorted(points, key=lambda p: p.exposure_ms)
    last = ordered[-1]
    assert last.variance_dn2 < 1.0  # both frames clipped: no temporal variance left
    assert r.saturation_index is not None and r.saturation_index < len(ordered) - 1
    assert len(ordered) - 1 not in r.k_fit_indices
    assert max(r.k_fit_indices) < r.saturation_index


def test_dark_step_below_read_noise() -> None:
    points, r = analyse(make_sweep(rate=100.0, size=64))  # 0.05 ms: 5 e- = 1 DN
    first = min(points, key=lambda p: p.exposure_ms)
    assert 0 < first.signal_dn < r.read_noise_dn  # below the read noise, kept, harmless
    i_first = 0
    assert i_first not in r.linearity_indices  # below 5 % of saturation
    assert np.isfinite(r.deviation_pct[i_first])


def test_12_bit_msb_aligned_equals_right_aligned(sweep12: Sweep) -> None:
    _, plain = analyse(sweep12)
    _, aligned = analyse(sweep12, transform=lambda a: (a.astype(np.uint16) << 4))
    assert msb_aligned([sweep12.dark[0][0].astype(np.uint16) << 4], 12) is False  # dark alone
    assert aligned.system_gain_dn_per_e == pytest.approx(plain.system_gain_dn_per_e, rel=1e-12)
    assert aligned.saturation_dn == pytest.approx(plain.saturation_dn, rel=1e-12)
    frame = np.array([[16, 32], [65520, 4096]], dtype=np.uint16)
    assert native_codes(frame, 12).tolist() == [[1, 2], [4095, 256]]
    with pytest.raises(ValueError, match="not MSB-aligned"):
        native_codes(np.array([4096, 17], dtype=np.uint16), 12)


def test_hot_pixels_are_excluded_and_counted() -> None:
    truth = dataclasses.replace(TRUTH, hot_pixel_fraction=0.002,
                                hot_pixel_dark_current_e_per_s=2e5)
    sweep = make_sweep(truth, size=96)
    _, r = analyse(sweep)
    t = truth_for(truth, gain=1.0, bits=12, width=96, height=96)
    assert t["hot_pixels"] > 5
    assert r.spatial is not None and r.spatial.defect_pixels == t["hot_pixels"]
    assert r.spatial.dsnu_dn == pytest.approx(t["dsnu_dn"], rel=0.1)
    assert r.spatial.dsnu_all_pixels_dn > 5 * r.spatial.dsnu_dn  # EMVA's all-pixel figure
    assert r.system_gain_dn_per_e == pytest.approx(TRUTH.dn12_per_e, rel=0.02)
    assert r.read_noise_e == pytest.approx(8.0, rel=0.05)


def test_eight_bit_read_noise_below_quantisation_is_flagged() -> None:
    sweep = make_sweep(bits=8, size=48)
    _, r = analyse(sweep, bits=8)
    assert not r.read_noise_resolved
    assert any("quantisation" in w for w in r.warnings)
    assert r.system_gain_dn_per_e == pytest.approx(TRUTH.dn12_per_e / 16, rel=0.03)


def test_bad_inputs() -> None:
    p = SweepPoint(1.0, 100.0, 20.0, 64.0, 3.0)
    with pytest.raises(ValueError, match="at least 3"):
        photon_transfer([p, p])
    with pytest.raises(ValueError, match="shapes differ"):
        pair_statistics(np.zeros((2, 2)), np.zeros((2, 3)))
    with pytest.raises(ValueError, match="no step has signal"):
        photon_transfer([SweepPoint(t, 64.0, 3.0, 64.0, 3.0) for t in (1.0, 2.0, 3.0)])
    with pytest.raises(ValueError, match="stacks"):
        spatial_nonuniformity(np.zeros((1, 4, 4)), np.zeros((1, 4, 4)))


def test_sensor_truth_defaults_keep_the_plain_model() -> None:
    plain = SensorModel(0)
    truth = SensorModel(0, truth=SensorTruth())
    a = grab(plain, 30.0, 300.0, 1.0, 12, 32)
    b = grab(truth, 30.0, 300.0, 1.0, 12, 32)
    assert np.array_equal(a, b)
    with pytest.raises(ValueError, match="unknown sensor truth"):
        SensorTruth.from_mapping({"gain": 2.0})
    with pytest.raises(ValueError, match="finite and >= 0"):
        SensorTruth(read_noise_e=-1.0)


def test_saturation_vertex_refines_a_flat_peak_and_keeps_a_sharp_one() -> None:
    signal = np.arange(10, dtype=float) * 100.0
    flat = 1000.0 - 0.001 * (signal - 640.0) ** 2  # vertex at 640, between steps
    flat[7] += 3.0  # noise makes step 7 the highest
    assert int(np.argmax(flat)) == 7
    assert saturation_vertex(signal, flat, 7) == pytest.approx(640.0, abs=5.0)
    sharp = np.array([1.0, 2.0, 3.0, 10.0, 0.5, 0.1])
    assert saturation_vertex(signal[:6], sharp, 3) == 300.0  # no neighbours within 10 %
