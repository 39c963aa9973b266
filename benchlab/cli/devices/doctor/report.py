"""The bring-up's outputs: the report (``bringup-report.md``) and what it learned, written
into the bench file after a backup."""

from __future__ import annotations

import shutil
import tomllib
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

#: Check results, in the report's words.
STATUSES = ("ok", "FAIL", "warn", "skip")


@dataclass
class Check:
    step: str
    status: str  # one of STATUSES
    detail: str
    todo: str = ""


@dataclass
class RunSummary:
    """What the report says besides the checks."""

    source: str
    simulate: bool
    injections: dict[str, str]
    learned: dict[tuple[str, str], Any]
    cassette: str | None
    replayed_from: str | None = None
    interrupted: str | None = None
    current_step: str | None = None


def toml_literal(key: str, value: str | float | list[int]) -> str:
    """``value`` as TOML: strings quoted, USB ids in hex, other ints plain, floats as floats,
    lists of ints as arrays."""
    if isinstance(value, list):
        return "[" + ", ".join(str(int(v)) for v in value) + "]"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, int) and not isinstance(value, bool):
        return f"0x{value:04X}" if key.endswith("pid") else str(value)
    return repr(float(value))


def set_toml_key(text: str, section: str, key: str, value: str | float | list[int]) -> str:
    """``text`` with ``key = value`` in ``[section]`` (replaced, or added after the header)."""
    literal = toml_literal(key, value)
    lines = text.splitlines()
    header = f"[{section}]"
    try:
        start = next(i for i, ln in enumerate(lines) if ln.strip() == header)
    except StopIteration:
        return text.rstrip("\n") + f"\n\n{header}\n{key} = {literal}\n"
    end = next((i for i in range(start + 1, len(lines)) if lines[i].lstrip().startswith("[")),
               len(lines))
    for i in range(start + 1, end):
        if lines[i].split("=", 1)[0].strip() == key:
            lines[i] = f"{key} = {literal}"
            break
    else:
        lines.insert(start + 1, f"{key} = {literal}")
    return "\n".join(lines) + "\n"


def write_learned(path: Path, learned: dict[tuple[str, str], Any]) -> Path | None:
    """Write what the doctor learned into the bench file, after a backup; the new text must
    still be a valid bench file, else nothing is written. Returns the backup's path."""
    from benchlab.bench import BenchConfig

    if not learned:
        return None
    text = path.read_text(encoding="utf-8")
    new = text
    for (section, key), value in learned.items():
        new = set_toml_key(new, section, key, value)
        if (section, key) == ("stage", "actuator"):  # the actuator sets the scale
            new = "\n".join(ln for ln in new.splitlines()
                            if ln.split("=", 1)[0].strip() != "counts_per_mm") + "\n"
    BenchConfig.from_dict(tomllib.loads(new), str(path))  # raises: nothing written
    backup = path.with_name(f"{path.name}.bak-{datetime.now(UTC):%Y%m%dT%H%M%S}")
    shutil.copy2(path, backup)
    path.write_text(new, encoding="utf-8")
    return backup


def _cell(text: str) -> str:
    return text.replace("|", "/").replace("\n", " ")


def report_markdown(checks: list[Check], run: RunSummary) -> str:
    """The report: what was checked, what differs from what benchlab assumed (one line each,
    with what to put in the bench file) and which file to send back."""
    fails = [c for c in checks if c.status == "FAIL"]
    out = [f"# Bench bring-up report ({datetime.now(UTC):%Y-%m-%d %H:%M} UTC)", "",
           f"Bench file: {run.source}{' (simulated bench)' if run.simulate else ''}."]
    if run.replayed_from:
        out.append(f"Replayed from the recording {run.replayed_from} (no devices).")
    if run.injections:
        out.append("Injected faults: " + "; ".join(f"{k} ({v})"
                                                     for k, v in run.injections.items()) + ".")
    if run.interrupted:
        out += ["", f"**Interrupted** ({run.interrupted}) during "
                    f"{run.current_step or 'the start'}: the checks below are those done so far."]
    verdict = ("every check ok" if not fails and not run.interrupted
               else f"{len(fails)} check(s) failed" if fails else "no check failed so far")
    counts = ", ".join(f"{n} {s}" for s in STATUSES
                       if (n := sum(c.status == s for c in checks)))
    out += ["", f"Result: {verdict} ({counts}).", ""]
    if fails:
        out += ["## What differs from what benchlab assumed", ""]
        out += [f"- **{c.step}**: {_cell(c.detail)}" + (f" -> {_cell(c.todo)}" if c.todo else "")
                for c in fails]
        out.append("")
    out += ["## Checks", "", "| step | result | detail | what to do |", "|---|---|---|---|"]
    for c in sorted(checks, key=lambda c: c.step.split(" ", 1)[0]):  # in step order
        out.append("| " + " | ".join(_cell(x) for x in (c.step, c.status, c.detail, c.todo))
                   + " |")
    if run.learned:
        out += ["", "Learned (written to the bench file when one was given with --config):", ""]
        out += [f"- [{s}] {k} = {toml_literal(k, v)}" for (s, k), v in run.learned.items()]
    if run.cassette:
        out += ["", "## What to send back", "",
                f"This report and the recording `{run.cassette}` (every device exchange of "
                "this run; `benchlab doctor --replay` on it reproduces the run byte for byte)."]
    return "\n".join(out) + "\n"
