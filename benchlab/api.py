"""The scripting API at ``import benchlab``: open a bench, run a procedure, read a session,
measure bars, an edge or a whole chart on an array.

Thin calls onto the layers below (:mod:`benchlab.bench`, :mod:`benchlab.protocols`,
:mod:`benchlab.session`, :mod:`benchlab.analysis`): no second implementation of anything, and
every answer is the type those layers already return. Listed once in ``benchlab/__init__.pyi``
and imported on first use, so ``import benchlab`` stays cheap. Sits in the top layer beside
:mod:`benchlab.cli`; nothing below may import it.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy.typing as npt

from benchlab.drivers.errors import UsageError

if TYPE_CHECKING:
    from benchlab.analysis.bars.estimators import EstimatorChoice
    from benchlab.analysis.bars.result import ModulationResult
    from benchlab.analysis.bars.roi import BarOrientation
    from benchlab.analysis.chart.reading import ChartReading
    from benchlab.analysis.sfr.measure import SfrResult
    from benchlab.bench import Bench
    from benchlab.procedures import ProcedureName
    from benchlab.protocols.engine import RunOutcome, Step
    from benchlab.protocols.params import Params
    from benchlab.session import Session

__all__ = [
    "Prompt",
    "measure_bars",
    "measure_chart",
    "measure_edge",
    "open_bench",
    "open_session",
    "run_procedure",
]

PathLike = str | os.PathLike[str]


@dataclass(frozen=True)
class Prompt:
    """A manual step asking the operator to act (thread the target, set the focus, ...).

    ``str(prompt)`` is :attr:`message`.

    Attributes
    ----------
    step_id : str
        The step's id in the procedure's plan (``"mount-usaf"``, ``"focus"``, ...).
    title : str
        The step's title.
    kind : str
        ``"setup"``, ``"manual"`` or ``"focus"`` (the back-focus step: ``message`` holds the
        current sharpness).
    message : str
        What the operator is asked to do.
    """

    step_id: str
    title: str
    kind: str
    message: str

    def __str__(self) -> str:
        return self.message


@contextlib.contextmanager
def open_bench(config: PathLike | None = None, *, simulate: bool = False) -> Iterator[Bench]:
    """Open the bench's devices (or their simulators) for the length of a ``with`` block.

    Parameters
    ----------
    config : str or path-like, optional
        A bench TOML file (serial ports, LED current ceilings, stage travel; see
        ``benchlab config init``). Required for the real bench; with ``simulate`` the
        packaged simulated bench is used when it is not given.
    simulate : bool, default False
        The simulated bench: the real drivers talking to device simulators (camera firmware
        on a USB backend, LED controller and stage on pseudo-terminals) over a simulated
        optical world.

    Yields
    ------
    benchlab.bench.Bench
        The open bench. On every way out of the block - normal end, exception, Ctrl-C -
        every LED channel is switched off and the stage stopped before the devices close.

    Raises
    ------
    benchlab.bench.BenchConfigError
        The bench file is missing, not TOML, or has bad fields (every problem listed, each
        naming the file and the field).
    benchlab.drivers.errors.UsageError
        The real bench without a bench file.
    benchlab.drivers.errors.DeviceError
        A device could not be opened (its subclasses name which and why).

    Examples
    --------
    >>> import benchlab
    >>> with benchlab.open_bench(simulate=True) as bench:  # doctest: +SKIP
    ...     pixels, meta = bench.grab(exposure_ms=300.0, gain=1.0)
    """
    from benchlab.bench import Bench, BenchConfig

    if config is None and not simulate:
        raise UsageError("open_bench: the real bench needs a bench file, "
                         "open_bench('bench.toml') (`benchlab config init` writes one), "
                         "or open_bench(simulate=True)")
    cfg = BenchConfig.load(None if config is None else Path(config), simulate=simulate)
    with Bench.open(cfg, simulate=simulate) as bench:
        yield bench


def _prompter(answer: Callable[[Prompt], bool] | None) -> Callable[[Step, str], bool]:
    """The engine's prompt callback for ``answer``: with none, the first prompt aborts."""
    from benchlab.protocols.engine import RunAborted

    def prompt(step: Step, message: str) -> bool:
        if answer is None:
            raise RunAborted(f"step {step.id} needs the operator ({message}); pass "
                             "answer=... to run_procedure to answer prompts")
        reply = answer(Prompt(step.id, step.title, step.kind, message))
        if not isinstance(reply, bool):
            raise RunAborted(f"step {step.id}: answer returned {reply!r}, not True (go on) or "
                             "False (abort)")
        return reply

    return prompt


