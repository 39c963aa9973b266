"""The Run screen's terminal plot, target names in words, and tables for narrow terminals."""

from __future__ import annotations

from benchlab.tui import services
from benchlab.tui.drawing.plot import PlotPoint, render_plot


def test_points_land_where_their_values_say() -> None:
    pts = [PlotPoint(50.0, 1.0, "sagittal", False), PlotPoint(100.0, 0.0, "tangential", False)]
    lines = render_plot(pts, [], 24, 6, x_max=100.0, nyquist=96.0).plain.splitlines()
    assert len(lines) == 6
    top, bottom = lines[0][4:], lines[4][4:]  # plot rows start after "1.0|"
    assert top.index("s") == int(50.0 / 100.0 * 39) // 2  # braille columns: 2 per char
    assert bottom.rstrip().endswith("t")  # 0.0 at 100 lp/mm: bottom row, last column
    assert lines[-1].startswith("   \u2514") and "\u253c" in lines[-1]  # axis and Nyquist


def test_unresolved_and_aliased_have_their_own_marks() -> None:
    pts = [PlotPoint(30.0, None, "sagittal", False), PlotPoint(90.0, 0.7, "sagittal", True)]
    text = render_plot(pts, [], 30, 6, x_max=100.0, nyquist=96.0).plain
    bottom = text.splitlines()[4]
    assert "x" in bottom and "a" in bottom and "s" not in text  # neither drawn as a value


def test_curve_is_drawn_in_braille_and_extremes_do_not_break() -> None:
    curve = ([0.0, 100.0], [1.0, 0.0])
    text = render_plot([], [curve], 30, 8, x_max=100.0, nyquist=96.0).plain
    assert sum(0x2800 < ord(c) <= 0x28FF for c in text) >= 20
    tiny = render_plot([PlotPoint(500.0, 2.0, "?", False)], [curve], 1, 1, 100.0, 96.0)
    assert len(tiny.plain.splitlines()) == 4  # clamped to the smallest plot, point clipped


def test_targets_in_words() -> None:
    assert services.target_words(("radial", 2.0, "sagittal")) == "radial bars 2 lp/mm, sagittal"
    assert services.target_words("usaf") == "USAF 1951 chart"
    assert services.target_words("dark") == "dark (lens capped)"
    assert services.target_words("unknown-thing") == "unknown-thing"


def test_known_tables_put_modulations_first_and_format_numbers() -> None:
    rows = [{"element": "G1E5", "image_lp_per_mm": 51.749, "sagittal_dark": 20.7,
             "sagittal_bright": 186.2, "sagittal_modulation": 0.8, "tangential_dark": None,
             "tangential_bright": None, "tangential_modulation": 0.0, "aliased": False}]
    title, headers, cells = services.display_table("table_4_11", rows)
    assert title == "Table 4.11"
    assert headers[:3] == ["element", "S mod.", "T mod."]
    assert cells[0][:3] == ["G1E5", "0.800", "0.000"]
    assert "N/A" in cells[0] and "no" in cells[0]  # missing levels, aliased flag in words
    _, headers2, cells2 = services.display_table("something_new", [{"a": 1.23456, "b": "x"}])
    assert headers2 == ["a", "b"] and cells2 == [["1.235", "x"]]
