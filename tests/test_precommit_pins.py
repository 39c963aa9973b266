"""The pre-commit hooks run the lint and type tools at the versions pyproject pins for CI."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]


def _pins() -> dict[str, str]:
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"][
        "optional-dependencies"]["test"]
    pins = (re.fullmatch(r"([A-Za-z0-9_.-]+)==(\S+)", spec) for spec in extras)
    return {m.group(1).lower(): m.group(2) for m in pins if m}


def _hooks() -> dict[str, tuple[str, dict[str, object]]]:
    config = yaml.safe_load((ROOT / ".pre-commit-config.yaml").read_text())
    return {hook["id"]: (repo.get("rev", ""), hook)
            for repo in config["repos"] for hook in repo["hooks"]}


def test_ruff_hook_is_the_pinned_ruff() -> None:
    rev, _ = _hooks()["ruff-check"]
    assert rev == "v" + _pins()["ruff"]


def test_mypy_and_lint_imports_run_the_project_environment_pins() -> None:
    hooks, pins = _hooks(), _pins()
    for hook_id, package in (("mypy", "mypy"), ("lint-imports", "import-linter")):
        _, hook = hooks[hook_id]
        # The environment's tool is the one pyproject pins (`pip install -e ".[test]"`).
        assert hook["language"] == "system" and hook["entry"] == hook_id
        assert package in pins
    assert f"mypy=={pins['mypy']}" in str(hooks["mypy"][1]["name"])
