"""``benchlab benchmark fov``: the field-of-view procedure against the simulator's truth.

Each (lens variant, seed) is a whole simulated ``benchlab run fov`` (default parameters, the
variant's ``[simulator]`` values over them, the camera's noise seeded). Every figure of the
results is compared with ``simulator_truth``: bias, RMSE, the largest error and the share of
95 % intervals that cover the truth, per variant and over all of them, against the issue's
targets (field of view 0.5 deg, direction of view 0.3 deg, entrance pupil 0.3 mm, image height
0.01 mm at every point; the radial field's start and end 0.2 mm along the wall; coverage
90-98 %). The radial view (the ring tube through the ray-trace table) is the same in every
variant: the variants are the forward lens's. So each variant takes its own seeds
(:func:`seed_of`): the radial rows over all variants are variants x seeds independent runs, not
the same seeds' runs repeated.
"""

from __future__ import annotations

import json
import math
import tempfile
import time
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

#: Lens variants: ``[simulator]`` values over the defaults (an equidistant f = 2.83 mm lens,
#: pupil 2 mm behind the front, no tilt).
VARIANTS: dict[str, dict[str, float]] = {
    "nominal": {},
    "no-distortion": {"barrel": 0.0},
    "strong-barrel": {"barrel": 2.0},
    "tilted": {"tilt_deg": 3.0, "tilt_azimuth_deg": 40.0},
    "shifted-pupil": {"entrance_pupil_mm": 5.0},
}
#: The issue's accuracy targets (largest error allowed), per figure; None: none set.
TARGETS: dict[str, float | None] = {
    "full_fov_deg": 0.5, "direction_of_view_deg": 0.3, "entrance_pupil_mm": 0.3,
    "paraxial_focal_length_mm": None, "image_height_mm": 0.01,
    "distortion_rectilinear_pct": None, "distortion_equidistant_pct": None,
    "radial_field_start_mm": 0.2, "radial_field_end_mm": 0.2, "radial_field_start_deg": None,
    "radial_field_end_deg": None, "radial_fov_deg": None, "radial_inner_radius_mm": None,
    "radial_outer_radius_mm": None, "radial_image_height_mm": 0.01,
}
COVERAGE_RANGE = (0.90, 0.98)


def seed_of(variant: str, k: int) -> int:
    """The camera's seed of a variant's ``k``-th run: a block of 1000 per variant (in
    :data:`VARIANTS`' order, whichever variants are run), so no two runs share their noise."""
    return 1000 * (list(VARIANTS).index(variant) + 1) + k


def run_once(variant: str, seed: int, root: Path) -> tuple[Path, float, dict[str, Any]]:
    """One simulated run; returns (results folder, wall s, its summary)."""
    from benchlab.bench import Bench, BenchConfig
    from benchlab.protocols import load_params, start_run
    from benchlab.protocols.params import params_to_dict, parse_params

    config = BenchConfig.load(None, simulate=True)
    base = params_to_dict(load_params("fov", None, config.limits()))
    base["simulator"] = {**base["simulator"], **VARIANTS[variant]}
    params = parse_params("fov", base, f"<benchmark {variant}>", config.limits())
    t0 = time.perf_counter()
    with Bench.open(config, simulate=True, seed=seed) as bench:
        runner = start_run("fov", bench=bench, params=params, root=root, operator="bench",
                           prompt=lambda step, msg: True)
        outcome = runner.run()
    wall = time.perf_counter() - t0
    summary = json.loads((outcome.results_path / "summary.json").read_text())
    summary = summary.get("summary", summary)  # the procedure's own part
    return outcome.results_path, wall, summary


def _load(results: Path, name: str) -> list[dict[str, Any]]:
    rows: list[dict[str, Any]] = json.loads((results / f"{name}.json").read_text())
    return rows


def compare(results: Path) -> list[dict[str, Any]]:
    """Every figure of one results version against its truth: ``{"figure", "key", "error",
    "covered"}`` rows."""
    truth: dict[tuple[str, Any], float] = {
        (t["table"], t["key"]): float(t["value"]) for t in _load(results, "simulator_truth")}
    out: list[dict[str, Any]] = []

    def add(figure: str, key: Any, value: Any, ci: Any, true: float | None) -> None:
        if true is None or value is None or ci is None:
            return
        out.append({"figure": figure, "key": key, "error": float(value) - true,
                    "covered": float(ci[0]) <= true <= float(ci[1])})

    for r in _load(results, "field_of_view"):
        add(r["quantity"], "", r["value"], r["value_ci95"],
            truth.get(("field_of_view", r["quantity"])))
    edge = next(r["value"] for r in _load(results, "field_of_view")
                if r["quantity"] == "full_fov_deg") / 2.0
    for r in _load(results, "image_height_mapping"):
        a = r["field_angle_deg"]
        if r.get("view", "forward") == "radial":
            add("radial_image_height_mm", a, r["image_height_mm"], r["image_height_mm_ci95"],
                truth.get(("radial_image_height_mapping", f"{a:g}")))
        elif 0 < a <= edge:
            add("image_height_mm", a, r["image_height_mm"], r["image_height_mm_ci95"],
                truth.get(("image_height_mapping", f"{a:g}")))
    for r in _load(results, "distortion"):
        a = r["field_angle_deg"]
        if a <= edge:
            for model in ("rectilinear", "equidistant"):
                add(f"distortion_{model}_pct", a, r[f"{model}_pct"], r[f"{model}_pct_ci95"],
                    truth.get((f"distortion_{model}", f"{a:g}")))
    return out


