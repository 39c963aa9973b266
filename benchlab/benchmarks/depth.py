"""``benchlab benchmark depth``: the depth-of-field sweep measured against the simulated bench's
closed-form truth (``simulator_truth``), over seeds and lens variants.

Each run is the packaged procedure (``benchlab run depth`` with the default sweep) on the
simulated bench, seeded, with the variant's ``[simulator]`` lens; the ``depth_of_field`` rows
are compared with ``simulator_truth`` row by row:

* best focus: error, and whether the 95 % interval covers the truth;
* DOF ends (near, far), where both the truth and the measurement have the end inside the
  sweep: the same; ends the fit extrapolates beyond the sweep are counted apart;
* a figure *passes* when it is within the issue's tolerance (0.3 mm, forward view) of the
  truth or its interval covers the truth;
* astigmatic difference (S - T) per field point: where its interval excludes 0, is its sign
  the truth's?

Then the wall time and the frames of a default run, against a plain baseline: one frame and
no bar reading per position.
"""

from __future__ import annotations

import json
import math
import tempfile
import time
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

#: The issue's tolerances, mm: forward view, radial view.
TOLERANCE_MM = 0.3
RADIAL_TOLERANCE_MM = 0.1
#: Lens variants (``[simulator]`` of the parameter file).
VARIANTS: dict[str, dict[str, float]] = {
    "nominal": {},
    "sharp": {"lens_blur_scale": 0.5},
    "astigmatic": {"axial_astigmatism_per_mm": 0.0015, "astigmatism_per_mm2": 0.002},
    "tilted": {"tilt_per_mm2": 0.002, "field_curvature_per_mm2": 0.001},
}
#: Radial variants: the rolled 2 lp/mm pattern, S and T, moved from the side wall, read at the
#: three default field points (image heights 1.80, 2.13, 2.48 mm); "radial-curved" has field
#: curvature (best focus about 0.5 mm nearer the wall at 2.48 mm than at 1.80 mm).
RADIAL_VARIANTS: dict[str, dict[str, float]] = {
    "radial": {},
    "radial-astigmatic": {"axial_astigmatism_per_mm": 0.004},
    "radial-curved": {"field_curvature_per_mm2": 0.0005},
}
ENDS = ("best_focus_mm", "near_mm", "far_mm")


def run_once(variant: str, seed: int, root: Path, *, frames: int = 2, read_chart: bool = False
             ) -> tuple[Path, float, int]:
    """One simulated run; returns (results folder, wall s, frames taken)."""
    from benchlab.bench import Bench, BenchConfig
    from benchlab.protocols import load_params, start_run
    from benchlab.protocols.params import params_to_dict, parse_params

    config = BenchConfig.load(None, simulate=True)
    base = params_to_dict(load_params("depth", None, config.limits()))
    if variant in RADIAL_VARIANTS:
        base = {"procedure": "depth", "camera": base["camera"], "sweep": {"view": "radial"},
                "analysis": {}, "simulator": RADIAL_VARIANTS[variant]}
    else:
        base["simulator"] = {**base["simulator"], **VARIANTS[variant]}
    base["camera"]["frames"] = frames
    base["analysis"]["read_chart"] = read_chart
    params = parse_params("depth", base, f"<benchmark {variant}>", config.limits())
    t0 = time.perf_counter()
    with Bench.open(config, simulate=True, seed=seed) as bench:
        runner = start_run("depth", bench=bench, params=params, root=root, operator="bench",
                           prompt=lambda step, msg: True)
        outcome = runner.run()
    wall = time.perf_counter() - t0
    n_frames = sum(1 for _ in (outcome.session_path / "frames").rglob("*.tif*"))
    return outcome.results_path, wall, n_frames


def _load(results: Path, name: str) -> list[dict[str, Any]]:
    rows: list[dict[str, Any]] = json.loads((results / f"{name}.json").read_text())
    return rows


def _key(row: Mapping[str, Any]) -> tuple[Any, ...]:
    return (row["field_point"], row["orientation"], row["freq_lp_per_mm"], row["criterion"])


