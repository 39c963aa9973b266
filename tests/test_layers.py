"""The import rules are import-linter contracts in pyproject's ``[tool.importlinter]``;
``lint-imports`` checks them in CI and names the file and line of a broken one. These tests
check that every package is placed in the layers and that each contract really fails when it
is broken: a violation of each is planted in a copy of the package."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
CONFIG = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
CONTRACTS: list[dict[str, Any]] = CONFIG["tool"]["importlinter"]["contracts"]

#: One planted module per contract type: (file in the package, its source). Each breaks its
#: contract and no other rule of the same contract type.
PLANTS: dict[str, tuple[str, str]] = {
    "layers": ("analysis/planted_upward.py", "import benchlab.session\n"),
    "independence": ("protocols/depth/planted_sibling.py", "import benchlab.protocols.mtf.edges\n"),
    "forbidden": ("session/planted_simulator.py", "import benchlab.scenes.edge\n"),
}


def _layer_names() -> set[str]:
    (layers,) = [c for c in CONTRACTS if c["type"] == "layers"]
    return {name.strip() for layer in layers["layers"]
            for name in layer.replace("|", ":").split(":")}


def test_every_package_is_in_a_layer() -> None:
    top = {p.stem if p.is_file() else p.name
           for p in (ROOT / "benchlab").iterdir()
           if (p.suffix == ".py" and p.stem != "__init__") or (p / "__init__.py").exists()}
    placed = {name.removeprefix("benchlab.") for name in _layer_names()}
    assert len(top) > 15
    assert not top - placed, f"add these to the layers contract in pyproject.toml: {top - placed}"


def test_every_contract_type_has_a_plant() -> None:
    assert {c["type"] for c in CONTRACTS} <= set(PLANTS)
    assert len(CONTRACTS) >= 3


def test_each_contract_fails_on_a_planted_violation(tmp_path: Path) -> None:
    # A copy with the symlinked drivers/ and protocols/ folders resolved, as installed.
    package = tmp_path / "benchlab"
    shutil.copytree(ROOT / "benchlab", package,
                    ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    for rel, source in PLANTS.values():
        (package / rel).write_text(source, encoding="utf-8")
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    env = {**os.environ, "PYTHONPATH": str(tmp_path)}
    lint = Path(sys.executable).with_name("lint-imports")
    out = subprocess.run([str(lint), "--no-cache"], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=110)
    text = " ".join(out.stdout.split())  # the report wraps long lines
    assert out.returncode == 1, text[-2000:]
    for contract in CONTRACTS:
        assert f"{' '.join(contract['name'].split())} BROKEN" in text, contract["name"]
        rel = PLANTS[contract["type"]][0]
        planted = "benchlab." + rel.removesuffix(".py").replace("/", ".")
        assert planted in text, (contract["name"], planted)
    assert f"Contracts: 0 kept, {len(CONTRACTS)} broken." in text
