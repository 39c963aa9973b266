"""The simulated bench's world: which target is mounted, and the scene the camera then sees.

Targets (the set-ups of Table 4.10 and section 4.4):

- ``"usaf"`` - forward-view set-up with the USAF 1951 chart (:class:`UsafScene`) and, in the
  empty part of the disc, the slanted-edge target (:class:`EdgeScene`);
- ``"edge"`` - the forward view with the slanted-edge target alone;
- ``("radial", lp_per_mm, "sagittal" | "tangential")`` - a rolled radial pattern
  (:class:`RadialScene`); also accepted as a list or the string ``"radial:4:sagittal"``;
- ``"card"`` or ``("card", radius_mm)`` - a flat grid-and-text card rolled onto the cylinder
  ``radius_mm`` from the axis (default 19.88; :class:`CardScene`); also ``"card:19.88"``;
- ``"led"`` - the radiometry LED (:class:`LedScene`), its current and stage position read from
  ``state.bench`` (``led_current_ma``, ``stage_position_mm``) at each exposure;
- ``"flat"`` - uniform illumination (diffuser, lens off) lit by the LED: every pixel gets
  ``flat_e_per_ms_per_ma`` x the LED current (camera characterisation, EMVA 1288 set-up);
- ``"dark"`` - nothing lit (lens cap on);
- ``"dots"`` - the forward view with the dot-grid chart of ``benchlab run fov``
  (:class:`DotGridScene`, :attr:`SimWorld.dots`), carried by the stage: its object distance is
  ``object_offset_mm`` + the stage position;
- ``"rings"`` - the radial view with the ring tube of ``benchlab run fov``
  (:class:`RingTubeScene`, :attr:`SimWorld.rings`), carried by the stage: ring 0's axial
  position is ``object_offset_mm`` + the stage position.

``state.bench["target"]``, when present, overrides the mounted target for that exposure, so a
bench assembly can keep the target in the state it already passes to the camera.
"""

from __future__ import annotations

import dataclasses
import threading
from collections.abc import Mapping
from typing import Any

import numpy as np

from benchlab.analysis.arrays import FloatArray
from benchlab.analysis.chart.layout import Orientation
from benchlab.drivers.sensor import AcquisitionState
from benchlab.scenes.card import CardScene
from benchlab.scenes.dots import DotGridScene
from benchlab.scenes.edge import EdgeScene
from benchlab.scenes.focus import ThroughFocusLens, defocused_radial, scenes_at
from benchlab.scenes.led import LedScene
from benchlab.scenes.radial import RadialScene
from benchlab.scenes.rings import RingTubeScene
from benchlab.scenes.usaf import UsafScene

Target = tuple[Any, ...]
TARGET_KINDS = ("usaf", "edge", "radial", "card", "led", "flat", "dark", "dots", "rings")


def parse_target(target: object) -> Target:
    """Normalise a target spec to ``("usaf",)``, ``("edge",)``, ``("led",)``, ``("dark",)``,
    ``("radial", lp_per_mm, orientation)`` or ``("card", radius_mm)``.

    Raises
    ------
    ValueError
        Naming the spec when it is not one of the accepted forms.
    """
    spec: object = target
    if isinstance(spec, str) and ":" in spec:
        spec = spec.split(":")
    if isinstance(spec, str):
        if spec in ("usaf", "edge", "led", "flat", "dark", "dots", "rings"):
            return (spec,)
        if spec == "card":
            return ("card", None)
        raise ValueError(f"unknown target {target!r}; expected one of {TARGET_KINDS}")
    if isinstance(spec, list | tuple) and len(spec) == 3 and spec[0] == "radial":
        try:
            lp = float(spec[1])
        except (TypeError, ValueError) as exc:
            raise ValueError(f"radial target {target!r}: frequency is not a number") from exc
        if not lp > 0:
            raise ValueError(f"radial target {target!r}: frequency must be > 0 lp/mm")
        if spec[2] not in ("sagittal", "tangential"):
            raise ValueError(f"radial target {target!r}: orientation must be sagittal/tangential")
        return ("radial", lp, str(spec[2]))
    if isinstance(spec, list | tuple) and len(spec) == 2 and spec[0] == "card":
        if spec[1] is None:
            return ("card", None)
        try:
            radius = float(spec[1])
        except (TypeError, ValueError) as exc:
            raise ValueError(f"card target {target!r}: radius is not a number (mm)") from exc
        if not radius > 0:
            raise ValueError(f"card target {target!r}: radius must be > 0 mm")
        return ("card", radius)
    if isinstance(spec, list | tuple) and len(spec) == 1:
        return parse_target(spec[0])
    raise ValueError(
        f"unknown target {target!r}; expected 'usaf', 'edge', 'led', 'flat', 'dark' or "
        "('radial', lp_per_mm, 'sagittal'|'tangential') or 'card[:RADIUS_MM]'"
    )


