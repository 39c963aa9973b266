"""Atomic, lossless writes of frames and records.

Every file benchlab writes goes through :func:`atomic_write_bytes`: the data is written to a
temporary file in the same folder, flushed and fsync'd, then renamed over the target, so a
crash leaves either the old file or the new one, never half of either.

Frames are lossless (zlib) ImageJ TIFFs, so Fiji/ImageJ opens them calibrated: pixel size in
um (the frame's ``pixel_size_um``, which the camera driver records: its profile's pitch times
any binning; storage copies it and computes none), display range of the bit depth, Software
"benchlab". The full acquisition metadata is JSON in the ImageJ ``Info`` property (Fiji: Image >
Show Info), so a frame is self-describing without any sidecar. Frames written before that kept
the JSON in the ImageDescription tag; :func:`load_frame_tiff` reads both.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import io
import json
import logging
import math
import os
import tempfile
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from benchlab.drivers.errors import BenchlabError

if TYPE_CHECKING:
    import tifffile

log = logging.getLogger(__name__)

#: Marks benchlab's metadata inside a TIFF ImageDescription.
METADATA_FORMAT = "benchlab.frame"
METADATA_VERSION = 1
#: The TIFF Software tag of every frame benchlab writes.
SOFTWARE = "benchlab"


def printable_name(name: str | os.PathLike[str]) -> str:
    """A file or folder name as text that encodes as UTF-8: bytes that are not UTF-8 (a
    folder named on another system; Python keeps them as surrogate escapes) are shown as
    backslash-x escapes, ``bad\\xffname``. Text that is UTF-8 already is returned as it is.
    For catalogues, pages and certificates, which hold UTF-8 text only."""
    text = os.fspath(name)
    try:
        raw = text.encode("utf-8", "surrogateescape")
    except UnicodeEncodeError:  # a lone surrogate that stands for no byte
        raw = text.encode("utf-8", "backslashreplace")
    return raw.decode("utf-8", "backslashreplace")


@contextlib.contextmanager
def naming(path: str | os.PathLike[str]) -> Iterator[None]:
    """Errors of the writes inside name ``path``: ``write()`` and ``fsync()`` on a full disk
    (ENOSPC), over a size limit (EFBIG) or on a failing device (EIO) raise an ``OSError``
    without a file name, so the user would read "No space left on device" and not where."""
    try:
        yield
    except OSError as exc:
        if exc.filename is not None or exc.errno is None:
            raise
        raise OSError(exc.errno, exc.strerror, os.fspath(path)) from exc


def _current_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


#: mkstemp creates files 0600; saved data must follow the umask like any other file so that
#: analysts in the bench group can read the technician's frames.
_FILE_MODE = 0o666 & ~_current_umask()
#: The same for folders: mkdtemp creates them 0700 (a results version would be private).
_DIR_MODE = 0o777 & ~_current_umask()


def make_staging_dir(folder: str | os.PathLike[str], prefix: str, suffix: str = ".tmp") -> Path:
    """A new, uniquely named folder in ``folder`` (to be filled, then renamed into place) with
    the mode a plain ``mkdir`` would give it, not mkdtemp's private 0700."""
    path = Path(tempfile.mkdtemp(prefix=prefix, suffix=suffix, dir=folder))
    os.chmod(path, _DIR_MODE)
    return path


class FrameFileError(BenchlabError):
    """A frame file is missing, corrupt or not what benchlab wrote."""