def run_procedure(
    bench: Bench,
    procedure: ProcedureName,
    *,
    params: Params | PathLike | None = None,
    out: PathLike = "sessions",
    answer: Callable[[Prompt], bool] | None = None,
    operator: str | None = None,
    sample: str | None = None,
) -> RunOutcome:
    """Run a measurement procedure on an open bench into a new session folder.

    Parameters
    ----------
    bench : benchlab.bench.Bench
        From :func:`open_bench`.
    procedure : {"mtf", "radiometry", "characterise", "depth", "fov"}
        Table 4.10 MTF, section 4.4 relative radiometry, the camera characterisation, depth
        of field through focus, or the forward view's field of view and mapping.
    params : path-like or benchlab.protocols.params.Params, optional
        The procedure's parameter TOML file (or parameters already loaded); default the
        packaged ones. Checked in full, bench limits included, before any folder is made or
        any device moves.
    out : path-like, default "sessions"
        The folder that receives the session folder (its last level is created).
    answer : callable, optional
        Called at each manual step with a :class:`Prompt`; ``True`` once the operator has
        done it, ``False`` to abort the run. ``None`` (the default) answers nothing: the
        first prompt aborts the run with :class:`~benchlab.protocols.engine.RunAborted`
        saying so - prompts are never answered "yes" silently. The simulated bench needs
        no one at the bench: ``answer=lambda prompt: True``.
    operator, sample : str, optional
        Who ran it, and the lens or sample under test (``session.json``; the catalogue's
        trends group by sample).

    Returns
    -------
    benchlab.protocols.engine.RunOutcome
        ``session_path``, ``results_path`` (``results/v1``), ``tables`` (label -> rows),
        ``summary`` and ``duration_s``.

    Raises
    ------
    benchlab.drivers.errors.UsageError
        Unknown procedure (nothing created).
    benchlab.protocols.params.ParamsError
        Bad parameters (every problem listed; nothing created).
    benchlab.protocols.engine.RunAborted
        A prompt declined or unanswered: the session's status is "aborted", its path is the
        exception's ``session_path``, and ``benchlab resume`` continues it.
    benchlab.protocols.engine.StepFailed
        A step failed (``.step``, ``.cause``): status "failed", resumable likewise.

    Examples
    --------
    >>> import benchlab
    >>> with benchlab.open_bench(simulate=True) as bench:  # doctest: +SKIP
    ...     run = benchlab.run_procedure(bench, "mtf", answer=lambda prompt: True)
    >>> run.session_path  # doctest: +SKIP
    PosixPath('sessions/20260101-120000_mtf')
    """
    from benchlab.procedures import PROCEDURES
    from benchlab.protocols.runs import start_run

    if procedure not in PROCEDURES:
        raise UsageError(f"run_procedure: unknown procedure {procedure!r}; choose "
                         f"{', '.join(PROCEDURES)}")
    if answer is not None and not callable(answer):
        raise UsageError(f"run_procedure: answer must be a callable taking a Prompt, got "
                         f"{type(answer).__name__}")
    if isinstance(params, str | os.PathLike):
        params = Path(params)
    runner = start_run(procedure, bench=bench, params=params, root=Path(out),
                       operator=operator or "", sample=sample or "", prompt=_prompter(answer))
    return runner.run()


def open_session(path: PathLike) -> Session:
    """Open a session folder to read it (nothing in it is changed).

    Parameters
    ----------
    path : path-like
        The session folder (``RunOutcome.session_path``, or one under ``sessions/``).

    Returns
    -------
    benchlab.session.Session
        ``.status``, ``.procedure``, ``.params``; ``.tables()`` and ``.table(name)`` (the
        latest results version, typed values); ``.frames()`` and ``.frame(name)`` (pixels,
        hash-checked).

    Raises
    ------
    benchlab.session.SessionError
        Not a session folder (the message names ``session.json`` and what is wrong with it).

    Examples
    --------
    >>> import benchlab
    >>> session = benchlab.open_session("sessions/20260101-120000_mtf")  # doctest: +SKIP
    >>> session.tables()  # doctest: +SKIP
    ['forward_view_modulation', 'radial_view_modulation', ...]
    """
    from benchlab.session import Session

    return Session.open(Path(path))


def measure_bars(
    roi: npt.ArrayLike,
    *,
    orientation: BarOrientation | None = None,
    estimator: EstimatorChoice | None = None,
    freq_cycles_per_px: float | None = None,
) -> ModulationResult:
    """Eq. 2.9 bar modulation of one ROI holding bars (a square-wave target).

    Parameters
    ----------
    roi : array_like
        2-D gray levels (rows, cols), any integer or float dtype, or a stack (frames, rows,
        cols) that is averaged.
    orientation : {"horizontal", "vertical", "sagittal", "tangential"}, optional
        The direction the intensity varies (``"horizontal"``: along the columns, vertical
        bars; ``"sagittal"`` = horizontal, ``"tangential"`` = vertical); detected when
        ``None``.
    estimator : str, optional
        ``None`` or ``"auto"`` for the library's default, or one of
        ``benchlab.analysis.ESTIMATORS`` (``"profilefit"``, ``"histogram"``, ``"sinefit"``,
        ``"variance"``, ...).
    freq_cycles_per_px : float, optional
        The bars' frequency on the sensor, when known: flags aliasing (above 0.5) and helps
        the sine fit.

    Returns
    -------
    benchlab.analysis.ModulationResult
        ``modulation``, ``uncertainty`` (1 sigma), ``interval`` (95 %), ``dark``, ``bright``,
        ``resolved``, ``warnings``. See :func:`benchlab.analysis.estimate_modulation`.

    Raises
    ------
    ValueError
        Unknown estimator or orientation, empty or non-finite ROI.

    Examples
    --------
    >>> import numpy as np
    >>> import benchlab
    >>> rng = np.random.default_rng(0)
    >>> period = [40.0] * 4 + [200.0] * 4                # 4 px dark, 4 px bright
    >>> roi = np.tile(period * 8, (32, 1)) + rng.normal(0.0, 3.0, (32, 64))
    >>> result = benchlab.measure_bars(roi, orientation="horizontal", estimator="histogram")
    >>> f"{result.modulation:.2f}"                       # (200 - 40) / (200 + 40)
    '0.67'
    """
    from benchlab.analysis import estimate_modulation

    return estimate_modulation(roi, estimator=estimator or "auto", orientation=orientation,
                               freq_cycles_per_px=freq_cycles_per_px)


