"""Imports point down only. The layers are written once, in pyproject's ``[tool.importlinter]``
contract (``lint-imports`` runs it in CI); this test reads the same list and checks every module's
imports with the AST, so a failure names the file and line."""

from __future__ import annotations

import ast
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _layers() -> dict[str, int]:
    """Package or module -> layer index, lowest first (from the import-linter contract)."""
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    (contract,) = config["tool"]["importlinter"]["contracts"]
    rank: dict[str, int] = {}
    for index, layer in enumerate(reversed(contract["layers"])):
        for name in layer.replace("|", ":").split(":"):
            rank[name.strip()] = index
    return rank


LAYER = _layers()


def _layer(module: str) -> int | None:
    best, depth = None, -1
    for prefix, layer in LAYER.items():
        if (module == prefix or module.startswith(prefix + ".")) and prefix.count(".") > depth:
            best, depth = layer, prefix.count(".")
    return best


def upward_imports(module: str, source: str) -> list[str]:
    """``line N: name`` for each import of ``source`` that points to a higher layer."""
    own = _layer(module)
    if own is None:
        return []
    found = []
    for node in ast.walk(ast.parse(source)):
        names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                 else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
        for name in names:
            layer = _layer(name)
            if layer is not None and layer > own:
                found.append(f"line {node.lineno}: {name}")
    return found


def _sources() -> list[tuple[str, Path]]:
    out = []
    for folder, package in ((ROOT / "drivers", "benchlab.drivers"),
                            (ROOT / "protocols", "benchlab.protocols"),
                            (ROOT / "benchlab", "benchlab")):
        for p in sorted(folder.rglob("*.py")):
            rel = p.relative_to(folder).with_suffix("").parts
            if package == "benchlab" and rel[0] in ("drivers", "protocols"):
                continue  # the symlinks to the folders above
            out.append((".".join((package, *rel)).removesuffix(".__init__"), p))
    return out


def test_every_package_is_in_a_layer() -> None:
    top = {m.split(".")[1] for m, _ in _sources() if m.count(".") >= 1}
    unplaced = {t for t in top if _layer(f"benchlab.{t}") is None}
    assert not unplaced, f"add these to the layers contract in pyproject.toml: {unplaced}"
    assert len(_sources()) > 150


def test_an_upward_import_is_found() -> None:
    probe = "import numpy\nfrom benchlab.session import Session\n"
    assert upward_imports("benchlab.analysis.bars.roi", probe) == ["line 2: benchlab.session"]
    assert upward_imports("benchlab.cli.frames.sfr", probe) == []


@pytest.mark.parametrize(("module", "path"), _sources(), ids=lambda v: str(v))
def test_imports_point_down(module: str, path: Path) -> None:
    upward = upward_imports(module, path.read_text(encoding="utf-8"))
    assert not upward, f"{module} ({path}) imports a higher layer: {upward}"
