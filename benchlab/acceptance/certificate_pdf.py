"""The unit's certificate as an A4 PDF, drawn with matplotlib: no browser needed.

The text is :func:`benchlab.acceptance.certificate.certificate_content`, the same as the HTML
page's. Tables are set in DejaVu Sans Mono (shipped with matplotlib), so a column's width in
characters is its width on paper and a long cell wraps at a known place; a table that does not
fit on the page continues on the next one under its header again. Every page carries the unit,
the verdict record and "page i of n". The file has no creation date, so the same verdict record
gives the same bytes.
"""

from __future__ import annotations

import io
import textwrap
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import matplotlib
from matplotlib.figure import Figure
from matplotlib.font_manager import FontProperties
from matplotlib.lines import Line2D
from matplotlib.textpath import TextPath

from benchlab.acceptance.certificate import (
    MARGIN_NOTE,
    SIGNATURES,
    VERDICT_COLOURS,
    CertificateContent,
    certificate_content,
)

PAGE_IN = (8.27, 11.69)  # A4 portrait
MARGIN_IN = 15 / 25.4
FOOTER_IN = 0.25  # kept free above the bottom margin for the page footer
BODY_PT = 7.0
MONO_ADVANCE_EM = 0.6021  # DejaVu Sans Mono: 1233 / 2048 units per em
LINE_EM = 1.4
CHAR_IN = BODY_PT * MONO_ADVANCE_EM / 72
LINE_IN = BODY_PT * LINE_EM / 72
#: Characters across the text width, and between two table columns.
COLUMNS = int((PAGE_IN[0] - 2 * MARGIN_IN) / CHAR_IN)
GAP = 2
INK, GREY, RULE = "#222222", "#555555", "#bbbbbb"
#: TrueType fonts embedded (text selectable and searchable), the fonts matplotlib ships.
_RC: dict[Any, Any] = {"pdf.fonttype": 42, "font.family": "DejaVu Sans",
                      "font.monospace": ["DejaVu Sans Mono"]}


@dataclass(frozen=True)
class _Text:
    x_in: float
    y_in: float  # from the top of the page, to the top of the text
    text: str
    size_pt: float = BODY_PT
    colour: str = INK
    bold: bool = False
    mono: bool = True


@dataclass(frozen=True)
class _Rule:
    y_in: float
    x0_in: float = MARGIN_IN
    x1_in: float = PAGE_IN[0] - MARGIN_IN
    colour: str = RULE


class _Pages:
    """Top-to-bottom placement of text on as many pages as it needs."""

    def __init__(self) -> None:
        self.pages: list[list[_Text | _Rule]] = [[]]
        self.y_in = MARGIN_IN

    def fits(self, height_in: float) -> bool:
        return self.y_in + height_in <= PAGE_IN[1] - MARGIN_IN - FOOTER_IN

    def new_page(self) -> None:
        self.pages.append([])
        self.y_in = MARGIN_IN

    def add(self, item: _Text | _Rule) -> None:
        self.pages[-1].append(item)

    def line(self, text: str, *, size_pt: float = BODY_PT, colour: str = INK,
             bold: bool = False, mono: bool = False, gap_after_in: float = 0.0) -> None:
        """One line of text; a line too long for the text width goes on as many as it needs."""
        height = size_pt * LINE_EM / 72
        exact = mono and size_pt == BODY_PT  # the table font: its width is COLUMNS characters
        parts = (textwrap.wrap(text, COLUMNS) or [""]) if exact else _wrap_to_width(
            text, size_pt, bold, mono)
        for part in parts:
            if not self.fits(height):
                self.new_page()
            self.add(_Text(MARGIN_IN, self.y_in, part, size_pt, colour, bold, mono))
            self.y_in += height
        self.y_in += gap_after_in

    def paragraph(self, text: str, *, colour: str = GREY) -> None:
        self.line(text, colour=colour, mono=True)

    def heading(self, text: str) -> None:
        if not self.fits(0.2 + 4 * LINE_IN):  # a heading is not left alone at a page's foot
            self.new_page()
        self.y_in += 0.12
        self.line(text, size_pt=10.0, bold=True, gap_after_in=0.02)
        self.add(_Rule(self.y_in))
        self.y_in += 0.05


