"""Start-up: a command imports only what it uses (issue 11), with the public API unchanged;
the startup benchmark's bytecode environments; the curve file parsed once per process."""

from __future__ import annotations

import ast
import importlib
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import benchlab.analysis as analysis_pkg
from benchlab.analysis.mtf.compare import SimulatedCurve


def _modules_after(code: str) -> set[str]:
    """Module names loaded by a fresh interpreter after running ``code``."""
    done = subprocess.run(
        [sys.executable, "-c", f"{code}; import sys; print('\\n'.join(sys.modules))"],
        capture_output=True, text=True, check=True)
    return set(done.stdout.split())


def test_every_public_analysis_name_resolves_to_its_module() -> None:
    """Each name of the stub is the object its defining module holds (no second copy)."""
    stub = ast.parse((Path(analysis_pkg.__file__).parent / "__init__.pyi").read_text())
    exported = {}
    for node in stub.body:
        if isinstance(node, ast.ImportFrom):
            for alias in node.names:
                exported[alias.name] = f"benchlab.analysis.{node.module}"
    assert len(exported) > 40
    assert sorted(analysis_pkg.__all__) == sorted(exported)
    for name, module in exported.items():
        defined = getattr(importlib.import_module(module), name)
        assert getattr(analysis_pkg, name) is defined, name
    assert set(analysis_pkg.__all__) <= set(dir(analysis_pkg))
    with pytest.raises(AttributeError, match="no_such_name"):
        analysis_pkg.no_such_name  # noqa: B018
    # a submodule is still importable through the package
    from benchlab.analysis.bars import histogram

    assert histogram.__name__ == "benchlab.analysis.bars.histogram"


def test_importing_the_analysis_package_loads_no_submodule() -> None:
    loaded = _modules_after("import benchlab.analysis")
    assert not {m for m in loaded if m.startswith("benchlab.analysis.")}
    assert "numpy" not in loaded
    loaded = _modules_after("from benchlab.analysis import usaf_frequency_lp_per_mm")
    assert "benchlab.analysis.mtf.frequency" in loaded
    assert "benchlab.analysis.bars.estimators" not in loaded


def test_reanalysing_an_mtf_session_loads_no_other_procedure() -> None:
    loaded = _modules_after(
        "from benchlab.protocols.runs import make_procedure; "
        "from benchlab.protocols.params import load_params; "
        "make_procedure(load_params('mtf'))")
    assert "benchlab.protocols.mtf.steps" in loaded
    for other in ("benchlab.protocols.radiometry", "benchlab.protocols.characterise.steps",
                  "benchlab.protocols.characterise.analysis",
                  "benchlab.analysis.camera.photon_transfer",
                  "benchlab.scenes"):
        assert other not in loaded, other


def test_each_procedure_is_made_on_demand() -> None:
    from benchlab.protocols.characterise.steps import CharacteriseProcedure
    from benchlab.protocols.mtf.steps import MtfProcedure
    from benchlab.protocols.params import load_params
    from benchlab.protocols.radiometry import RadiometryProcedure
    from benchlab.protocols.runs import make_procedure

    assert isinstance(make_procedure(load_params("mtf")), MtfProcedure)
    assert isinstance(make_procedure(load_params("radiometry")), RadiometryProcedure)
    assert isinstance(make_procedure(load_params("characterise")), CharacteriseProcedure)


def test_the_bar_model_does_not_import_scipy_special() -> None:
    loaded = _modules_after("import benchlab.analysis.bars.model")
    assert "scipy.special" not in loaded  # imported where an edge is blurred (s > 0) only


