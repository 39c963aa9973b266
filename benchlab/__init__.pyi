"""The public names of :mod:`benchlab`, read by lazy_loader, mypy and the docs."""

from .analysis.chart.reading import ChartReading
from .api import (
    Prompt,
    measure_bars,
    measure_chart,
    measure_edge,
    open_bench,
    open_session,
    run_procedure,
)

__version__: str

__all__ = [
    "ChartReading",
    "Prompt",
    "__version__",
    "measure_bars",
    "measure_chart",
    "measure_edge",
    "open_bench",
    "open_session",
    "run_procedure",
]
