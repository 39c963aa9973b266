"""pyproject lists the packages explicitly (``drivers/`` and ``protocols/`` install under
``benchlab.``); a package folder missing from the list would be left out of a wheel while an
editable install still finds it."""

from __future__ import annotations

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _listed() -> tuple[set[str], dict[str, str]]:
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    tool = config["tool"]["setuptools"]
    return set(tool["packages"]), dict(tool["package-dir"])


def _on_disk(package_dir: dict[str, str]) -> set[str]:
    found = set()
    for name, folder in package_dir.items():
        base = ROOT / folder
        for init in base.rglob("__init__.py"):
            rel = init.parent.relative_to(base)
            found.add(".".join((name, *rel.parts)) if rel.parts else name)
    return found


def test_every_package_folder_is_listed_and_every_listed_one_exists() -> None:
    listed, package_dir = _listed()
    on_disk = _on_disk(package_dir)
    assert on_disk - listed == set(), "add these to [tool.setuptools] packages"
    assert listed - on_disk == set(), "these listed packages have no __init__.py"
    assert {"benchlab.drivers.trace", "benchlab.cli.runs", "benchlab.benchmarks.sfr"} <= listed
