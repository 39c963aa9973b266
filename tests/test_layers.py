"""Imports point down only: tui/cli -> protocols -> session/bench -> scenes -> analysis
-> drivers."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: Layer of each package or module, lowest first.
LAYER = {
    "benchlab.drivers": 0, "benchlab.analysis": 1, "benchlab.scenes": 2,
    "benchlab.checks": 3, "benchlab.storage": 3, "benchlab.session": 3, "benchlab.bench": 3,
    "benchlab.tiff_strips": 3, "benchlab.forked": 3,
    "benchlab.protocols": 4, "benchlab.cli": 5, "benchlab.tui": 5,
}


def _layer(module: str) -> int | None:
    best = None
    for prefix, layer in LAYER.items():
        if module == prefix or module.startswith(prefix + "."):
            best = layer
    return best


def _sources() -> list[tuple[str, Path]]:
    out = []
    for folder, package in ((ROOT / "drivers", "benchlab.drivers"),
                            (ROOT / "protocols", "benchlab.protocols")):
        out += [(f"{package}.{p.stem}", p) for p in sorted(folder.glob("*.py"))]
    for p in sorted((ROOT / "benchlab").rglob("*.py")):
        rel = p.relative_to(ROOT).with_suffix("")
        if rel.parts[1] in ("drivers", "protocols"):
            continue  # the symlinks to the folders above
        out.append((".".join(rel.parts), p))
    return out


@pytest.mark.parametrize(("module", "path"), _sources(), ids=lambda v: str(v))
def test_imports_point_down(module: str, path: Path) -> None:
    own = _layer(module)
    if own is None:
        return  # top-level helpers outside the layer map (report, __init__)
    tree = ast.parse(path.read_text(encoding="utf-8"))
    upward = []
    for node in ast.walk(tree):
        names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                 else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
        for name in names:
            layer = _layer(name)
            if layer is not None and layer > own:
                upward.append(f"line {node.lineno}: {name}")
    assert not upward, f"{module} imports a higher layer: {upward}"