def compare(results: Path, tolerance_mm: float = TOLERANCE_MM) -> list[dict[str, Any]]:
    """One row per depth_of_field row and quantity: measured, interval, truth, error, covered,
    passed (None: not comparable)."""
    measured = _load(results, "depth_of_field")
    # keyed by orientation and frequency too: a radial field point carries an S and a T pattern
    truth = {_key(r): r for r in _load(results, "simulator_truth")}
    out = []
    for row in measured:
        t = truth.get(_key(row))
        if t is None or row["best_focus_mm"] is None:
            continue
        for key in ENDS:
            m, tv = row[key], t[key]
            lo, hi = row[f"{key}_ci95"]
            extrapolated = key != "best_focus_mm" and (
                f"{key[:-3]} end extrapolated" in (row.get("note") or ""))
            if m is None or tv is None or lo is None or hi is None or extrapolated:
                out.append({"quantity": key, "criterion": row["criterion"], "judged": False})
                continue
            err = m - tv
            covered = lo <= tv <= hi
            out.append({"quantity": key, "criterion": row["criterion"], "judged": True,
                        "error_mm": err, "covered": covered,
                        "passed": covered or abs(err) <= tolerance_mm,
                        "half_width_mm": (hi - lo) / 2})
    return out


def astig_signs(results: Path) -> list[dict[str, Any]]:
    """Per field point and frequency: measured S - T, its interval, the truth's sign."""
    from benchlab.protocols.depth.truth import truth_astigmatism

    rows = _load(results, "depth_astigmatism")
    truth_rows = _load(results, "simulator_truth")
    if any(r.get("view") == "radial" for r in truth_rows):
        truth = _radial_astigmatism(truth_rows)
    else:
        truth = truth_astigmatism(truth_rows)
    out = []
    for r in rows:
        t = truth.get((r["field_point"], r["freq_lp_per_mm"]))
        lo, hi = r["s_minus_t_mm_ci95"]
        if t is None or lo is None or hi is None:
            continue
        excl = lo > 0 or hi < 0
        out.append({"significant": excl, "sign_right": (not excl) or (
            math.copysign(1, r["s_minus_t_mm"]) == math.copysign(1, t)),
            "covered": lo <= t <= hi})
    return out


def _radial_astigmatism(truth: Iterable[Mapping[str, Any]]) -> dict[tuple[str, float], float]:
    """S minus T truth best focus per radial field point and frequency."""
    by = {(r["field_point"], r["freq_lp_per_mm"], r["orientation"]): r["best_focus_mm"]
          for r in truth}
    return {(fp, f): b - by[(fp, f, "tangential")] for (fp, f, o), b in by.items()
            if o == "sagittal" and (fp, f, "tangential") in by}


def curvature_checks(results: Path) -> list[dict[str, Any]]:
    """Per orientation and frequency: is the truth's field curvature (best focus = b0 + k h^2
    through the truth's field points) inside the measured k's interval?"""
    import numpy as np

    truth = _load(results, "simulator_truth")
    out = []
    for r in _load(results, "depth_field_curvature"):
        pts = {(t["field_point"], t["image_height_mm"], t["best_focus_mm"]) for t in truth
               if t["orientation"] == r["orientation"]
               and t["freq_lp_per_mm"] == r["freq_lp_per_mm"]}
        lo, hi = r["curvature_mm_per_mm2_ci95"]
        if len(pts) < 2 or lo is None or hi is None:
            continue
        h2 = np.array([p[1] ** 2 for p in pts])
        b = np.array([p[2] for p in pts])
        k_true = float(np.polyfit(h2, b, 1)[0])
        out.append({"covered": lo <= k_true <= hi, "error": r["curvature_mm_per_mm2"] - k_true})
    return out