def text_width_in(text: str, size_pt: float, bold: bool = False, mono: bool = False) -> float:
    """Width of ``text`` as drawn (glyph outlines, no renderer needed)."""
    font = FontProperties(family="DejaVu Sans Mono" if mono else "DejaVu Sans",
                          weight="bold" if bold else "normal")
    return float(TextPath((0, 0), text, size=size_pt, prop=font).get_extents().width) / 72


def _wrap_to_width(text: str, size_pt: float, bold: bool, mono: bool) -> list[str]:
    """Greedy word wrap to the text width; a word wider than the line is cut."""
    width_in = PAGE_IN[0] - 2 * MARGIN_IN
    lines: list[str] = []
    current = ""
    for word in text.split(" "):
        trial = f"{current} {word}" if current else word
        if text_width_in(trial, size_pt, bold, mono) <= width_in:
            current = trial
            continue
        if current:
            lines.append(current)
        current = word
        while text_width_in(current, size_pt, bold, mono) > width_in:
            fits, too_long = 1, len(current)  # bisect the longest head that fits
            while too_long - fits > 1:
                mid = (fits + too_long) // 2
                if text_width_in(current[:mid], size_pt, bold, mono) <= width_in:
                    fits = mid
                else:
                    too_long = mid
            lines.append(current[:fits])
            current = current[fits:]
    return [*lines, current]


def _x(widths: Sequence[int], column: int) -> float:
    return MARGIN_IN + CHAR_IN * (sum(widths[:column]) + GAP * column)


def _cell_lines(text: str, width: int) -> list[str]:
    return textwrap.wrap(text, width, break_on_hyphens=False) or [""]


def _table(pages: _Pages, header: Sequence[str] | None, widths: Sequence[int],
           rows: Sequence[Sequence[str]], *, colours: Sequence[Sequence[str]] | None = None,
           notes: Sequence[str] | None = None) -> None:
    """Rows of wrapped cells under a header (repeated on each page); a note (grey, from the
    second column to the right edge) under a row."""
    assert sum(widths) + GAP * (len(widths) - 1) <= COLUMNS, "table wider than the page"

    def draw_header() -> None:
        if header is None:
            return
        for i, h in enumerate(header):
            pages.add(_Text(_x(widths, i), pages.y_in, h, bold=True))
        pages.y_in += LINE_IN
        pages.add(_Rule(pages.y_in - 0.03))

    if not pages.fits(3 * LINE_IN):
        pages.new_page()
    draw_header()
    note_width = COLUMNS - widths[0] - GAP
    for r, row in enumerate(rows):
        cells = [_cell_lines(text, w) for text, w in zip(row, widths, strict=True)]
        note = _cell_lines(notes[r], note_width) if notes and notes[r] else []
        height = (max(len(c) for c in cells) + len(note)) * LINE_IN + 0.04
        if not pages.fits(height):
            pages.new_page()
            draw_header()
        top = pages.y_in
        for i, lines in enumerate(cells):
            colour = colours[r][i] if colours else INK
            for k, text in enumerate(lines):
                pages.add(_Text(_x(widths, i), top + k * LINE_IN, text, colour=colour,
                                bold=colour != INK))
        below = top + max(len(c) for c in cells) * LINE_IN
        for k, text in enumerate(note):
            pages.add(_Text(_x(widths, 1), below + k * LINE_IN, text, colour=GREY))
        pages.y_in = top + height
        pages.add(_Rule(pages.y_in - 0.03, colour="#e4e4e4"))