def measure_edge(
    roi: npt.ArrayLike, *, full_scale: float | None = None, fit_order: int = 1
) -> SfrResult:
    """Slanted-edge SFR (the sine-wave MTF along the edge normal) of one ROI holding one edge.

    Parameters
    ----------
    roi : array_like, shape (rows, cols)
        Linear gray levels; the edge crosses the ROI from side to side, a few degrees off a
        pixel axis.
    full_scale : float, optional
        The saturation code (clipping check); from the dtype when ``None``.
    fit_order : int, default 1
        Polynomial order of the edge fit (2-3 follow a bent edge).

    Returns
    -------
    benchlab.analysis.sfr.measure.SfrResult
        ``freqs_cycles_per_px``, ``mtf``, ``mtf_sigma``, ``mtf50_cycles_per_px``,
        ``mtf_nyquist``, ``edge_angle_deg``, ``direction``, ... See
        :func:`benchlab.analysis.sfr.measure.measure_sfr`.

    Raises
    ------
    benchlab.analysis.sfr.measure.SfrRefused
        No usable edge in the ROI (the reasons listed).
    ValueError
        Not 2-D, non-finite values, bad options.

    Examples
    --------
    >>> import numpy as np
    >>> from scipy.special import erf
    >>> import benchlab
    >>> rows, cols = np.mgrid[0:80, 0:80]
    >>> across = (cols - 40) - 0.1 * (rows - 40)         # an edge 5.7 deg off the columns
    >>> roi = 20 + 180 * 0.5 * (1 + erf(across / 1.2))   # blurred: dark 20 to bright 200
    >>> result = benchlab.measure_edge(roi)
    >>> result.direction, round(result.edge_angle_deg, 1)
    ('horizontal', 5.7)
    """
    from benchlab.analysis.sfr.measure import measure_sfr

    return measure_sfr(roi, full_scale=full_scale, fit_order=fit_order)


def measure_chart(frame: npt.ArrayLike, *, magnification: float | None = None) -> ChartReading:
    """Find the USAF 1951 chart in a whole frame and read every bar set found.

    The same reading as ``benchlab analyze FRAME --chart usaf``: each found set is fitted at
    the geometry the chart's pose gives it, with the blur shared across the chart
    (:func:`benchlab.analysis.chart.reading.read_chart`).

    Parameters
    ----------
    frame : array_like
        The 2-D frame (any integer or float dtype), or a stack of frames (averaged).
    magnification : float, optional
        The configured object-to-image frequency factor (Eq. 4.1); default the forward view's
        (16.3). The chart is found at 0.5-2x this scale and the implied one is reported.

    Returns
    -------
    benchlab.analysis.chart.reading.ChartReading
        ``.fit`` (pose, polarity, implied magnification, every set found or rejected with the
        reason), ``.readings`` (one :class:`~benchlab.analysis.ModulationResult` per found
        set, coarse to fine), ``.labels`` and ``.reading(label)``.

    Raises
    ------
    benchlab.analysis.chart.finder.ChartNotFoundError
        No chart in the frame (a ``ValueError``).
    ValueError
        A frame that is not 2-D (or a stack), empty or not finite; a magnification <= 0.

    Examples
    --------
    >>> import benchlab
    >>> from benchlab.scenes.usaf import UsafScene  # the simulated bench's chart, noise-free
    >>> frame = UsafScene().render(1024, 1280)
    >>> chart = benchlab.measure_chart(frame)
    >>> len(chart.readings), chart.labels[0], chart.fit.polarity
    (32, 'G0E1S', 'positive')
    >>> f"{chart.reading('G2E1S').modulation:.2f}"
    '0.80'
    """
    import numpy as np

    from benchlab.analysis.chart.finder import find_chart
    from benchlab.analysis.chart.layout import ChartLayout
    from benchlab.analysis.chart.reading import ChartReading, read_chart

    layout = ChartLayout()
    if magnification is not None:
        if not magnification > 0:
            raise ValueError(f"magnification must be > 0, got {magnification}")
        layout = ChartLayout(magnification=magnification)
    pixels = np.asarray(frame)
    fit = find_chart(pixels, layout)
    return ChartReading(fit, tuple(read_chart(pixels, fit)))