def summarise(comparisons: Iterable[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per quantity: judged count, pass rate, coverage, median |error|, not judged."""
    acc: dict[str, dict[str, Any]] = {}
    for c in comparisons:
        a = acc.setdefault(c["quantity"], {"n": 0, "passed": 0, "covered": 0, "errors": [],
                                           "not_judged": 0, "half": []})
        if not c["judged"]:
            a["not_judged"] += 1
            continue
        a["n"] += 1
        a["passed"] += c["passed"]
        a["covered"] += c["covered"]
        a["errors"].append(abs(c["error_mm"]))
        a["half"].append(c["half_width_mm"])
    out = {}
    for k, a in acc.items():
        errs = sorted(a["errors"])
        half = sorted(a["half"])
        out[k] = {"judged": a["n"], "not_judged": a["not_judged"],
                  "pass_rate": a["passed"] / a["n"] if a["n"] else None,
                  "coverage": a["covered"] / a["n"] if a["n"] else None,
                  "median_abs_error_mm": errs[len(errs) // 2] if errs else None,
                  "median_half_width_mm": half[len(half) // 2] if half else None}
    return out


def run_benchmark(seeds: int = 20,
                  variants: Iterable[str] = (*VARIANTS, *RADIAL_VARIANTS),
                  keep: Path | None = None, progress: Any = None) -> dict[str, Any]:
    """Every (variant, seed) run compared; then the timing of a default run and the baseline."""
    out: dict[str, Any] = {"seeds": seeds, "variants": {}, "timing": {}}
    with tempfile.TemporaryDirectory() as tmp:
        root = keep if keep is not None else Path(tmp)
        for v in variants:
            comps: list[dict[str, Any]] = []
            signs: list[dict[str, Any]] = []
            curv: list[dict[str, Any]] = []
            walls = []
            for s in range(seeds):
                results, wall, _ = run_once(v, 1000 + s, root / v)
                walls.append(wall)
                radial = v in RADIAL_VARIANTS
                comps += compare(results, RADIAL_TOLERANCE_MM if radial else TOLERANCE_MM)
                signs += astig_signs(results)
                curv += curvature_checks(results)
                if progress is not None:
                    progress(f"{v} seed {s}: {wall:.1f} s")
            sig = [x for x in signs if x["significant"]]
            out["variants"][v] = {
                "figures": summarise(comps),
                "astig_significant": len(sig),
                "astig_sign_right": sum(x["sign_right"] for x in sig),
                "astig_coverage": (sum(x["covered"] for x in signs) / len(signs)
                                   if signs else None),
                "curvature_coverage": (sum(x["covered"] for x in curv) / len(curv)
                                       if curv else None),
                "curvature_median_abs_error": (sorted(abs(x["error"]) for x in curv)[
                    len(curv) // 2] if curv else None),
                "median_wall_s": sorted(walls)[len(walls) // 2],
            }
        for name, frames, chart in (("default (2 frames, edges + bar reading)", 2, True),
                                    ("baseline (1 frame, edges only)", 1, False)):
            results, wall, n = run_once("nominal", 7, root / f"timing-{frames}",
                                        frames=frames, read_chart=chart)
            fig = summarise(compare(results))
            out["timing"][name] = {"wall_s": wall, "frames": n,
                                   "best_focus_coverage": fig["best_focus_mm"]["coverage"],
                                   "best_focus_median_half_width_mm":
                                   fig["best_focus_mm"]["median_half_width_mm"]}
    return out


def _pct(v: float | None) -> str:
    return "n/a" if v is None else f"{100 * v:5.1f} %"


def format_benchmark(out: Mapping[str, Any]) -> str:
    """The figures as a plain-text table."""
    w = max([11, *(len(v) for v in out["variants"])])  # the radial variants' names are longer
    lines = [f"depth of field on the simulated bench: {out['seeds']} seeds per variant, "
             f"tolerance {TOLERANCE_MM} mm (radial {RADIAL_TOLERANCE_MM} mm) or the 95 % "
             "interval covering the truth", "",
             f"{'variant':<{w}} {'quantity':<14} {'judged':>6} {'pass':>8} {'coverage':>9} "
             f"{'med |err|':>10} {'med half-CI':>11} {'extrapol.':>9}"]
    for v, r in out["variants"].items():
        for q, f in r["figures"].items():
            med = f["median_abs_error_mm"]
            half = f["median_half_width_mm"]
            lines.append(f"{v:<{w}} {q:<14} {f['judged']:>6} {_pct(f['pass_rate']):>8} "
                         f"{_pct(f['coverage']):>9} "
                         f"{'n/a' if med is None else f'{med:.3f} mm':>10} "
                         f"{'n/a' if half is None else f'{half:.3f} mm':>11} "
                         f"{f['not_judged']:>9}")
        lines.append(f"{v:<{w}} astigmatism S-T: sign right {r['astig_sign_right']} of "
                     f"{r['astig_significant']} significant; interval coverage "
                     f"{_pct(r['astig_coverage'])}; median run {r['median_wall_s']:.1f} s")
        cme = r["curvature_median_abs_error"]
        lines.append(f"{'':<{w}} field curvature k: interval coverage "
                     f"{_pct(r['curvature_coverage'])}, median |error| "
                     f"{'n/a' if cme is None else f'{cme:.3f} mm/mm2'}")
    lines.append("")
    for name, t in out["timing"].items():
        lines.append(f"{name:<42} {t['wall_s']:6.1f} s  {t['frames']:4d} frames  best-focus "
                     f"coverage {_pct(t['best_focus_coverage'])}, median half-CI "
                     f"{t['best_focus_median_half_width_mm']:.3f} mm")
    return "\n".join(lines)
