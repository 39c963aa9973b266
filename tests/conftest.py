"""Shared pytest configuration; ``--hardware bench.toml`` runs the contract suites
(tests/drivers/test_contract_*.py) on the real devices that bench file names."""

import os
from collections.abc import Iterator

import pytest
from hypothesis import settings

# Property tests draw the same examples on every run (a red CI names a defect, not a lucky draw);
# `--hypothesis-profile explore` draws new ones (CONTRIBUTING.md: Tests).
settings.register_profile("repeatable", derandomize=True)
settings.register_profile("explore", derandomize=False, max_examples=500)
settings.load_profile("repeatable")


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        "--hardware", metavar="BENCH_TOML",
        help="run the hardware contract suites on the devices this bench file names (the LED "
             "is lit at most at min(its ceiling, 10 mA), the stage moves inside its travel); "
             "without it they are skipped")


def hardware_environment(path: str) -> dict[str, str]:
    """The variables tests/device_implementations.py reads, from a bench file."""
    from benchlab.bench import BenchConfig

    cfg = BenchConfig.load(path)
    env = {"BENCHLAB_HW_CAMERA_SERIAL": cfg.camera.serial or "any"}
    if cfg.camera.model:
        env["BENCHLAB_HW_CAMERA_MODEL"] = cfg.camera.model
    if cfg.led is not None and cfg.led.port:
        env["BENCHLAB_HW_LED_PORT"] = cfg.led.port
        env["BENCHLAB_HW_LED_CEILING_MA"] = f"{min(cfg.led.ceilings_ma.get(1, 10.0), 10.0):g}"
    if cfg.stage is not None and cfg.stage.port:
        lo, hi = cfg.stage.travel_mm
        env["BENCHLAB_HW_STAGE_PORT"] = cfg.stage.port
        env["BENCHLAB_HW_STAGE_TRAVEL_MM"] = f"{lo:g},{hi:g}"
        env["BENCHLAB_HW_STAGE_COUNTS_PER_MM"] = repr(cfg.stage.counts_per_mm)
    return env


def pytest_configure(config: pytest.Config) -> None:
    path = config.getoption("--hardware")
    if path:  # before collection imports device_implementations
        os.environ.update(hardware_environment(path))


@pytest.fixture(autouse=True)
def _isolated_user_config(tmp_path_factory: pytest.TempPathFactory,
                          monkeypatch: pytest.MonkeyPatch) -> None:
    """No test reads or writes the developer's own benchlab config (platformdirs)."""
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path_factory.mktemp("xdg-config")))


@pytest.fixture
def quick_silence(monkeypatch: pytest.MonkeyPatch) -> None:
    """The simulated bench's LED and stage time out after a real device's 1 s, for tests that
    make a simulator fall silent (its default is patient: ``SIM_REPLY_TIMEOUT_S``)."""
    import benchlab.bench

    monkeypatch.setattr(benchlab.bench, "SIM_REPLY_TIMEOUT_S", 1.0)


@pytest.fixture
def terminal_sigint() -> Iterator[None]:
    """SIGINT raises KeyboardInterrupt, as in a program started from a terminal. A test runner
    started in the background by a non-interactive shell inherits SIGINT ignored, and a test of
    Ctrl-C must not depend on how its runner was started."""
    import signal

    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
