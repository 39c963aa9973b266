"""Parameter files: defaults load, and every problem of a bad file is reported at once."""

from __future__ import annotations

from pathlib import Path

import pytest
from sim_runs import FIXTURES, MTF_SMALL, RAD_SMALL

from benchlab.bench import BenchConfig
from benchlab.cli.main import main
from benchlab.protocols import MtfParams, ParamsError, RadiometryParams, load_params, parse_params
from benchlab.protocols.params import BenchLimits


def test_packaged_defaults_follow_table_4_10_and_section_4_4() -> None:
    mtf = load_params("mtf")
    assert isinstance(mtf, MtfParams)
    assert (mtf.exposure_ms, mtf.gain) == (300.0, 1.0)
    assert [e.name for e in mtf.forward_elements] == [
        "G1E5", "G1E6", "G2E1", "G2E2", "G2E3", "G2E4", "G2E5", "G2E6", "G3E1"]
    assert mtf.radial_frequencies_lp_per_mm == (0.5, 1, 2, 3, 4, 5, 6)
    assert mtf.radial_roi == (250, 1000, 290, 1050)
    rad = load_params("radiometry")
    assert isinstance(rad, RadiometryParams)
    assert rad.positions_mm == (15, 18, 20, 25, 32)
    assert (rad.exposure_ms, rad.mask_gain, rad.measurement_gain) == (375.0, 5.0, 1.0)
    assert rad.simulated_irradiance_mw_per_mm2 == (22.48, 21.21, 19.40, 14.34, 3.014)


def test_small_fixtures_are_valid() -> None:
    assert len(load_params("mtf", MTF_SMALL).forward_elements) == 2
    assert load_params("radiometry", RAD_SMALL).positions_mm == (15, 18, 25)


def test_bad_mtf_file_lists_every_problem_with_file_and_field() -> None:
    with pytest.raises(ParamsError) as info:
        load_params("mtf", FIXTURES / "bad-mtf.toml")
    msg = str(info.value)
    assert msg.startswith(str(FIXTURES / "bad-mtf.toml"))
    fields = [p.split(":")[0] for p in info.value.problems]
    assert fields == [
        "camera.exposure_ms", "camera.gain", "camera.bits", "forward.elements[1]",
        "forward.elements[2]", "radial.frequencies_lp_per_mm[1]", "radial.roi",
        "analysis.estimator", "forward.magnfication",
    ]
    assert "9 problems" in msg and "unknown parameter" in msg


def test_bad_radiometry_file_is_checked_against_the_bench_too() -> None:
    limits = BenchConfig.load(None, simulate=True).limits()
    with pytest.raises(ParamsError) as info:
        load_params("radiometry", FIXTURES / "bad-radiometry.toml", limits)
    fields = sorted(p.split(":")[0] for p in info.value.problems)
    assert fields == sorted([
        "camera.mask_gain", "analysis.simulated_irradiance_mw_per_mm2", "led.current_ma",
        "positions.field_mm[2]"])
    assert "exceeds the bench ceiling 50 mA" in str(info.value)


def test_bench_limits_missing_channel_and_no_stage() -> None:
    data = {"led": {"channel": 3, "current_ma": 10.0}, "positions": {"field_mm": [70]},
            "analysis": {"simulated_irradiance_mw_per_mm2": [1.0]}}
    with pytest.raises(ParamsError, match="channel 3 has no current ceiling"):
        parse_params("radiometry", data, limits=BenchLimits({1: 50.0}, (0.0, 50.0)))
    # No stage: positions are set by hand, so no travel check.
    params = parse_params("radiometry", data, limits=BenchLimits({3: 50.0}, None))
    assert params.positions_mm == (70,)


def test_syntax_error_and_missing_file_name_the_file(tmp_path: Path) -> None:
    with pytest.raises(ParamsError, match="not valid TOML"):
        load_params("mtf", FIXTURES / "bad-syntax.toml")
    with pytest.raises(ParamsError, match="no such parameter file"):
        load_params("mtf", tmp_path / "nope.toml")
    with pytest.raises(ParamsError, match="file is for 'radiometry'"):
        load_params("mtf", RAD_SMALL)


def test_cli_rejects_bad_params_before_any_session_or_device(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(["run", "radiometry", "--simulate", "--yes", "--out", str(tmp_path),
                 "--params", str(FIXTURES / "bad-radiometry.toml")])
    assert code == 1
    err = capsys.readouterr().err
    assert "4 problems" in err and "positions.field_mm[2]" in err and "led.current_ma" in err
    assert not any(tmp_path.iterdir())  # no session folder was created


def test_bench_config_problems_are_all_listed(tmp_path: Path) -> None:
    bad = tmp_path / "bench.toml"
    bad.write_text('[led]\nchannel = 0\n[led.ceiling_ma]\nx = 5\n1 = -2\n'
                   '[stage]\ntravel_mm = [10, 5]\nspeed = 3\n')
    with pytest.raises(ParamsError) as info:
        BenchConfig.load(bad)
    fields = sorted(p.split(":")[0] for p in info.value.problems)
    assert fields == sorted(["led.channel", "led.ceiling_ma.x", "led.ceiling_ma.1",
                             "stage.travel_mm", "stage.speed"])


def test_effective_parameters_round_trip_through_the_session_snapshot(tmp_path: Path) -> None:
    from benchlab.protocols.params import params_to_dict

    custom = tmp_path / "mtf.toml"
    custom.write_text('procedure = "mtf"\n[forward.roi.G2E4]\nsagittal = [600, 600, 610, 610]\n')
    for procedure, path in (("mtf", custom), ("mtf", None), ("radiometry", RAD_SMALL)):
        params = load_params(procedure, path)
        snap = params_to_dict(params)
        again = parse_params(procedure, snap)
        assert params_to_dict(again) == snap
        assert {k: v for k, v in vars(again).items() if k != "raw"} == {
            k: v for k, v in vars(params).items() if k != "raw"}
    assert params_to_dict(load_params("mtf", custom))["camera"]["exposure_ms"] == 300.0
