"""Decision rules on simulated lots with known truth: false accepts, false rejects, and the
indeterminate share of each rule; verification time per session and per lot.

The lens-variation model: each unit's optics blur like a Gaussian point spread of width
``sigma_um`` (drawn log-normally around a design value: assembly tolerances spread it), so
its true modulation transfer at the limit's frequency is ``exp(-2 pi^2 sigma^2 f^2)``. The
bench reads it with a normal error of the standard uncertainty it reports (the calibrated
1-sigma of benchlab's readings), and each rule decides from the reading and that
uncertainty. A unit *truly* conforms when its true value meets the limit; a false accept is
a pass of a truly non-conforming unit, a false reject a fail of a truly conforming one.
"""

from __future__ import annotations

import math
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from benchlab.acceptance.decide import FAIL, INDETERMINATE, PASS, decide, reading_of
from benchlab.acceptance.spec import Limit, Spec
from benchlab.acceptance.verify import read_session, verify_unit
from benchlab.session import Session

#: The limit every lot is judged against: modulation >= 0.50 at 60 lp/mm.
LIMIT_MIN = 0.50
FREQ_LP_PER_MM = 60.0
#: Design blur and its spread between units (log-normal: sigma_um * exp(N(0, spread))).
DESIGN_SIGMA_UM = 3.0
#: Lots: (name, log spread of the blur, the bench's 1-sigma uncertainty of a reading).
LOTS = (("tight lot, good bench", 0.10, 0.010),
        ("tight lot, noisy bench", 0.10, 0.030),
        ("wide lot, good bench", 0.25, 0.010),
        ("wide lot, noisy bench", 0.25, 0.030))


def true_modulation(sigma_um: np.ndarray) -> np.ndarray:
    """Modulation transfer of a Gaussian blur of ``sigma_um`` at :data:`FREQ_LP_PER_MM`."""
    sigma_mm = sigma_um * 1e-3
    return np.exp(-2.0 * math.pi**2 * sigma_mm**2 * FREQ_LP_PER_MM**2)


@dataclass
class RuleFigures:
    lot: str
    rule: str
    units: int
    truly_failing: int
    false_accepts: int
    false_rejects: int
    indeterminate: int

    def row(self) -> dict[str, Any]:
        conforming = self.units - self.truly_failing
        return {"lot": self.lot, "rule": self.rule, "units": self.units,
                "truly failing": self.truly_failing,
                "false accept % of failing": 100 * self.false_accepts / max(self.truly_failing, 1),
                "false reject % of conforming": 100 * self.false_rejects / max(conforming, 1),
                "indeterminate %": 100 * self.indeterminate / self.units}


def simulate_lot(units: int, spread: float, u: float, rng: np.random.Generator
                 ) -> tuple[np.ndarray, np.ndarray]:
    """True modulations and readings of ``units`` units."""
    blur = DESIGN_SIGMA_UM * np.exp(rng.normal(0.0, spread, size=units))
    truth = true_modulation(blur)
    return truth, truth + rng.normal(0.0, u, size=units)


def rule_figures(units: int = 2000, seed: int = 0) -> list[RuleFigures]:
    """Every lot of :data:`LOTS` judged by both rules through :func:`decide`."""
    rng = np.random.default_rng(seed)
    limit = Limit(id="m60", table="t", column="modulation", min=LIMIT_MIN)
    out = []
    for name, spread, u in LOTS:
        truth, readings = simulate_lot(units, spread, u, rng)
        failing = truth < LIMIT_MIN
        for rule in ("guarded", "simple"):
            verdicts = np.array([
                decide(reading_of({"modulation": float(r), "modulation_uncertainty": u},
                                  limit, 0.95), limit, rule).verdict for r in readings])
            out.append(RuleFigures(
                name, rule, units, int(failing.sum()),
                int(np.sum((verdicts == PASS) & failing)),
                int(np.sum((verdicts == FAIL) & ~failing)),
                int(np.sum(verdicts == INDETERMINATE))))
    return out


def _session(root: Path, name: str, reading: float, u: float) -> Path:
    session = Session.create(root, procedure="mtf", params={}, operator="benchmark",
                             devices={}, software_version="benchmark", name=name,
                             sample=name, lot="BENCH")
    session.write_results({"table_4_11": [{"element": "G3E6", "sagittal_modulation": reading,
                                           "sagittal_uncertainty": u,
                                           "sagittal_resolved": True}]},
                          summary={}, estimator="benchmark")
    session.finish("completed")
    session.release()
    return session.path


def timing(lot_units: int = 1000, seed: int = 0) -> dict[str, float]:
    """Seconds to read and verify one session, and a lot of ``lot_units`` sessions (folders
    written first, outside the timing)."""
    rng = np.random.default_rng(seed)
    spec = Spec(path=Path("<benchmark>"), name="benchmark", version=1, decision_rule="guarded",
                coverage=0.95, limits=(Limit(id="m", table="forward_view_modulation",
                                             column="sagittal_modulation", min=LIMIT_MIN),))
    _, readings = simulate_lot(lot_units, 0.25, 0.01, rng)
    with tempfile.TemporaryDirectory(prefix="benchlab-acceptance-") as tmp:
        paths = [_session(Path(tmp), f"u{i:05d}", float(r), 0.01)
                 for i, r in enumerate(readings)]
        t0 = time.perf_counter()
        verify_unit([read_session(paths[0])], spec)
        one = time.perf_counter() - t0
        t0 = time.perf_counter()
        for p in paths:
            verify_unit([read_session(p)], spec)
        lot = time.perf_counter() - t0
    return {"per_session_s": one, "lot_s": lot, "lot_units": lot_units}
