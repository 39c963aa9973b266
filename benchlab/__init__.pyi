"""The public names of :mod:`benchlab`, read by lazy_loader, mypy and the docs."""

from .analysis.bars.result import ModulationResult
from .analysis.chart.reading import ChartReading
from .analysis.sfr.measure import SfrResult
from .api import (
    Prompt,
    measure_bars,
    measure_chart,
    measure_edge,
    open_bench,
    open_session,
    run_procedure,
)
from .bench import Bench
from .protocols.engine import RunOutcome
from .session import Session

__version__: str

__all__ = [
    "Bench",
    "ChartReading",
    "ModulationResult",
    "Prompt",
    "RunOutcome",
    "Session",
    "SfrResult",
    "__version__",
    "measure_bars",
    "measure_chart",
    "measure_edge",
    "open_bench",
    "open_session",
    "run_procedure",
]
