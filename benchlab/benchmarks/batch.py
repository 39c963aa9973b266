"""``benchlab benchmark batch`` and ``benchmark catalog``: many-session figures.

Sessions for the benchmark are fabricated quickly: one real simulated MTF run (or ``--source``)
is copied N times (``session.json``, journal and results copied; frames hard-linked, which is
safe because frames are never modified and re-analysis verifies their hashes).
"""

from __future__ import annotations

import os
import resource
import shutil
import statistics
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from benchlab.catalog.index import CATALOG_FILE, Catalog


def make_source_session(root: Path) -> Path:
    """One real simulated Table 4.10 run (``benchlab run mtf --simulate --yes``)."""
    from benchlab.bench import Bench, BenchConfig
    from benchlab.protocols import start_run

    config = BenchConfig.load(None, simulate=True)
    with Bench.open(config, simulate=True) as bench:
        runner = start_run("mtf", bench=bench, root=root, operator="benchmark",
                           prompt=lambda step, msg: True, abort=threading.Event())
        return Path(runner.run().session_path)


def fabricate(source: Path, root: Path, n: int, *, link_frames: bool = True) -> list[Path]:
    """``n`` copies of ``source`` under ``root`` named ``<source>-NNNN``, sample ``proto-NNN``."""
    import json

    root.mkdir(parents=True, exist_ok=True)
    meta = json.loads((source / "session.json").read_text(encoding="utf-8"))
    out = []
    for i in range(n):
        dst = root / f"{source.name}-{i:04d}"
        dst.mkdir()
        (dst / "session.json").write_text(
            json.dumps({**meta, "sample": f"proto-{i:03d}"}, indent=2), encoding="utf-8")
        shutil.copy2(source / "events.jsonl", dst / "events.jsonl")
        shutil.copytree(source / "frames", dst / "frames",
                        copy_function=os.link if link_frames else shutil.copy2)
        shutil.copytree(source / "results", dst / "results")
        out.append(dst)
    return out


@contextmanager
def _count_fsyncs() -> Iterator[list[int]]:
    """Count the durability barriers: ``os.fsync`` calls and ``syncfs`` file-system flushes."""
    import benchlab.storage as storage_mod

    count = [0]
    real = os.fsync
    real_syncfs = storage_mod._syncfs

    def counting(fd: Any) -> None:
        count[0] += 1
        real(fd)

    def counting_syncfs(fd: int) -> bool:
        done = real_syncfs(fd)
        count[0] += int(done)
        return done

    os.fsync = counting  # type: ignore[assignment]
    storage_mod._syncfs = counting_syncfs
    try:
        yield count
    finally:
        os.fsync = real  # type: ignore[assignment]
        storage_mod._syncfs = real_syncfs


