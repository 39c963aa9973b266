"""Helpers for the batch and catalogue tests (no tests here): one small real simulated MTF
session, and quick copies of it (frames hard-linked: they are never modified)."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

from sim_runs import MTF_SMALL, only_session

from benchlab.cli.main import main


def real_session(root: Path, sample: str = "LENS-7") -> Path:
    """``benchlab run mtf --simulate --yes --params mtf-small.toml --sample ...`` into root."""
    assert main(["run", "mtf", "--simulate", "--yes", "--out", str(root), "--params",
                 str(MTF_SMALL), "--sample", sample, "--operator", "ana"]) == 0
    return only_session(root)


def copy_session(source: Path, dst: Path, *, sample: str | None = None,
                 started_at: str | None = None) -> Path:
    """A copy of ``source`` at ``dst`` (journal, results and session.json copied)."""
    dst.mkdir(parents=True)
    meta = json.loads((source / "session.json").read_text())
    if sample is not None:
        meta["sample"] = sample
    if started_at is not None:
        meta["started_at"] = started_at
    (dst / "session.json").write_text(json.dumps(meta, indent=2))
    shutil.copy2(source / "events.jsonl", dst / "events.jsonl")
    shutil.copytree(source / "frames", dst / "frames", copy_function=os.link)
    shutil.copytree(source / "results", dst / "results")
    return dst


def results_files(version_dir: Path) -> dict[str, bytes]:
    """Every file of a results version; summary.json without its creation time."""
    out = {}
    for p in sorted(version_dir.iterdir()):
        data = p.read_bytes()
        if p.name == "summary.json":
            doc = json.loads(data)
            doc.pop("created_at")
            data = json.dumps(doc, sort_keys=True).encode()
        out[p.name] = data
    return out
