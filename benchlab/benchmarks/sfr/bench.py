"""The simulated-bench half of ``benchlab benchmark sfr``: the Table 4.10 procedure run on the
simulated bench (real drivers on the simulators), its slanted-edge MTF curves against the
scene's analytic MTF, its bar readings against what the edges predict they read (each set imaged
through the edges' transfer and read by the same estimator:
:mod:`benchlab.analysis.chart.threebar`) and, for reference, its Coltman-converted bar
readings against the edge MTF.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from benchlab.analysis.bars.result import NYQUIST_CYCLES_PER_PX as NYQUIST

#: Criteria (issue 16): edge vs scene truth to Nyquist; Coltman bars vs edge below Nyquist.
EDGE_TRUTH_TOL = 0.02
BARS_EDGE_TOL = 0.05
#: Target: the bar modulation within this of the edges' predicted three-bar reading.
BARS_PREDICTED_TOL = 0.02


@dataclass(frozen=True)
class BenchCheck:
    bits: int
    blur_scale: float
    edge_rows: list[dict[str, Any]]  # label, orientation, max |edge - truth| to Nyquist, ...
    bar_rows: list[dict[str, Any]]  # the procedure's table_sfr_vs_bars rows
    edge_tables_cpu_ms: float  # median CPU time of the edge tables of the forward frame


def run_bench_check(bits: int = 8, seed: int = 0, blur_scale: float = 1.0) -> BenchCheck:
    """Run the Table 4.10 procedure on the simulated bench (default parameters at ``bits``)
    into a temporary folder and score its edge tables against the scene's truth.
    ``blur_scale`` scales the forward view's blur widths (chart and edge target alike; 0.5:
    a lens twice as sharp)."""
    import copy
    import tempfile
    import threading

    from benchlab.bench import Bench, BenchConfig
    from benchlab.protocols import load_params, start_run
    from benchlab.protocols.params import parse_params
    from benchlab.scenes.edge import EdgeScene
    from benchlab.scenes.optics import FORWARD_BLUR, BlurProfile
    from benchlab.scenes.usaf import UsafScene

    config = BenchConfig.load(None, simulate=True)
    raw = copy.deepcopy(dict(load_params("mtf", None, config.limits()).raw))
    raw.setdefault("camera", {})["bits"] = bits
    params = parse_params("mtf", raw, "<benchmark sfr>", config.limits())
    if not blur_scale > 0:
        raise ValueError(f"blur_scale must be > 0, got {blur_scale}")
    blur = BlurProfile(FORWARD_BLUR.image_height_mm,
                       tuple(s * blur_scale for s in FORWARD_BLUR.sigma_sagittal_px),
                       tuple(s * blur_scale for s in FORWARD_BLUR.sigma_tangential_px))
    with tempfile.TemporaryDirectory(prefix="benchlab-sfr-") as root:
        with Bench.open(config, simulate=True, seed=seed) as bench:
            if blur_scale != 1.0:
                assert bench.world is not None
                bench.world.usaf = UsafScene(blur=blur)
                bench.world.edges = EdgeScene(blur=blur)
            runner = start_run("mtf", bench=bench, params=params, root=root, operator="bench",
                               prompt=lambda step, msg: True, abort=threading.Event())
            outcome = runner.run()
            tables = outcome.tables
            edge_ms = _edge_tables_cpu_ms(outcome.session_path / "frames" / "forward__forward.tiff")
    scene = EdgeScene(blur=blur)  # what the simulated bench's world showed
    specs = {e.label: e for e in scene.edges()}
    edge_rows = []
    for row in tables.get("table_sfr_edges", []):
        if row["status"] != "ok":
            edge_rows.append({"edge": row["edge"], "orientation": row["orientation"],
                              "status": row["status"], "max_err": None})
            continue
        pts = [r for r in tables["table_sfr_curves"]
               if r["edge"] == row["edge"] and r["freq_cycles_per_px"] <= NYQUIST + 1e-9]
        f = np.array([r["freq_cycles_per_px"] for r in pts])
        m = np.array([r["mtf"] for r in pts])
        truth = scene.truth_mtf(specs[row["edge"]], f)
        err = np.abs(m - truth)
        edge_rows.append({"edge": row["edge"], "orientation": row["orientation"],
                          "status": "ok", "max_err": float(err.max()),
                          "f_at_max": float(f[int(err.argmax())]),
                          "mtf_nyquist": row["mtf_nyquist"],
                          "truth_mtf_nyquist": float(scene.truth_mtf(specs[row["edge"]],
                                                                     [NYQUIST])[0])})
    return BenchCheck(bits, blur_scale, edge_rows, list(tables.get("table_sfr_vs_bars", [])),
                      edge_ms)


def _edge_tables_cpu_ms(frame: Path, repeats: int = 15) -> float:
    """Median CPU milliseconds of what re-analysis spends on the slanted edges of one forward
    frame: every edge's SFR (with its uncertainty) and the curve tables (``measure_edges`` +
    ``edge_tables``; CPU time, which the machine's other jobs do not inflate)."""
    import statistics
    import time

    import tifffile

    from benchlab.analysis.sfr.target_edges import measure_edges
    from benchlab.protocols.mtf.edges import edge_tables

    pixels = tifffile.imread(frame)
    centre = (pixels.shape[0] / 2.0, pixels.shape[1] / 2.0)
    edge_tables(measure_edges(pixels), centre)  # warm-up
    cpu = []
    for _ in range(repeats):
        c0 = time.process_time()
        edge_tables(measure_edges(pixels), centre)
        cpu.append(time.process_time() - c0)
    return statistics.median(cpu) * 1e3