def _layout(c: CertificateContent) -> list[list[_Text | _Rule]]:
    pages = _Pages()
    pages.line(c.title, size_pt=15.0, bold=True, gap_after_in=0.08)
    pages.line(f"Unit verdict: {c.verdict.upper()}", size_pt=13.0, bold=True,
               colour=VERDICT_COLOURS.get(c.verdict, INK), gap_after_in=0.1)
    key_width = max(len(k) for k, _ in c.identity)
    _table(pages, None, (key_width, COLUMNS - key_width - GAP),
           [(k, v) for k, v in c.identity])

    pages.heading("Limits")
    header = ("limit", "quantity", "reading", f"interval ({c.coverage:.0%})", "limit",
              "margin", "rule", "verdict")
    widths = (16, 22, 8, 17, 12, 9, 8, 13)
    rows = [(r.limit_id, r.column, r.reading, r.interval, r.limit, r.margin, r.rule,
             r.verdict) for r in c.limits]
    colours = [[INK] * 7 + [VERDICT_COLOURS.get(r.verdict, INK)] for r in c.limits]
    notes = ["; ".join(x for x in (f"{r.table}: {r.row}" if r.row else r.table, r.why) if x)
             for r in c.limits]
    _table(pages, header, widths, rows, colours=colours, notes=notes)
    pages.y_in += 0.05
    pages.paragraph(f"{MARGIN_NOTE} {c.rule}.")

    if c.disagreements:
        pages.heading("Sessions that disagree")
        for text in c.disagreements:
            pages.line(text, mono=True)
        pages.paragraph("Readings of the unit's sessions that differ beyond their "
                        "uncertainties (E_n > 1, ISO 13528): such a row is never a pass.")

    pages.heading("Sessions")
    _table(pages, ("session", "procedure", "started", "results", "acquired with"),
           (30, 13, 26, 14, 28), c.sessions)
    for title, what, hashes in (("Results (sha256 of the files certified)", "file", c.results),
                                ("Frames (sha256 at acquisition)", "frame", c.frames)):
        pages.heading(title)
        session_width = min(26, max([len("session"), *(len(f[0]) for f in hashes)]))
        _table(pages, ("session", what, "sha256"),
               (session_width, COLUMNS - session_width - 64 - 2 * GAP, 64), hashes)

    if not pages.fits(0.7):
        pages.new_page()
    pages.y_in += 0.5
    width_in = 2.4
    for i, text in enumerate(SIGNATURES):
        x0 = MARGIN_IN + i * (width_in + 0.6)
        pages.add(_Rule(pages.y_in, x0, x0 + width_in, colour=GREY))
        pages.add(_Text(x0, pages.y_in + 0.04, text, colour=GREY, mono=False))
    return pages.pages


def certificate_figures(record: Mapping[str, Any], session_id: str = "") -> list[Figure]:
    """The certificate's pages as matplotlib figures (A4 portrait)."""
    return _figures(certificate_content(record, session_id))


def _figures(content: CertificateContent) -> list[Figure]:
    pages = _layout(content)
    footer = f"{content.title} - unit verdict {content.verdict} - {content.record_name}"
    w, h = PAGE_IN
    figures = []
    for number, items in enumerate(pages, 1):
        fig = Figure(figsize=PAGE_IN)
        for item in [*items, _Text(MARGIN_IN, h - MARGIN_IN - 0.12,
                                   f"{footer} - page {number} of {len(pages)}",
                                   size_pt=6.5, colour=GREY, mono=False)]:
            if isinstance(item, _Rule):
                fig.add_artist(Line2D([item.x0_in / w, item.x1_in / w], [1 - item.y_in / h] * 2,
                                      color=item.colour, linewidth=0.5))
            else:
                fig.text(item.x_in / w, 1 - item.y_in / h, item.text, va="top", ha="left",
                         fontsize=item.size_pt, color=item.colour,
                         fontweight="bold" if item.bold else "normal",
                         family="monospace" if item.mono else "sans-serif")
        figures.append(fig)
    return figures


def certificate_pdf(record: Mapping[str, Any], session_id: str = "") -> bytes:
    """The certificate of one stored verdict record as the bytes of an A4 PDF; ``record`` and
    ``session_id`` as for :func:`~benchlab.acceptance.certificate.certificate_content`.

    Returns
    -------
    bytes
        The PDF: text embedded (TrueType), no creation date, so the same record gives the same
        bytes.
    """
    from matplotlib.backends.backend_pdf import PdfPages

    content = certificate_content(record, session_id)
    metadata = {"Title": content.title, "Subject": f"unit verdict: {content.verdict}",
                "Creator": f"benchlab {record.get('software_version', '')}",
                "CreationDate": None}
    buffer = io.BytesIO()
    with matplotlib.rc_context(_RC), PdfPages(buffer, metadata=metadata) as pdf:
        for fig in _figures(content):
            pdf.savefig(fig)
    return buffer.getvalue()