def summarise(comps: Iterable[Mapping[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per figure: n, bias, RMSE, largest error, coverage, and whether the target is met."""
    by: dict[str, list[Mapping[str, Any]]] = {}
    for c in comps:
        by.setdefault(c["figure"], []).append(c)
    out = {}
    for figure in TARGETS:
        rows = by.get(figure, [])
        if not rows:
            continue
        errs = [float(r["error"]) for r in rows]
        worst = max(abs(e) for e in errs)
        target = TARGETS[figure]
        out[figure] = {"n": len(rows), "bias": sum(errs) / len(errs),
                       "rmse": math.sqrt(sum(e * e for e in errs) / len(errs)),
                       "max_abs_error": worst,
                       "coverage": sum(bool(r["covered"]) for r in rows) / len(rows),
                       "target": target, "within_target": None if target is None
                       else worst <= target}
    return out


def run_benchmark(seeds: int = 20, variants: Iterable[str] = tuple(VARIANTS),
                  keep: Path | None = None, progress: Any = None) -> dict[str, Any]:
    """Every (variant, seed) run compared, per variant and over all."""
    out: dict[str, Any] = {"seeds": seeds, "variants": {}, "all": {}}
    every: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        root = keep if keep is not None else Path(tmp)
        for v in variants:
            comps: list[dict[str, Any]] = []
            walls = []
            summary: dict[str, Any] = {}
            for s in range(seeds):
                results, wall, summary = run_once(v, seed_of(v, s), root / v)
                walls.append(wall)
                comps += compare(results)
                if progress is not None:
                    progress(f"{v} seed {s}: {wall:.1f} s")
            every += comps
            out["variants"][v] = {"figures": summarise(comps),
                                  "median_wall_s": sorted(walls)[len(walls) // 2],
                                  "frames_per_distance": summary.get("frames_per_distance"),
                                  "distances_mm": summary.get("distances_mm"),
                                  "stage_travel_mm": summary.get("stage_travel_mm"),
                                  "radial_positions_mm": summary.get("radial_positions_mm")}
    out["all"] = summarise(every)
    return out


def _figure_lines(figs: Mapping[str, Mapping[str, Any]]) -> list[str]:
    lines = []
    lo, hi = COVERAGE_RANGE
    for name, f in figs.items():
        target = "" if f["target"] is None else f"{f['target']:g}"
        met = "" if f["within_target"] is None else ("yes" if f["within_target"] else "NO")
        cov_ok = "" if lo <= f["coverage"] <= hi else " (outside 90-98 %)"
        lines.append(f"  {name:<28} {f['n']:>5} {f['bias']:>+11.5f} {f['rmse']:>10.5f} "
                     f"{f['max_abs_error']:>10.5f} {target:>7} {met:>4} "
                     f"{100 * f['coverage']:>6.1f} %{cov_ok}")
    return lines


def format_benchmark(out: Mapping[str, Any]) -> str:
    """The benchmark's table as text."""
    head = (f"  {'figure':<28} {'n':>5} {'bias':>11} {'RMSE':>10} {'max |err|':>10} "
            f"{'target':>7} {'met':>4} {'cover95':>8}")
    lines = [f"benchlab run fov against the simulator's truth: {out['seeds']} seeds per variant"]
    for v, res in out["variants"].items():
        lines.append("")
        lines.append(f"{v} ({json.dumps(VARIANTS.get(v, {}))}): median run "
                     f"{res['median_wall_s']:.1f} s, {res['frames_per_distance']} frames at "
                     f"each of {res['distances_mm']} mm, stage travel "
                     f"{res['stage_travel_mm']:g} mm"
                     + (f"; the ring tube at {res['radial_positions_mm']} mm"
                        if res.get("radial_positions_mm") else ""))
        lines.append(head)
        lines += _figure_lines(res["figures"])
    lines.append("")
    lines.append("all variants")
    lines.append(head)
    lines += _figure_lines(out["all"])
    return "\n".join(lines)
