"""A vectorised Sixel encoder for palette images (the live view's 32 grays plus outlines).

Sixel (DEC VT340 graphics) sends an image in bands of six pixel rows. For each band and each
colour in it, one line of characters ``chr(63 + bits)`` sets the pixels of that colour in a
column (bit ``r`` = row ``r`` of the band), ``!<n><char>`` repeats a character ``n`` times,
``$`` returns to the band's start for the next colour and ``-`` moves to the next band.

All of it is done with numpy on whole arrays (no Python loop per band, colour or run), so a
640x512 frame encodes in a few milliseconds; the live view encodes one every frame.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

BAND_ROWS = 6
#: DCS introducer (pixel aspect 1:1, pixels of bit 0 keep the background) and ST terminator.
INTRODUCER = "\x1bP0;0;0q"
TERMINATOR = "\x1b\\"
#: Runs at least this long are sent as ``!<n><char>`` (shorter ones as the characters).
MIN_REPEAT = 4


def _digits(values: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
    """Number of decimal digits of each (non-negative) value."""
    return np.maximum(1, np.floor(np.log10(np.maximum(values, 1))).astype(np.int64) + 1)


def _put_numbers(out: npt.NDArray[np.uint8], at: npt.NDArray[np.int64],
                 values: npt.NDArray[np.int64], ndigits: npt.NDArray[np.int64]) -> None:
    """Write ``values`` in decimal into ``out`` starting at ``at`` (``ndigits`` each)."""
    for d in range(int(ndigits.max(initial=0))):
        has = ndigits > d
        power = 10 ** (ndigits[has] - 1 - d)
        out[at[has] + d] = 48 + (values[has] // power) % 10


def encode_sixel(index: npt.NDArray[np.uint8], palette: npt.NDArray[np.uint8]) -> str:
    """The Sixel string of a palette image.

    Parameters
    ----------
    index : ndarray of uint8, shape (H, W)
        Palette index of each pixel.
    palette : ndarray of uint8, shape (K, 3)
        RGB of each index (``K`` <= 256; indices >= K must not occur).

    Returns
    -------
    str
        DCS ... ST, raster size ``W x H``, the colours used, then the bands.
    """
    index = np.asarray(index, np.uint8)
    height, width = index.shape
    colours = len(palette)
    if height == 0 or width == 0:
        return f'{INTRODUCER}"1;1;{width};{height}{TERMINATOR}'
    if int(index.max()) >= colours:
        raise ValueError(f"palette index {int(index.max())} >= {colours} colours")
    bands = -(-height // BAND_ROWS)
    padded = np.full((bands * BAND_ROWS, width), colours, np.int64)  # colour K: no pixel
    padded[:height] = index
    cells = padded.reshape(bands, BAND_ROWS, width)
    # bits[band, colour, x]: which of the band's six rows have that colour at column x
    key = (np.arange(bands)[:, None, None] * (colours + 1) + cells) * width + np.arange(width)
    weight = np.broadcast_to((1 << np.arange(BAND_ROWS))[None, :, None], cells.shape)
    bits = np.bincount(key.ravel(), weights=weight.ravel(),
                       minlength=bands * (colours + 1) * width)
    bits = bits.reshape(bands, colours + 1, width)[:, :colours].astype(np.uint8)

    # one output line per (band, colour) present, its trailing empty columns dropped
    band_of, colour_of = np.nonzero(bits.any(axis=2))
    lines = bits[band_of, colour_of]
    length = width - np.argmax(lines[:, ::-1] != 0, axis=1)
    keep = np.arange(width)[None, :] < length[:, None]
    chars = (lines[keep] + 63).astype(np.uint8)  # the lines end to end
    line_of = np.repeat(np.arange(len(lines)), length)

    # runs of one character within a line
    starts_mask = np.ones(len(chars), bool)
    starts_mask[1:] = (chars[1:] != chars[:-1]) | (line_of[1:] != line_of[:-1])
    run_start = np.flatnonzero(starts_mask)
    run_len = np.diff(np.append(run_start, len(chars))).astype(np.int64)
    run_char = chars[run_start]
    run_line = line_of[run_start]
    repeat = run_len >= MIN_REPEAT
    len_digits = _digits(run_len)
    run_bytes = np.where(repeat, 2 + len_digits, run_len)

    # each line: "#<colour>" + runs + "$" (or "-" when it is its band's last)
    colour_digits = _digits(colour_of.astype(np.int64))
    head_bytes = 1 + colour_digits
    line_run_bytes = np.bincount(run_line, weights=run_bytes, minlength=len(lines))
    line_bytes = head_bytes + line_run_bytes.astype(np.int64) + 1
    line_at = np.concatenate(([0], np.cumsum(line_bytes)[:-1]))
    out = np.empty(int(line_bytes.sum()), np.uint8)

    out[line_at] = ord("#")
    _put_numbers(out, line_at + 1, colour_of.astype(np.int64), colour_digits)
    last_of_band = np.ones(len(lines), bool)
    last_of_band[:-1] = band_of[1:] != band_of[:-1]
    out[line_at + line_bytes - 1] = np.where(last_of_band, ord("-"), ord("$"))

    # where each run starts: its line's data start + the bytes of the line's earlier runs
    run_cum = np.cumsum(run_bytes) - run_bytes
    first_run_of_line = np.searchsorted(run_line, np.arange(len(lines)))
    run_at = (line_at + head_bytes)[run_line] + run_cum - run_cum[first_run_of_line][run_line]
    short = ~repeat
    if short.any():  # short runs: the character run_len times
        s_at, s_len, s_char = run_at[short], run_len[short], run_char[short]
        offsets = np.arange(int(s_len.sum())) - np.repeat(np.cumsum(s_len) - s_len, s_len)
        out[np.repeat(s_at, s_len) + offsets] = np.repeat(s_char, s_len)
    if repeat.any():  # long runs: "!<n><char>"
        r_at, r_digits = run_at[repeat], len_digits[repeat]
        out[r_at] = ord("!")
        _put_numbers(out, r_at + 1, run_len[repeat], r_digits)
        out[r_at + 1 + r_digits] = run_char[repeat]

    used = np.unique(colour_of)
    pct = (palette[used].astype(np.int64) * 100 + 127) // 255
    registers = "".join(f"#{c};2;{r};{g};{b}" for c, (r, g, b) in zip(used.tolist(),
                                                                       pct.tolist(),
                                                                       strict=True))
    return (f'{INTRODUCER}"1;1;{width};{height}{registers}' + out.tobytes().decode("ascii")
            + TERMINATOR)
