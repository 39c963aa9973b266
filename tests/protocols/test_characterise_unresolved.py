"""Characterisation figures the frames cannot resolve are flagged, never given as numbers: a
black level clipped at code 0 (read noise, dark current, DSNU biased low), an 8-bit dark signal
below 1 DN (quantisation), a PRNU stack at the top code."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest
from ptc_frames import TRUTH, Sweep, make_sweep

from benchlab.analysis.camera.photon_transfer import PhotonTransferResult, photon_transfer
from benchlab.protocols.characterise.analysis import sweep_statistics
from benchlab.report.tables import TABLE_VIEWS, format_table, html_table

DARK_KEYS = ("read_noise_dn", "read_noise_e", "dark_current_e_per_s", "dsnu_dn")


def _frames(sweep: Sweep) -> tuple[dict[str, Any], dict[str, Any]]:
    """The sweep as a session step's frames and metadata (names as the procedure saves)."""
    frames: dict[str, Any] = {}
    metas: dict[str, Any] = {}
    for i, (t, lit, dark) in enumerate(zip(sweep.exposures_ms, sweep.lit, sweep.dark,
                                           strict=True)):
        for half, a, d in zip("ab", lit, dark, strict=True):
            frames[f"e{i:03d}-lit-{half}"] = a
            frames[f"e{i:03d}-dark-{half}"] = d
        metas[f"e{i:03d}-lit-a"] = {"exposure_ms": t}
    for k, (a, d) in enumerate(zip(sweep.stack_lit, sweep.stack_dark, strict=True)):
        frames[f"stack-lit-{k:03d}"] = a
        frames[f"stack-dark-{k:03d}"] = d
    return frames, metas


def _analyse(sweep: Sweep, bits: int) -> PhotonTransferResult:
    frames, metas = _frames(sweep)
    points, spatial, _, _ = sweep_statistics(frames, metas, bits)
    return photon_transfer(points, spatial=spatial)


def test_black_level_clipped_at_zero_flags_the_dark_figures() -> None:
    clipped = dataclasses.replace(TRUTH, dark_offset_dn12=0.0)
    r = _analyse(make_sweep(clipped, gain=4.0, size=48, steps=20, stack=4), 12)
    assert r.dark_zero_fraction > 0.3  # about half the dark pixels read 0
    # The estimates are biased low (truth 8 e-, 500 e-/s): why they must not be given.
    assert r.read_noise_e < 0.8 * 8.0
    assert r.dark_current_e_per_s is not None and r.dark_current_e_per_s < 0.8 * 500.0
    for quantity in ("read_noise", "dark_current", "dsnu"):
        assert not r.resolved(quantity)
    assert r.resolved("prnu") and not r.read_noise_resolved
    m = r.measured()
    assert all(m[k] is None for k in DARK_KEYS)
    assert m["dark_level_clipped"] is True and m["dark_zero_pct"] > 30.0
    assert m["dark_current_resolved"] is False and m["dsnu_resolved"] is False
    assert m["read_noise_unresolved"] == "black level clipped"
    assert m["system_gain_dn_per_e"] > 0  # K is still given
    assert any("black level clipped" in w and "raise the black level/offset" in w
               for w in r.warnings)


def test_black_level_with_offset_is_resolved() -> None:
    r = _analyse(make_sweep(TRUTH, gain=4.0, size=48, steps=20, stack=4), 12)
    assert r.dark_zero_fraction == 0.0 and not r.unresolved and not r.warnings
    m = r.measured()
    assert m["read_noise_e"] == pytest.approx(8.0, rel=0.08)
    assert m["dark_current_e_per_s"] == pytest.approx(500.0, rel=0.1)
    assert (m["dark_current_resolved"], m["dsnu_resolved"], m["prnu_resolved"]) == (
        True, True, True)
    assert m["dark_level_clipped"] is False


def test_a_few_zero_codes_are_tolerated() -> None:
    # 0.3 % of the pixels dead at 0 in every dark frame: under EMVA's 0.5 %, not "clipped".
    sweep = make_sweep(TRUTH, gain=4.0, size=48, steps=20, stack=4)
    dead = np.zeros((48, 48), dtype=bool)
    dead.flat[:: 48 * 48 // 7] = True  # 7 pixels of 2304 = 0.3 %

    def kill(a: Any) -> Any:
        a = a.copy()
        a[..., dead] = 0
        return a

    sweep = dataclasses.replace(sweep, dark=[(kill(a), kill(b)) for a, b in sweep.dark])
    r = _analyse(sweep, 12)
    assert 0.0 < r.dark_zero_fraction <= 0.005 and r.resolved("read_noise")


def test_eight_bit_dark_signal_below_one_dn_is_not_resolved() -> None:
    r = _analyse(make_sweep(TRUTH, gain=1.0, bits=8, size=48, steps=20, stack=4), 8)
    for quantity in ("read_noise", "dark_current", "dsnu"):
        assert not r.resolved(quantity)
    m = r.measured()
    assert all(m[k] is None for k in DARK_KEYS)
    assert m["dark_current_resolved"] is False and m["dark_level_clipped"] is False
    assert m["dark_current_unresolved"] == "dark noise < 1 DN"
    assert any("dark signal rises" in w and "dark current not resolved" in w
               for w in r.warnings)
    # The 12-bit frames of the same sensor resolve it.
    r12 = _analyse(make_sweep(TRUTH, gain=1.0, bits=12, size=48, steps=20, stack=4), 12)
    assert r12.resolved("dark_current") and r12.measured()["dark_current_e_per_s"] == \
        pytest.approx(500.0, rel=0.1)


def test_saturated_prnu_stack_gives_no_prnu() -> None:
    sweep = make_sweep(TRUTH, gain=1.0, size=48, steps=20, stack=4)
    # The stack at the last (clipped) sweep step: every pixel at the top code.
    top = sweep.lit[-1][0]
    assert (top == 4095).mean() > 0.9
    saturated = dataclasses.replace(sweep, stack_lit=np.stack([top] * 4))
    r = _analyse(saturated, 12)
    assert r.spatial is not None and r.spatial.bright_top_fraction > 0.9
    assert r.spatial.prnu_pct < 0.1  # what it read without the check (truth 1 %)
    assert not r.resolved("prnu") and r.measured()["prnu_pct"] is None
    assert r.measured()["prnu_unresolved"] == "stack saturated"
    assert any("PRNU stack saturated" in w for w in r.warnings)
    ok = _analyse(sweep, 12)
    assert ok.spatial is not None and ok.spatial.bright_top_fraction == 0.0
    assert ok.measured()["prnu_pct"] == pytest.approx(1.0, rel=0.15)


def test_tables_show_unresolved_figures_as_na_with_the_reason() -> None:
    r = _analyse(make_sweep(dataclasses.replace(TRUTH, dark_offset_dn12=0.0), gain=4.0,
                            size=48, steps=20, stack=4), 12)
    row = {"gain": 4.0, "bits": 12, **r.measured()}
    view = TABLE_VIEWS["characterisation"]
    text = format_table([row], view.columns)
    assert text.count("n/a (unresolved: black level clipped)") == 4  # noise DN, e-, dark, DSNU
    assert "0.8" in text.splitlines()[1]  # K is given
    assert html_table([row], view.columns).count("n/a (unresolved: black level clipped)") == 4
