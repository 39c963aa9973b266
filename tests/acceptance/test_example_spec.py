"""The packaged example spec (``benchlab verify --example-spec``, shown on docs/formats/spec.md)
reads the real tables: on a simulated MTF session it passes (the README's path, issue 38), and
with its commented camera limits switched on, on an MTF and a characterisation session of one
unit, every one of its limits finds its rows and is decided."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import pytest
from sim_runs import FIXTURES, MTF_SMALL, run_sim

from benchlab.acceptance.spec import load_spec
from benchlab.cli.main import main

ROOT = Path(__file__).resolve().parents[2]
CAM_SMALL = FIXTURES / "characterise-small.toml"


def test_example_spec_is_printed_as_packaged(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["verify", "--example-spec"]) == 0
    text = capsys.readouterr().out
    assert text == (ROOT / "benchlab" / "acceptance" / "example-spec.toml").read_text()
    assert [lim["id"] for lim in tomllib.loads(text)["limit"]] == [
        "fwd-G2E2-S", "mtf50-centre", "avg-70"]
    assert [lim["id"] for lim in tomllib.loads(with_camera_limits(text))["limit"]] == [
        "fwd-G2E2-S", "mtf50-centre", "avg-70", "system-gain", "read-noise"]
    # The docs page includes the file itself, not a copy.
    assert '--8<-- "benchlab/acceptance/example-spec.toml"' in (
        ROOT / "docs" / "formats" / "spec.md").read_text()


def test_verify_without_sessions_or_spec_is_a_usage_error(
    capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["verify"]) == 2
    assert "give SESSION... and --spec FILE" in capsys.readouterr().err
    assert main(["verify", "some-session"]) == 2
    assert main(["verify", "--example-spec", "--spec", "x.toml"]) == 2
    assert "--example-spec prints the example and takes no SESSION" in capsys.readouterr().err


def with_camera_limits(text: str) -> str:
    """The example with its commented camera limits switched on, as its comment says."""
    head, camera = text.split("# Camera limits", 1)
    lines = camera.splitlines()[1:]
    return head + "\n".join(line[2:] if line.startswith("# ") else "" for line in lines) + "\n"


@pytest.mark.slow
def test_the_example_spec_passes_an_mtf_session_as_the_readme_shows(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """README: ``verify --example-spec > spec.toml``, then ``verify "$S" --spec spec.toml``
    on the MTF session it made: every limit is decided on that session alone, and it passes."""
    assert main(["verify", "--example-spec"]) == 0
    spec = tmp_path / "spec.toml"
    spec.write_text(capsys.readouterr().out)
    small = tmp_path / "mtf.toml"  # the element the example limits
    small.write_text(MTF_SMALL.read_text().replace('["G1E5", "G2E1"]', '["G2E2"]'))
    mtf = run_sim("mtf", tmp_path / "s", small).session_path
    assert main(["verify", str(mtf), "--spec", str(spec)]) == 0
    out = capsys.readouterr().out
    assert "unit verdict: PASS" in out and "indeterminate" not in out


@pytest.mark.slow
def test_every_example_limit_is_decided_on_simulated_sessions(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["verify", "--example-spec"]) == 0
    spec = tmp_path / "spec.toml"
    spec.write_text(with_camera_limits(capsys.readouterr().out))
    load_spec(spec)
    small = tmp_path / "mtf.toml"  # the element the example limits
    small.write_text(MTF_SMALL.read_text().replace('["G1E5", "G2E1"]', '["G2E2"]'))
    mtf = run_sim("mtf", tmp_path / "s", small, sample="OBJ-1").session_path
    cam = run_sim("characterise", tmp_path / "s", CAM_SMALL, sample="OBJ-1").session_path
    status = main(["verify", str(mtf), str(cam), "--spec", str(spec), "--json", "--no-store"])
    record = json.loads(capsys.readouterr().out)
    assert status == {"pass": 0, "fail": 1, "indeterminate": 3}[record["verdict"]]
    assert set(record["limits"]) == {"fwd-G2E2-S", "mtf50-centre", "system-gain",
                                     "read-noise", "avg-70"}
    for row in record["rows"]:  # every limit found a reading in the tables it names
        assert row["reading"] is not None, (row["limit_id"], row["notes"])
    assert {r["limit_id"] for r in record["rows"]} == set(record["limits"])


def test_spec_alone_is_checked_and_listed(tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["verify", "--example-spec"]) == 0
    spec = tmp_path / "spec.toml"
    spec.write_text(capsys.readouterr().out)
    assert main(["verify", "--spec", str(spec)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == (f"{spec}: dual-view objective rev B, rule guarded, coverage 95%, "
                        "3 limit(s)")
    assert lines[2] == ("  mtf50-centre: table_sfr_edges.mtf50_lp_per_mm [edge=E0L|E0R] "
                        ">= 90 lp/mm (guarded)")
    assert lines[3] == ("  avg-70: averaged_mtf_vs_monte_carlo.averaged_modulation "
                        "[view=forward] >= 0.5 (simple)")
    bad = tmp_path / "bad.toml"
    bad.write_text(spec.read_text().replace('decision_rule = "guarded"',
                                            'decision_rule = "strict"'))
    assert main(["verify", "--spec", str(bad)]) == 2
    assert "field 'decision_rule': must be one of guarded, simple" in capsys.readouterr().err