def _fsync_dir(folder: Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:  # pragma: no cover - platforms without directory fds
        return
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def atomic_write_bytes(
    path: str | os.PathLike[str], data: bytes, *, overwrite: bool = True, durable: bool = True
) -> Path:
    """Write ``data`` to ``path`` atomically (temp file, fsync, rename).

    With ``overwrite=False`` an existing file is never replaced (``FileExistsError``);
    raw frames use this so nothing already saved can be lost. The target's folder is created
    if missing, but not its parents (``FileNotFoundError``). ``durable=False`` skips the
    fsyncs: only for files inside a folder that is made durable as a whole afterwards
    (:func:`fsync_tree`) before it is renamed into place.
    """
    target = Path(path)
    # Only the last folder level is created: a missing parent is more likely a typo.
    target.parent.mkdir(exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    tmp = Path(tmp_name)
    try:
        os.fchmod(fd, _FILE_MODE)
        with naming(target), os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            if durable:
                os.fsync(fh.fileno())
        if overwrite:
            os.replace(tmp, target)
        else:
            # link() fails if the target exists, which rename() would silently replace.
            os.link(tmp, target)
            tmp.unlink()
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    if durable:
        _fsync_dir(target.parent)
    return target


def write_new_file(path: str | os.PathLike[str], data: bytes) -> Path:
    """Create ``path`` with ``data`` (``FileExistsError`` if it exists), not fsync'd, in
    place: only for files inside a private temporary folder that is flushed and renamed
    into place as a whole (a results version), which is what makes them atomic and durable.
    Saves the temporary name and rename per file of :func:`atomic_write_bytes`."""
    target = Path(path)
    fd = os.open(target, os.O_WRONLY | os.O_CREAT | os.O_EXCL, _FILE_MODE)
    try:
        view = memoryview(data)
        with naming(target):
            while view:
                view = view[os.write(fd, view):]
    finally:
        os.close(fd)
    return target


def fsync_dir(folder: str | os.PathLike[str]) -> None:
    """Make a folder's entries (a rename into it) durable."""
    _fsync_dir(Path(folder))


def fsync_tree(folder: str | os.PathLike[str]) -> int:
    """Flush every file directly in ``folder``, then the folder itself, in one pass.

    One durability barrier for a set of files written with ``durable=False`` (a results
    version): the data are written back together instead of one file at a time with a
    directory sync after each. Returns the number of fsync calls made.
    """
    base = Path(folder)
    calls = 0
    for entry in sorted(base.iterdir()):
        if entry.is_file():
            fd = os.open(entry, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
            calls += 1
    _fsync_dir(base)
    return calls + 1


@functools.cache
def _libc() -> Any:
    """The C library through ctypes when it has ``syncfs`` (Linux), else None."""
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
    except OSError:  # pragma: no cover - no C library to load
        return None
    return libc if hasattr(libc, "syncfs") else None


def _syncfs(fd: int) -> bool:
    """``syncfs(2)`` of the file system holding ``fd``; False where there is none.

    Raises
    ------
    OSError
        The write-back failed (Linux >= 5.8 reports it), with its errno.
    """
    libc = _libc()
    if libc is None:
        return False
    if libc.syncfs(fd) != 0:
        import ctypes

        err = ctypes.get_errno()
        raise OSError(err, os.strerror(err))
    return True


def flush_folder(folder: str | os.PathLike[str]) -> int:
    """Make every file directly in ``folder`` and the folder itself durable with ONE barrier:
    ``syncfs(2)`` of its file system on Linux (one write-back of everything dirty there,
    typically a few ms against ~3 ms per file for fsync), else :func:`fsync_tree`.

    Returns the number of flush calls made (1 with syncfs).
    """
    fd = os.open(folder, os.O_RDONLY)
    try:
        if _syncfs(fd):
            return 1
    finally:
        os.close(fd)
    return fsync_tree(folder)


def atomic_write_text(
    path: str | os.PathLike[str], text: str, *, overwrite: bool = True, durable: bool = True
) -> Path:
    """Atomically write UTF-8 text (see :func:`atomic_write_bytes`)."""
    return atomic_write_bytes(path, text.encode("utf-8"), overwrite=overwrite, durable=durable)


def atomic_write_json(
    path: str | os.PathLike[str], obj: Any, *, overwrite: bool = True, durable: bool = True
) -> Path:
    """Atomically write ``obj`` as indented JSON (NaN is refused: it is not valid JSON)."""
    text = json.dumps(obj, indent=2, sort_keys=False, allow_nan=False, default=json_default)
    return atomic_write_text(path, text + "\n", overwrite=overwrite, durable=durable)


def json_rows_text(rows: list[Any]) -> str:
    """A JSON array written one compact element per line (a results table: one row a line).

    Same JSON as :func:`atomic_write_json` writes, laid out so the C encoder does the work
    (``indent`` makes ``json`` fall back to its pure-Python encoder, ~10x slower; a results
    version of an MTF session spent ~20 ms there). NaN is refused as there.
    """
    if not rows:
        return "[]\n"
    # One encoder for all rows: json.dumps with options builds a new one per call.
    encode = json.JSONEncoder(allow_nan=False, default=json_default).encode
    return "[\n  " + ",\n  ".join(map(encode, rows)) + "\n]\n"


def json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def sha256_file(path: str | os.PathLike[str]) -> str:
    """Hex SHA-256 of a file's bytes (used to prove raw frames are never modified)."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


#: zlib level of saved frames: level 1 compresses a 1280 x 1024 frame in a third of the CPU of
#: the default 6 for ~10 % more bytes (the pixels are the same: lossless either way).
ZLIB_LEVEL = 1


#: Bytes of uncompressed rows per zlib strip: tifffile's default (~256 KB per strip).
STRIP_BYTES = 262144


def zlib_strips(pixels: npt.NDArray[Any], level: int | None = None
                ) -> tuple[Iterator[bytes], int]:
    """A 2-D array's TIFF strips compressed by Python's :mod:`zlib`, and the rows per strip:
    for ``tifffile`` to write as they are (``data=`` the strips, with ``shape``, ``dtype``,
    ``rowsperstrip`` and ``compression="zlib"``).

    What ``compression="zlib"`` gives with tifffile's own codec, byte for byte (same strips of
    ``STRIP_BYTES // row bytes`` rows, each ``zlib.compress(rows, level)``, default level 6),
    whichever codec tifffile would pick itself: with ``imagecodecs`` installed (read for its
    faster inflate) tifffile deflates with libdeflate, whose streams differ, so a frame written
    today would no longer be the bytes of the same frame written before."""
    import zlib

    arr = np.ascontiguousarray(pixels)
    if arr.ndim != 2:
        raise ValueError(f"strips of a 2-D array, got shape {arr.shape}")
    height = arr.shape[0]
    rows = min(max(STRIP_BYTES // max(arr.shape[1] * arr.itemsize, 1), 1), max(height, 1))
    lvl = 6 if level is None else level

    def strips() -> Iterator[bytes]:
        for r0 in range(0, height, rows):
            yield zlib.compress(arr[r0:r0 + rows].tobytes(), lvl)

    return strips(), rows


def encode_frame_tiff(pixels: npt.NDArray[Any], metadata: Mapping[str, Any]) -> bytes:
    """Encode a 2-D uint8/uint16 frame and its metadata as lossless TIFF bytes."""
    arr = np.asarray(pixels)
    if arr.ndim != 2:
        raise ValueError(f"frame must be 2-D, got shape {arr.shape}")
    if arr.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"frame dtype must be uint8 or uint16, got {arr.dtype}")
    meta = {"format": METADATA_FORMAT, "version": METADATA_VERSION, **dict(metadata)}
    size_um = pixel_size_um(meta)
    info = json.dumps(meta, allow_nan=False, default=json_default)
    imagej: dict[str, Any] = {"axes": "YX", "Info": info}
    resolution = None
    if size_um is not None:  # calibrated in Fiji: pixels per um
        imagej["unit"] = "um"
        resolution = (1.0 / size_um[0], 1.0 / size_um[1])
    bits = meta.get("bits")
    if isinstance(bits, int) and 8 <= bits <= 16:
        imagej.update(min=0.0, max=float(2**bits - 1))  # Fiji's display range: the bit depth
    import tifffile  # here: reading a frame back does not need it (start-up, issue 11)

    buf = io.BytesIO()
    strips, rows = zlib_strips(arr, ZLIB_LEVEL)
    tifffile.imwrite(buf, strips, shape=arr.shape, dtype=arr.dtype, rowsperstrip=rows,
                     imagej=True, resolution=resolution, metadata=imagej, software=SOFTWARE,
                     compression="zlib")
    return buf.getvalue()


def pixel_size_um(metadata: Mapping[str, Any]) -> tuple[float, float] | None:
    """Pixel size ``(x, y)`` in um on the sensor as the camera driver recorded it in the frame's
    metadata (``pixel_size_um``: the profile's pitch times the binning), or None when the
    metadata does not say (the frame is then written without a calibration, never a guessed
    one).

    Raises
    ------
    ValueError
        ``pixel_size_um`` is not two positive finite numbers.
    """
    size = metadata.get("pixel_size_um")
    if size is None:
        return None
    try:
        x_um, y_um = (float(v) for v in size)
    except (TypeError, ValueError):
        raise ValueError(f"frame metadata pixel_size_um must be [x, y] in um, got {size!r}"
                         ) from None
    if not (math.isfinite(x_um) and math.isfinite(y_um) and x_um > 0 and y_um > 0):
        raise ValueError(f"frame metadata pixel_size_um must be positive, got {size!r}")
    return x_um, y_um


def save_frame_tiff(
    path: str | os.PathLike[str],
    pixels: npt.NDArray[Any],
    metadata: Mapping[str, Any],
    *,
    overwrite: bool = False,
) -> Path:
    """Save a frame losslessly and atomically; by default refuses to replace an existing file."""
    saved = atomic_write_bytes(path, encode_frame_tiff(pixels, metadata), overwrite=overwrite)
    log.debug("frame saved: %s", saved)
    return saved


def check_bit_depth(path: str | os.PathLike[str], pixels: npt.NDArray[Any],
                    metadata: Mapping[str, Any]) -> None:
    """Refuse a frame whose codes its own ``bits`` metadata rules out (12-bit data above
    4095, say): analysing it would use the wrong saturation level and noise model.

    Raises
    ------
    FrameFileError
        Naming the file, the metadata value and the largest code found.
    """
    bits = metadata.get("bits")
    if bits is None:
        return
    if isinstance(bits, bool) or not isinstance(bits, int) or not 1 <= bits <= 16:
        raise FrameFileError(f"{path}: metadata field 'bits' must be an integer 1..16, "
                             f"got {bits!r}")
    arr = np.asarray(pixels)
    if arr.size == 0 or not np.issubdtype(arr.dtype, np.integer):
        return
    top = int(arr.max())
    if top > (1 << bits) - 1:
        raise FrameFileError(f"{path}: metadata says {bits}-bit but the frame holds codes up to "
                             f"{top} (> {(1 << bits) - 1})")


def _metadata_text(tif: tifffile.TiffFile) -> str:
    """The benchlab JSON of a TIFF: the ImageJ Info property of frames written since they are
    ImageJ TIFFs, the first ImageDescription of older ones ("" when there is none)."""
    ij = tif.imagej_metadata if tif.is_imagej else None
    if ij:
        return str(ij.get("Info") or "")
    return tif.pages.first.description or ""


def _all_pages(path: Path, tif: Any) -> npt.NDArray[Any]:
    """Every frame of a TIFF: its one series as tifffile reads it (a benchlab frame, a stack
    written at once, an ImageJ hyperstack), or, for pages appended one by one (a series per
    page), every page stacked - shapes and dtypes must match (FrameFileError naming the page
    and what differs)."""
    if len(tif.series) <= 1:
        return np.asarray(tif.asarray())
    frames = [np.asarray(page.asarray()) for page in tif.pages]
    first = frames[0]
    for i, f in enumerate(frames[1:], start=2):
        if f.shape != first.shape or f.dtype != first.dtype:
            raise FrameFileError(
                f"{path}: page {i} is {f.shape} {f.dtype}, page 1 {first.shape} {first.dtype}: "
                "a multi-page TIFF is read as a stack of same-sized frames")
    return np.stack(frames)


def read_tiff_pixels(path: str | os.PathLike[str]) -> npt.NDArray[Any]:
    """The pixels of any monochrome TIFF for analysis (a multi-page TIFF gives a stack).

    A colour TIFF (RGB samples; grey stored as three equal channels is accepted) is refused
    instead of being read as a stack of 3-pixel-wide frames, and a benchlab frame's codes
    are checked against its ``bits`` metadata (:func:`check_bit_depth`).

    Raises
    ------
    FrameFileError
        Missing, unreadable or colour file, or codes its metadata rules out, naming it.
    """
    return read_tiff_frame(path)[0]


def read_tiff_frame(path: str | os.PathLike[str]
                    ) -> tuple[npt.NDArray[Any], dict[str, Any] | None]:
    """:func:`read_tiff_pixels` and the file's benchlab metadata (None for any other TIFF):
    what the camera knew of the frame (``bits``: its ceiling) beside the pixels."""
    import tifffile

    p = Path(path)
    try:
        with tifffile.TiffFile(p) as tif:
            page = tif.pages.first
            samples = int(page.samplesperpixel)
            colour = page.photometric in (tifffile.PHOTOMETRIC.RGB,
                                          tifffile.PHOTOMETRIC.PALETTE,
                                          tifffile.PHOTOMETRIC.YCBCR)
            pixels = _all_pages(p, tif)
            description = _metadata_text(tif)
    except FrameFileError:
        raise
    except FileNotFoundError as exc:
        raise FrameFileError(f"{p}: no such file") from exc
    except Exception as exc:  # tifffile raises several types for corrupt data
        raise FrameFileError(f"{p}: not a readable TIFF ({exc})") from exc
    if samples > 1 or colour:
        if samples >= 3 and pixels.shape[-1] == samples:
            rgb = pixels[..., :3]
            if np.all(rgb == rgb[..., :1]):
                pixels = rgb[..., 0]
                samples, colour = 1, False
        if samples > 1 or colour:
            raise FrameFileError(f"{p}: colour TIFF ({samples} samples per pixel); benchlab "
                                 "analyses monochrome frames")
    try:
        meta = json.loads(description) if description else None
    except ValueError:
        meta = None
    if isinstance(meta, dict) and meta.get("format") == METADATA_FORMAT:
        check_bit_depth(p, pixels, meta)
        return pixels, meta
    return pixels, None


def load_frame_tiff(path: str | os.PathLike[str], data: bytes | None = None
                    ) -> tuple[npt.NDArray[Any], dict[str, Any]]:
    """Load a frame written by :func:`save_frame_tiff`: ``(pixels, metadata)``.

    ``data``: the file's bytes already read (and hash-checked) by the caller, decoded instead
    of reading the file again, so the pixels are exactly the bytes that were checked.

    Raises :class:`FrameFileError` naming the file when it is missing, unreadable, not 2-D,
    carries no benchlab metadata, or holds codes its ``bits`` rule out
    (:func:`check_bit_depth`, as :func:`read_tiff_frame` does for the analysis paths).
    """
    p = Path(path)
    try:
        if data is None:
            data = p.read_bytes()
        import tifffile

        with tifffile.TiffFile(tifffile.FileHandle(io.BytesIO(data), name=p.name)) as tif:
            pixels = tif.pages.first.asarray()
            description = _metadata_text(tif)
    except FileNotFoundError as exc:
        raise FrameFileError(f"{p}: no such frame file") from exc
    except Exception as exc:  # tifffile raises several types for corrupt data
        raise FrameFileError(f"{p}: not a readable TIFF ({exc})") from exc
    if pixels.ndim != 2:
        raise FrameFileError(f"{p}: expected a 2-D monochrome frame, got shape {pixels.shape}")
    try:
        meta = json.loads(description)
    except (TypeError, ValueError) as exc:
        raise FrameFileError(f"{p}: ImageDescription is not benchlab JSON metadata") from exc
    if not isinstance(meta, dict) or meta.get("format") != METADATA_FORMAT:
        raise FrameFileError(f"{p}: TIFF has no benchlab frame metadata")
    # As every analysis path reads a frame (read_tiff_frame): codes its bits rule out.
    check_bit_depth(p, pixels, meta)
    return pixels, meta