def fsync_comparison(sessions: list[Path], repeats: int) -> list[tuple[str, int, float, float]]:
    """Each results fsync policy on the same sessions, in this process, one at a time:
    ``(policy, fsyncs per re-analysis, min s, median s)``."""
    import benchlab.session.results as session_mod
    from benchlab.protocols.runs import reanalyze

    out = []
    saved = session_mod.RESULTS_FSYNC
    try:
        for policy in ("per-file", "per-version", "syncfs"):
            session_mod.RESULTS_FSYNC = policy
            times = []
            with _count_fsyncs() as count:
                for k in range(repeats):
                    t0 = time.perf_counter()
                    reanalyze(sessions[k % len(sessions)], new_version=True)
                    times.append(time.perf_counter() - t0)
            out.append((policy, count[0] // repeats, min(times), statistics.median(times)))
    finally:
        session_mod.RESULTS_FSYNC = saved
    return out


def run_batch_benchmark(
    *, n_sessions: int, jobs: int | None, source: str | None, workdir: str | None,
    link_frames: bool, fsync_repeats: int, say: Callable[[str], None],
) -> str:
    from benchlab.protocols.batch import run_batch, worker_memory_profile

    tmp = Path(tempfile.mkdtemp(prefix="benchlab-batch-", dir=workdir))
    try:
        t0 = time.perf_counter()
        if source:
            src = Path(source)
            how = f"--source {src}"
        else:
            with _count_fsyncs() as run_fsyncs:
                src = make_source_session(tmp / "source")
            how = (f"one simulated MTF run ({time.perf_counter() - t0:.1f} s, "
                   f"{run_fsyncs[0]} fsyncs)")
        say(f"source session: {how}")
        root = tmp / "sessions"
        t0 = time.perf_counter()
        paths = fabricate(src, root, n_sessions, link_frames=link_frames)
        fab_s = time.perf_counter() - t0
        say(f"fabricated {n_sessions} sessions in {fab_s:.1f} s "
            f"(frames {'hard-linked' if link_frames else 'copied'})")

        (root / CATALOG_FILE).unlink(missing_ok=True)
        t0 = time.perf_counter()
        with Catalog.open(root):  # a missing catalogue is rebuilt from the folders
            pass
        reindex_s = time.perf_counter() - t0
        say(f"reindex: {reindex_s:.2f} s")

        report = run_batch(paths, jobs=jobs)
        analysed = report.count("analysed")
        per_s = report.seconds / n_sessions
        worker_s = [i.seconds for i in report.items if i.outcome == "analysed"]
        cpu_s = [i.cpu_seconds for i in report.items if i.outcome == "analysed"]
        profile = worker_memory_profile(report)
        fs = fsync_comparison(paths, fsync_repeats) if fsync_repeats else []
        parent_kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    from benchlab.session import RESULTS_FSYNC as default_policy

    rows = [
        ("sessions", f"{n_sessions} ({analysed} analysed, {report.count('failed')} failed)"),
        ("executor", report.executor),
        ("batch wall time", f"{report.seconds:.2f} s  (target <= 25 s for 200)"),
        ("per session (wall / N)", f"{per_s * 1000:.0f} ms"),
        ("per session in a worker", f"median {statistics.median(worker_s) * 1000:.0f} ms, "
                                    f"min {min(worker_s) * 1000:.0f} ms"),
        ("CPU per session (worker)", f"median {statistics.median(cpu_s) * 1000:.0f} ms -> "
                                     f"{statistics.median(cpu_s) * n_sessions / report.jobs:.1f}"
                                     f" s for {n_sessions} on {report.jobs} idle cores"),
        ("extrapolated to 10,000", f"{per_s * 10_000 / 60:.1f} min at this wall rate; "
                                   f"{statistics.median(cpu_s) * 10_000 / report.jobs / 60:.1f}"
                                   f" min of CPU on {report.jobs} idle cores"),
        ("reindex of the catalogue", f"{reindex_s:.2f} s for {n_sessions} (target <= 10 s)"),
        ("worker peak RSS by quarter", ", ".join(f"{n}: {kib / 1024:.0f} MiB"
                                                 for n, kib in profile)),
        ("parent peak RSS", f"{parent_kib / 1024:.0f} MiB"),
    ]
    for policy, calls, lo, med in fs:
        chosen = " (default)" if policy == default_policy else ""
        rows.append((f"flush {policy}{chosen}", f"{calls} fsync/syncfs per re-analysis, min "
                                                f"{lo * 1000:.0f} ms, median {med * 1000:.0f} "
                                                "ms (1 process)"))
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)


def run_catalog_benchmark(*, n_sessions: int, source: str | None, repeats: int = 20) -> str:
    tmp = Path(tempfile.mkdtemp(prefix="benchlab-catalog-"))
    try:
        src = Path(source) if source else make_source_session(tmp / "source")
        root = tmp / "catalog"
        root.mkdir()
        t0 = time.perf_counter()
        _fill(root, n_sessions, src)
        fill_s = time.perf_counter() - t0
        with Catalog.open(root) as catalog:
            elements = {k[1] for k in catalog.figure_keys() if k[0] == "forward"}
        element = "G2E2" if "G2E2" in elements else min(elements)
        queries: list[tuple[str, str, dict[str, Any]]] = [
            ("list newest 50", "sessions", {"limit": 50}),
            ("list --sample proto-007", "sessions", {"sample": "proto-007"}),
            ("list --procedure mtf --since 2026-06-01 (all rows)", "sessions",
             {"procedure": "mtf", "since": "2026-06-01"}),
            ("trend --view forward --freq 70", "trend",
             {"view": "forward", "freq_lp_per_mm": 70.0}),
            (f"trend --view forward --element {element} --orientation S", "trend",
             {"view": "forward", "element": element, "orientation": "S"}),
        ]
        lines = [f"synthetic catalogue: {n_sessions} sessions, filled in {fill_s:.1f} s"]
        with Catalog.open(root) as catalog:
            n_fig = catalog.conn.execute("SELECT COUNT(*) FROM figures").fetchone()[0]
            size_mb = (root / CATALOG_FILE).stat().st_size / 1e6
            lines[0] += f", {n_fig} figure rows, {size_mb:.0f} MB"
            for label, fn, kwargs in queries:
                times = []
                for _ in range(repeats):
                    t0 = time.perf_counter()
                    rows = getattr(catalog, fn)(**kwargs)
                    times.append(time.perf_counter() - t0)
                lines.append(f"{label:<52} {len(rows):>6} rows  min {min(times) * 1000:6.1f} ms"
                             f"  median {statistics.median(times) * 1000:6.1f} ms")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    lines.append("(target: <= 100 ms per query over 10,000 sessions)")
    return "\n".join(lines)


def _fill(root: Path, n: int, source: Path) -> None:
    """``n`` catalogue rows made from one real session's record, figures varied -20..0 %."""
    import dataclasses
    import random

    from benchlab.catalog.extract import read_session_record

    base = read_session_record(source)
    rng = random.Random(0)

    def records() -> Iterator[Any]:
        for i in range(n):
            sid = f"synthetic-{i:05d}"
            yield dataclasses.replace(
                base, id=sid, path=str(root / sid), sample=f"proto-{i % 400:03d}",
                started_at=f"2026-{1 + i % 12:02d}-{1 + i % 28:02d}T{i % 24:02d}:{i % 60:02d}"
                ":00+00:00",
                figures=[dataclasses.replace(f, value=None if f.value is None
                                             else f.value * rng.uniform(0.8, 1.0))
                         for f in base.figures])

    with Catalog.open(root) as catalog:
        catalog.store(records())