def test_startup_benchmark_environments(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from benchlab.cli.startup import bytecode_environments

    monkeypatch.setenv("PYTHONDONTWRITEBYTECODE", "1")
    monkeypatch.setenv("PYTHONPYCACHEPREFIX", "/somewhere/else")
    envs = bytecode_environments(tmp_path / "pyc")
    assert "PYTHONDONTWRITEBYTECODE" not in envs["cached"]
    assert envs["cached"]["PYTHONPYCACHEPREFIX"] == str(tmp_path / "pyc")
    assert envs["no .pyc"]["PYTHONDONTWRITEBYTECODE"] == "1"
    assert "PYTHONPYCACHEPREFIX" not in envs["no .pyc"]
    assert envs["cached"]["PATH"] == os.environ["PATH"]
    # the cached environment really writes and reuses bytecode in that folder only
    code = [sys.executable, "-c", "import benchlab.cli.startup"]
    subprocess.run(code, env=envs["cached"], check=True)
    assert list((tmp_path / "pyc").rglob("startup*.pyc"))


def test_repeats_below_one_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    from benchlab.cli.main import main

    assert main(["benchmark", "startup", "--repeats", "0"]) == 2
    assert "--repeats must be >= 1" in capsys.readouterr().err


def test_curve_file_is_parsed_once_until_it_changes(tmp_path: Path,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    import benchlab.protocols.mtf.curves as rc

    parsed: list[Path] = []
    real = rc._parse_curves

    def counting(p: Path) -> list[SimulatedCurve]:
        parsed.append(p)
        return real(p)

    monkeypatch.setattr(rc, "_parse_curves", counting)
    rc._cached_curves.cache_clear()
    path = tmp_path / "curves.json"
    path.write_text(rc.default_curves_path().read_text(encoding="utf-8"), encoding="utf-8")
    first = rc.load_curves(path)
    second = rc.load_curves(path)
    assert len(parsed) == 1 and len(first) > 0
    assert [c.view for c in first] == [c.view for c in second]
    assert all(np.array_equal(a.mtf, b.mtf) for a, b in zip(first, second, strict=True))
    with pytest.raises(ValueError, match="read-only"):
        first[0].mtf[0] = 0.0  # a caller cannot change what the next one gets
    text = path.read_text(encoding="utf-8").replace('"view": "forward"', '"view": "radial"', 1)
    path.write_text(text, encoding="utf-8")
    os.utime(path, ns=(path.stat().st_atime_ns, path.stat().st_mtime_ns + 10**9))
    third = rc.load_curves(path)
    assert len(parsed) == 2
    assert [c.view for c in third].count("radial") == [c.view for c in first].count("radial") + 1
    with pytest.raises(FileNotFoundError):
        rc.load_curves(tmp_path / "missing.toml")


def test_startup_spread_is_median_quartiles_and_range() -> None:
    from benchlab.cli.startup import spread

    assert spread([5.0, 1.0, 4.0, 2.0, 3.0]) == (3.0, 2.0, 4.0, 1.0, 5.0)
    assert spread([0.7]) == (0.7, 0.7, 0.7, 0.7, 0.7)
    with pytest.raises(ValueError, match="no values"):
        spread([])


@pytest.mark.slow
def test_startup_benchmark_interleaves_two_installs(tmp_path: Path) -> None:
    """Each round runs each command once per install, the order reversed every other round;
    the warm-up round (cached bytecode only) is not counted; the ratio of medians is printed."""
    from benchlab.cli.startup import THIS, bytecode_environments, format_timings, interleaved

    log = tmp_path / "order.txt"
    session = tmp_path / "s"
    session.mkdir()
    (session / "session.json").write_text("{}", encoding="utf-8")

    def program(name: str) -> list[str]:  # logs its name and the command it was given
        code = ("import sys; open(sys.argv[1], 'a').write("
                f"{name!r} + ' ' + sys.argv[2] + chr(10))")
        return [sys.executable, "-c", code, str(log)]

    envs = bytecode_environments(tmp_path / "pyc")
    times = interleaved({THIS: program("A"), "old": program("B")}, session, 2, envs)
    runs = log.read_text(encoding="utf-8").split("\n")[:-1]
    assert runs == (["A --help", "B --help", "A analyze", "B analyze"]  # warm-up
                    + ["B --help", "A --help", "B analyze", "A analyze"] * 2  # round 1
                    + ["A --help", "B --help", "A analyze", "B analyze"] * 2)  # round 2
    assert sorted(times) == sorted((c, how, n) for c in ("--help", "analyze SESSION")
                                   for how in ("cached", "no .pyc") for n in (THIS, "old"))
    assert all(len(t.wall) == len(t.cpu) == 2 for t in times.values())
    table = format_timings(times, 2)
    assert "analyze SESSION (cached): this / old median wall = " in table
    assert table.count("median wall =") == 4


def test_startup_benchmark_times_the_command_a_user_types() -> None:
    """The ``benchlab`` script beside the interpreter (as pip installs it), not ``-m``."""
    from benchlab.cli.startup import this_program

    script = Path(sys.executable).parent / "benchlab"
    expected = [str(script)] if script.is_file() else [sys.executable, "-m", "benchlab.cli.main"]
    assert this_program() == expected


def test_startup_benchmark_refuses_a_missing_other_install(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from benchlab.cli.main import main

    missing = str(tmp_path / "nowhere" / "benchlab")
    assert main(["benchmark", "startup", "--against", missing]) == 2
    assert f"--against {missing}: not an executable benchlab command" in capsys.readouterr().err
    assert main(["benchmark", "startup", "--against", sys.executable,
                 "--against-label", "this"]) == 2
    assert "'this' names this install" in capsys.readouterr().err