def format_bench_check(checks: list[BenchCheck]) -> str:
    """Both tables and the verdicts."""
    scales = sorted({c.blur_scale for c in checks})
    blur = "" if scales == [1.0] else " blur x " + "/".join(f"{x:g}" for x in scales) + ","
    lines = [f"simulated bench, forward view (USAF chart + slanted-edge target),{blur} 300 ms, "
             "gain 1:"]
    lines.append(f"{'bits':>4} {'edge':>5} {'orient.':>10} {'max|edge-truth|':>15} "
                 f"{'at c/px':>7} {'MTF(Nyq)':>8} {'truth':>6}")
    worst = 0.0
    for chk in checks:
        for r in chk.edge_rows:
            if r["max_err"] is None:
                lines.append(f"{chk.bits:>4} {r['edge']:>5} {r['orientation']:>10}  refused: "
                             f"{r['status']}")
                worst = float("inf")
                continue
            worst = max(worst, r["max_err"])
            lines.append(f"{chk.bits:>4} {r['edge']:>5} {r['orientation']:>10} "
                         f"{r['max_err']:>15.4f} {r['f_at_max']:>7.3f} {r['mtf_nyquist']:>8.3f} "
                         f"{r['truth_mtf_nyquist']:>6.3f}")
    lines.append(f"edge MTF vs scene analytic MTF to Nyquist: worst {worst:.4f} "
                 f"({'pass' if worst <= EDGE_TRUTH_TOL else 'FAIL'}, criterion "
                 f"{EDGE_TRUTH_TOL})")
    lines.append("")
    lines.append("pred.: the set imaged through the edges' transfer and read by the same estimator "
                 "(compared where it exists); Coltman: harmonics (3f, 5f, ...) from the edge MTF; "
                 "Nyq: Nyquist taken as the cutoff (reference)")
    if blur:
        lines.append("(simul.: the default lens's simulated curves, not rescaled)")
    lines.append(f"{'bits':>4} {'set':>5} {'orient.':>10} {'lp/mm':>7} {'bar mod':>7} "
                 f"{'pred.':>6} {'|bar-pred|':>10} {'CTF':>6} {'Coltman':>7} {'Nyq':>6} "
                 f"{'edge':>6} {'simul.':>6} {'|bar-edge|':>10} {'Nyq':>6}")
    worst_b = worst_nyq = worst_p = 0.0
    n_pred = 0
    for chk in checks:
        for r in chk.bar_rows:
            d = abs(r["bar_mtf"] - r["edge_mtf"])
            d_nyq = abs(r["bar_mtf_coltman"] - r["edge_mtf"])
            worst_b, worst_nyq = max(worst_b, d), max(worst_nyq, d_nyq)
            pred = r.get("bar_modulation_predicted")
            if pred is None:
                p_txt = d_p_txt = "N/A"
            else:
                d_p = abs(r["bar_modulation"] - pred)
                worst_p, n_pred = max(worst_p, d_p), n_pred + 1
                p_txt, d_p_txt = f"{pred:.3f}", f"{d_p:.3f}"
            sim = "N/A" if r["simulated_mtf"] is None else f"{r['simulated_mtf']:.3f}"
            lines.append(f"{chk.bits:>4} {r['element']:>5} {r['orientation']:>10} "
                         f"{r['image_lp_per_mm']:>7.2f} {r['bar_modulation']:>7.3f} "
                         f"{p_txt:>6} {d_p_txt:>10} "
                         f"{r['ctf']:>6.3f} {r['bar_mtf']:>7.3f} {r['bar_mtf_coltman']:>6.3f} "
                         f"{r['edge_mtf']:>6.3f} {sim:>6} {d:>10.3f} {d_nyq:>6.3f}")
    n = sum(len(c.bar_rows) for c in checks)
    cpu = ", ".join(f"{c.bits}-bit {c.edge_tables_cpu_ms:.1f} ms" for c in checks)
    ok_p = bool(n) and n_pred == n and worst_p <= BARS_PREDICTED_TOL
    lines.append(f"bars vs the edges' predicted three-bar reading ({n_pred} of {n} readings): "
                 f"worst {worst_p:.3f} ({'pass' if ok_p else 'FAIL'}, target "
                 f"{BARS_PREDICTED_TOL})")
    lines.append(f"Coltman-converted bars vs edge MTF below Nyquist ({n} readings): worst "
                 f"{worst_b:.3f} ({'pass' if n and worst_b <= BARS_EDGE_TOL else 'FAIL'}, "
                 f"criterion {BARS_EDGE_TOL}); with Nyquist as the cutoff {worst_nyq:.3f}")
    lines.append(f"edge tables of one forward frame (12 edges, SFR + uncertainty + curves), CPU "
                 f"median: {cpu} (target <= 40 ms per session)")
    return "\n".join(lines)