class SimWorld:
    """What sits in front of the simulated camera; callable as a :class:`Scene`.

    Parameters
    ----------
    target
        The target mounted at start.
    usaf, radial, card, led, edges
        Scene parameters (``edges=None``: the default slanted-edge target). ``radial`` is a
        template whose frequency and orientation are replaced per mounted pattern.
    led_channel
        Which channel of a per-channel ``led_current_ma`` mapping drives the LED (None: the sum).
    led_position_mm
        Where the LED is when ``state.bench`` has no stage position (positioned by hand).
    flat_e_per_ms_per_ma
        Electron rate per pixel per mA of LED current on the ``"flat"`` target (linear in the
        current, so a current sweep is an irradiance sweep).
    through_focus
        The lens's focus behaviour (:mod:`benchlab.scenes.focus`); with it, and a forward target
        on the stage carriage (``object_offset_mm`` in the bench state), the chart and edges
        are imaged at object distance ``object_offset_mm + stage_position_mm`` (a rolled
        radial pattern: at that object radius, :func:`benchlab.scenes.focus.defocused_radial`).
    """

    def __init__(
        self,
        target: object = "dark",
        *,
        usaf: UsafScene | None = None,
        radial: RadialScene | None = None,
        card: CardScene | None = None,
        led: LedScene | None = None,
        led_channel: int | str | None = None,
        led_position_mm: float | None = None,
        edges: EdgeScene | None = None,
        flat_e_per_ms_per_ma: float = 20.0,
        through_focus: ThroughFocusLens | None = None,
    ) -> None:
        self.usaf = usaf if usaf is not None else UsafScene()
        self.edges = edges if edges is not None else EdgeScene()
        self.radial_template = radial if radial is not None else RadialScene(1.0, "sagittal")
        self.card_template = card if card is not None else CardScene()
        self._cards: dict[float, CardScene] = {}
        self.led = led if led is not None else LedScene()
        self.led_channel = led_channel
        self.led_position_mm = led_position_mm
        self.flat_e_per_ms_per_ma = float(flat_e_per_ms_per_ma)
        self._radial: dict[tuple[float, str], RadialScene] = {}
        self._lock = threading.Lock()
        self._target = self._checked(target)
        self.through_focus = through_focus
        #: The dot-grid chart and its lens (``benchlab run fov`` sets its parameters').
        self.dots = DotGridScene()
        #: The ring tube of ``benchlab run fov``'s radial view (its parameters set it).
        self.rings = RingTubeScene()

    @property
    def target(self) -> Target:
        """The mounted target (normalised)."""
        return self._target

    @target.setter
    def target(self, value: object) -> None:
        self._target = self._checked(value)

    def _checked(self, target: object) -> Target:
        """Parse a target; a card off the ray-trace table is refused here, not at exposure."""
        spec = parse_target(target)
        if spec[0] == "card":
            self.card_scene(spec[1])
        return spec

    def mount(self, target: object) -> None:
        """Mount a target (same as assigning :attr:`target`)."""
        self.target = target

    def radial_scene(self, lp_per_mm: float, orientation: str) -> RadialScene:
        """The (cached) radial scene for a pattern."""
        if orientation not in ("sagittal", "tangential"):
            raise ValueError(f"orientation must be 'sagittal' or 'tangential', got {orientation!r}")
        orient: Orientation = "sagittal" if orientation == "sagittal" else "tangential"
        key = (float(lp_per_mm), orient)
        with self._lock:
            scene = self._radial.get(key)
            if scene is None:
                scene = dataclasses.replace(
                    self.radial_template, object_lp_per_mm=key[0], orientation=orient
                )
                self._radial[key] = scene
        return scene

    def card_scene(self, radius_mm: float | None) -> CardScene:
        """The (cached) card scene at a radius (None: the template's).

        Raises
        ------
        ValueError
            When the radius is outside the ray-trace table.
        """
        if radius_mm is None:
            return self.card_template
        key = float(radius_mm)
        with self._lock:
            scene = self._cards.get(key)
            if scene is None:
                try:
                    scene = dataclasses.replace(self.card_template, object_radius_mm=key)
                except ValueError as exc:  # RayTraceError: off the table
                    raise ValueError(f"card at {key:g} mm: {exc}") from exc
                self._cards[key] = scene
        return scene

    def scene_for(
        self, target: object
    ) -> UsafScene | EdgeScene | RadialScene | CardScene | LedScene | None:
        """The scene object of a target (None for ``"dark"`` and ``"flat"``; the chart's for
        ``"usaf"``)."""
        spec = parse_target(target)
        if spec[0] == "card":
            return self.card_scene(spec[1])
        if spec[0] == "usaf":
            return self.usaf
        if spec[0] == "edge":
            return self.edges
        if spec[0] == "radial":
            return self.radial_scene(spec[1], spec[2])
        if spec[0] == "led":
            return self.led
        return None  # dark, flat: drawn directly by __call__

    def led_current_ma(self, bench: Mapping[str, Any]) -> float:
        """LED drive current from the bench state (0 when absent or switched off)."""
        if bench.get("led_on") is False:
            return 0.0
        current = bench.get("led_current_ma", 0.0)
        if isinstance(current, Mapping):
            if self.led_channel is not None:
                value = current.get(self.led_channel, current.get(str(self.led_channel), 0.0))
                return float(value or 0.0)
            return float(sum(float(v or 0.0) for v in current.values()))
        if isinstance(current, list | tuple):
            if self.led_channel is not None:
                return float(current[int(self.led_channel)])
            return float(sum(current))
        return float(current or 0.0)

    def stage_position_mm(self, bench: Mapping[str, Any]) -> float:
        """LED position: the stage's, else the hand-set one, else mid-range."""
        pos = bench.get("stage_position_mm")
        if pos is None:
            pos = self.led_position_mm
        if pos is None:
            pos = sum(self.led.position_range_mm) / 2.0
        return float(pos)

    def __call__(self, state: AcquisitionState) -> FloatArray:
        """Electron-rate image (e-/ms) of whatever is mounted, for this acquisition state."""
        bench = state.bench or {}
        spec = parse_target(bench["target"]) if bench.get("target") is not None else self._target
        if spec[0] == "dark":
            return np.zeros((state.height, state.width))
        if spec[0] == "flat":
            rate = self.flat_e_per_ms_per_ma * self.led_current_ma(bench)
            return np.full((state.height, state.width), rate)
        if spec[0] == "dots":
            offset = bench.get("object_offset_mm")
            at_mm = (self.dots.default_distance_mm if offset is None else
                     float(offset) + float(bench.get("stage_position_mm") or 0.0))
            return self.dots.render(at_mm, state.height, state.width).copy()
        if spec[0] == "rings":
            return self.rings(state)
        if spec[0] == "led":
            return self.led.render(
                self.stage_position_mm(bench), self.led_current_ma(bench), state.height, state.width
            ).copy()
        scene = self.scene_for(spec)
        assert scene is not None
        edges = self.edges
        distance = self.object_distance_mm(bench)
        if distance is not None and spec[0] in ("usaf", "edge"):
            assert self.through_focus is not None
            usaf, edges = scenes_at(self.through_focus, distance, self.usaf, self.edges)
            scene = usaf if spec[0] == "usaf" else edges
        elif distance is not None and spec[0] == "radial":
            assert self.through_focus is not None and isinstance(scene, RadialScene)
            scene = defocused_radial(scene, self.through_focus, distance)
        if spec[0] == "usaf":  # the slanted-edge target shares the forward view with the chart
            # Composed as transmissions multiply (``chart x (1 - darkening / bright)``): where
            # a chart bar (or a moved chart) overlaps a square the light passes both chromes,
            # not subtracted twice and clamped at 0 (fake clipping); on clear glass it is
            # exactly the chart minus the squares.
            assert isinstance(scene, UsafScene)
            chart = scene.rendered(state)  # cached: composed into one new array, no copy
            img = np.divide(chart, edges.bright_rate)
            np.multiply(edges.darkening(state), img, out=img)
            return np.subtract(chart, img, out=img)
        return scene(state)

    def object_distance_mm(self, bench: Mapping[str, Any]) -> float | None:
        """Object distance of a stage-carried forward target (None: not carried, or no
        through-focus model)."""
        offset = bench.get("object_offset_mm")
        if self.through_focus is None or offset is None:
            return None
        return float(offset) + float(bench.get("stage_position_mm") or 0.0)
