"""The MTF procedure judges its slanted edges' clipping against the camera's ceiling from the
forward frame's own metadata (``bits``), in the run's analysis and in ``benchlab analyze``
alike; the codes are only a fallback."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from sim_runs import MTF_SMALL

from benchlab.analysis.sfr.measure import SfrResult, full_scale_of_frame, measure_sfr
from benchlab.analysis.sfr.target import edge_specs
from benchlab.analysis.sfr.target_edges import measure_edges
from benchlab.drivers.mightex.sim_sensor import SensorModel
from benchlab.drivers.sensor import AcquisitionState
from benchlab.protocols.mtf.analysis import analyze_mtf
from benchlab.protocols.mtf.edges import edge_tables
from benchlab.protocols.mtf.params import MtfParams
from benchlab.protocols.params import load_params
from benchlab.scenes.world import SimWorld
from benchlab.session import Session
from benchlab.synthetic.edges import synthetic_edge


@pytest.fixture(scope="module")
def dn12() -> np.ndarray:
    """A 12-bit forward frame of the simulated bench (edges at ~320 and ~3040, noise ~14)."""
    state = AcquisitionState(300.0, 1.0, 12, 1280, 1024, 0.0, 0, {})
    return SensorModel(seed=0).render_dn12(SimWorld("usaf"), state).reshape(1024, 1280).copy()


def _ten_bit(dn12: np.ndarray, divisor: float) -> np.ndarray:
    """The scene on a camera set to 10 bits, in uint16: codes above 1023 read 1023."""
    return np.minimum(np.round(dn12 / divisor), 1023).astype(np.uint16)


def _clipped_text(pixels: np.ndarray, roi: tuple[int, int, int, int], top: int) -> str:
    r0, c0, r1, c1 = roi
    cut = pixels[r0:r1, c0:c1]
    frac = float(np.mean((cut <= 0) | (cut >= top)))
    return (f"{100 * frac:.1f} % of the pixels are clipped at 0 or full scale ({top}) "
            "(> 0.5 %): the ESF is flattened")


def test_full_scale_of_frame_is_the_metadata_bit_depth() -> None:
    plain10 = np.array([[0, 1000]], dtype=np.uint16)
    aligned12 = np.array([[16 * 20, 16 * 3000]], dtype=np.uint16)  # 12-bit codes << 4
    aligned10 = np.array([[64 * 20, 64 * 1000]], dtype=np.uint16)  # 10-bit codes << 6
    assert full_scale_of_frame(plain10, {"bits": 10}) == 1023.0
    assert full_scale_of_frame(plain10, {"bits": 12}) == 4095.0
    assert full_scale_of_frame(plain10, {"bits": 16}) == 65535.0
    assert full_scale_of_frame(aligned12, {"bits": 12}) == 65520.0
    assert full_scale_of_frame(aligned10, {"bits": 10}) == 65472.0
    assert full_scale_of_frame(np.array([[3, 200]], dtype=np.uint8), {"bits": 8}) == 255.0
    # Nothing usable: None, and the SFR infers the full scale from the ROI's codes as before.
    odd = np.array([[17, 5000]], dtype=np.uint16)  # above 4095, not MSB-aligned
    for frame, meta in ((odd, {"bits": 12}), (plain10, {}), (plain10, None),
                        (plain10, {"bits": True}), (plain10, {"bits": "10"}),
                        (plain10, {"bits": 17}), (plain10, {"bits": 0}),
                        (np.array([[3, 200]], dtype=np.uint8), {"bits": 12}),
                        (plain10.astype(np.float64), {"bits": 10})):
        assert full_scale_of_frame(frame, meta) is None, (frame, meta)


def test_a_10_bit_frame_clipped_at_1023_is_refused_by_its_metadata(dn12: np.ndarray) -> None:
    pixels = _ten_bit(dn12, 3.0)  # bright sides ~1014 +- 5: 5-7 % of each ROI reads 1023
    with_bits = measure_edges(pixels, full_scale=full_scale_of_frame(pixels, {"bits": 10}))
    assert [res for _, res in with_bits] == [_clipped_text(pixels, spec.roi, 1023)
                                             for spec in edge_specs()]
    # What the codes alone say (a uint16 frame below 4096 is taken as 12-bit): every edge
    # measured as if unclipped, without a word about clipping.
    inferred = measure_edges(pixels)
    assert all(isinstance(res, SfrResult) and res.clipped_fraction == 0.0
               and not any("clipped" in w for w in res.warnings) for _, res in inferred)


def test_a_little_clipping_is_warned_only_with_the_metadata(dn12: np.ndarray) -> None:
    pixels = _ten_bit(dn12, 3.05)
    e0b = [s for s in edge_specs() if s.label == "E0B"]
    (_, res), = measure_edges(pixels, e0b, full_scale=full_scale_of_frame(pixels, {"bits": 10}))
    assert isinstance(res, SfrResult)
    assert res.warnings == ("0.11 % of the pixels clipped (0 or 1023)",)
    (_, plain), = measure_edges(pixels, e0b)
    assert isinstance(plain, SfrResult) and plain.warnings == ()


def test_bits_that_match_the_inference_change_nothing(dn12: np.ndarray) -> None:
    centre = (512.0, 640.0)
    for pixels, bits in ((dn12, 12), ((dn12 >> 4).astype(np.uint8), 8)):
        top = full_scale_of_frame(pixels, {"bits": bits})
        assert top == 2.0**bits - 1
        assert edge_tables(measure_edges(pixels, full_scale=top), centre) == \
            edge_tables(measure_edges(pixels), centre)


def test_msb_aligned_codes_read_as_their_plain_codes() -> None:
    """A 10-bit edge MSB-aligned in 16 bits reads as its plain 10-bit codes, the rounding of
    its 64-code steps included (the frame's full scale 65472 gives the code step)."""
    plain = synthetic_edge((100, 100), 5.0, 1.0, bits=10).astype(np.uint16)
    aligned = plain << np.uint16(6)
    a = measure_sfr(aligned, full_scale=full_scale_of_frame(aligned, {"bits": 10}))
    p = measure_sfr(plain, full_scale=full_scale_of_frame(plain, {"bits": 10}))
    assert a.mtf50_cycles_per_px == pytest.approx(p.mtf50_cycles_per_px, rel=1e-9)
    assert a.mtf50_sigma == pytest.approx(p.mtf50_sigma, rel=1e-6)
    assert a.mtf_sigma is not None and p.mtf_sigma is not None
    np.testing.assert_allclose(a.mtf_sigma, p.mtf_sigma, rtol=1e-6, atol=1e-12)


def _session(root: Path, pixels: np.ndarray, meta: dict[str, Any]) -> Session:
    s = Session.create(root, procedure="mtf", params={}, operator="t", devices={},
                       software_version="0")
    s.save_frame("forward", "forward", pixels, meta)
    return s


@pytest.fixture(scope="module")
def params() -> MtfParams:
    p = load_params("mtf", MTF_SMALL)
    assert isinstance(p, MtfParams)
    return p


def test_the_analysis_reads_bits_from_the_forward_frame(
        dn12: np.ndarray, params: MtfParams, tmp_path: Path) -> None:
    """``analyze_mtf`` (the run's analysis step and ``benchlab analyze``): the 10-bit frame's
    edges are refused as clipped at 1023."""
    pixels = _ten_bit(dn12, 3.0)
    expected = [f"no clean edge: {_clipped_text(pixels, spec.roi, 1023)}"
                for spec in edge_specs()]
    session = _session(tmp_path, pixels, {"bits": 10})
    tables, _, _ = analyze_mtf(session, params, None)
    assert [r["status"] for r in tables["table_sfr_edges"]] == expected
    # The same pixels recorded as 12-bit: measured, every edge ok (no clipping below 4095).
    other = _session(tmp_path, pixels, {"bits": 12})
    tables12, _, _ = analyze_mtf(other, params, None)
    assert [r["status"] for r in tables12["table_sfr_edges"]] == ["ok"] * len(edge_specs())
