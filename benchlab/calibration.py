"""The response calibration: a versioned file referenced from the bench configuration.

``benchlab run characterise`` writes ``calibration/response-vN.json`` (never overwritten) next
to the bench configuration file and points the file's ``[camera] response_calibration`` at it,
so every later run on that bench records which calibration it used (the session's bench
snapshot) and radiometry linearises its readings with it. The packaged simulated bench file is
not ours to edit: with ``--simulate`` and no ``--config``, the calibration goes to
``SESSIONS/calibration/`` beside a copy of the simulated bench file that references it
(``bench-vN.toml``; pass it as ``--config``).
"""

from __future__ import annotations

import hashlib
import json
import re
import tomllib
from collections.abc import Callable, Mapping
from importlib import resources
from pathlib import Path
from typing import Any

from benchlab.analysis.camera.photon_transfer import ResponseCurve, linearise
from benchlab.drivers.errors import BenchlabError
from benchlab.storage import (
    atomic_write_bytes,
    atomic_write_json,
    atomic_write_text,
    sha256_file,
)

FORMAT = "benchlab-response-calibration"
_VERSION_RE = re.compile(r"^response-v(\d+)\.json$")


class CalibrationError(BenchlabError):
    """A response calibration file is missing, unreadable or has no curve for a setting."""


def _packaged_bench() -> Path:
    return Path(str(resources.files("benchlab.protocols") / "defaults" / "bench-simulated.toml"))


def _next_version(folder: Path) -> int:
    found = [int(m.group(1)) for p in folder.glob("response-v*.json")
             if (m := _VERSION_RE.match(p.name))]
    return max(found, default=0) + 1


#: A ``[camera]`` table header line: any spacing, an optional trailing comment.
_CAMERA_HEADER = re.compile(r"^\s*\[\s*camera\s*\]\s*(#.*)?$")
#: Any table or array-of-tables header line (the end of the ``[camera]`` section).
_ANY_HEADER = re.compile(r"^\s*\[")
_REFERENCE_KEY = re.compile(r"^\s*response_calibration\s*=")


def set_camera_reference(text: str, value: str, source: str = "<bench file>") -> str:
    """Bench TOML text with ``[camera] response_calibration = value`` set (added after the
    ``[camera]`` header, or that key's line replaced; a ``[camera]`` table appended when the
    file has none); every other line unchanged.

    The result is checked before it is returned: parsed, it must equal the original with only
    that key set, and pass the bench configuration's validation.

    Raises
    ------
    CalibrationError
        Naming ``source`` and the key when the text is not valid TOML, when the camera is
        given as dotted keys (``camera.serial = ...``) or an inline table (``camera = {...}``),
        which cannot be edited line by line safely, or when the edited text would not check.
    """
    from benchlab.bench import BenchConfig, BenchConfigError

    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise CalibrationError(f"{source}: not valid TOML ({exc}); not edited") from exc
    newline = "\r\n" if "\r\n" in text else "\n"
    line = f"response_calibration = {json.dumps(value)}"
    lines = text.splitlines()
    headers = [i for i, ln in enumerate(lines) if _CAMERA_HEADER.match(ln)]
    camera = data.get("camera")
    if "camera" in data and (not isinstance(camera, dict) or len(headers) != 1):
        raise CalibrationError(
            f"{source}: camera: given as dotted keys or an inline table, which benchlab cannot "
            "edit safely to set camera.response_calibration; write it as a [camera] table "
            "(one key per line); file not edited")
    if not headers:
        lines += ["", "[camera]", line]
    else:
        header = headers[0]
        end = next((i for i in range(header + 1, len(lines)) if _ANY_HEADER.match(lines[i])),
                   len(lines))
        key = next((i for i in range(header + 1, end) if _REFERENCE_KEY.match(lines[i])), None)
        if key is None:
            lines.insert(header + 1, line)
        else:
            lines[key] = line
    out = newline.join(lines) + newline
    expected = {**data, "camera": {**(camera if isinstance(camera, dict) else {}),
                                   "response_calibration": value}}
    try:
        parsed = tomllib.loads(out)
    except tomllib.TOMLDecodeError as exc:
        parsed = {"<unparsable>": str(exc)}
    if parsed != expected:
        raise CalibrationError(f"{source}: camera.response_calibration: could not be set "
                               "without changing other keys (a multi-line value?); set it "
                               "by hand; file not edited")
    try:
        BenchConfig.from_dict(parsed, source)
    except BenchConfigError as exc:
        raise CalibrationError(f"{source}: {'; '.join(exc.problems)}; file not edited") from exc
    return out


def _bench_file(config: Any) -> tuple[Path | None, bool, bool]:
    """``(source, editable, packaged)``: the bench TOML a configuration was read from, whether
    it is the user's (edited to reference the calibration) or the packaged simulated bench."""
    source = Path(config.source) if config.source and not config.source.startswith("<") else None
    is_file = source is not None and source.suffix == ".toml" and source.is_file()
    packaged = is_file and source is not None and source.resolve() == _packaged_bench().resolve()
    return source, is_file and not packaged, packaged


def check_bench_editable(config: Any) -> None:
    """Refuse, before a characterisation starts, a bench file its end could not point at the
    new calibration (camera as dotted keys or an inline table): :class:`CalibrationError`."""
    source, editable, _ = _bench_file(config)
    if editable and source is not None:
        set_camera_reference(source.read_text(encoding="utf-8"), "calibration/response-v1.json",
                             str(source))


def write_calibration(session: Any, results: Path, config: Any) -> dict[str, Any]:
    """Write the calibration of a characterisation results version; point the bench
    configuration at it. Returns ``{file, sha256, version, bench_config}``."""
    summary = json.loads((Path(results) / "summary.json").read_text(encoding="utf-8"))
    curves = summary.get("summary", {}).get("response_curves") or []
    if not curves:
        raise CalibrationError(f"{results}: no response curve to calibrate with")
    source, editable, packaged = _bench_file(config)
    folder = (source.parent if editable and source is not None
              else Path(session.path).parent) / "calibration"
    folder.mkdir(parents=True, exist_ok=True)
    version = _next_version(folder)
    target = folder / f"response-v{version}.json"
    doc = {"format": FORMAT, "version": version, "session": str(session.path),
           "results": str(results), "results_version": summary.get("version"),
           "camera": session.meta.get("devices", {}).get("camera"), "curves": curves}
    # The edited bench text is built and checked before anything is written: a bench file
    # that cannot be edited leaves no response file behind (a resume would add another).
    bench_file: Path | None = None
    bench_text = None
    if editable and source is not None:
        bench_file = source
        bench_text = set_camera_reference(bench_file.read_text(encoding="utf-8"),
                                          f"calibration/{target.name}", str(bench_file))
    elif packaged:
        bench_file = folder / f"bench-v{version}.toml"
        bench_text = set_camera_reference(_packaged_bench().read_text(encoding="utf-8"),
                                          target.name, str(_packaged_bench()))
    atomic_write_json(target, doc, overwrite=False)
    if bench_file is not None and bench_text is not None:
        atomic_write_text(bench_file, bench_text)
    # Otherwise (a configuration rebuilt from a session snapshot) there is no file to edit:
    # the calibration is written and its path reported.
    return {"file": str(target), "sha256": sha256_file(target), "version": version,
            "bench_config": str(bench_file) if bench_file is not None else None}


def load_calibration(path: str | Path) -> dict[str, Any]:
    """Read a calibration file (or the one a bench TOML references)."""
    p = Path(path)
    if p.suffix == ".toml":
        from benchlab.bench import BenchConfig

        ref = BenchConfig.load(p).camera.response_calibration
        if ref is None:
            raise CalibrationError(f"{p}: no [camera] response_calibration")
        p = Path(ref)
    return parse_calibration(p, _read_bytes(p))


def _read_bytes(p: Path) -> bytes:
    try:
        return p.read_bytes()
    except FileNotFoundError as exc:
        raise CalibrationError(f"{p}: no such response calibration file") from exc
    except OSError as exc:
        raise CalibrationError(f"{p}: unreadable response calibration ({exc})") from exc


def parse_calibration(p: Path, data: bytes) -> dict[str, Any]:
    """A calibration document from the bytes of file ``p`` (checked), with ``path`` and the
    ``sha256`` of exactly those bytes."""
    try:
        doc = json.loads(data.decode("utf-8"))
    except ValueError as exc:
        raise CalibrationError(f"{p}: unreadable response calibration ({exc})") from exc
    if not isinstance(doc, Mapping) or doc.get("format") != FORMAT:
        raise CalibrationError(f"{p}: not a benchlab response calibration (format)")
    if not isinstance(doc.get("curves"), list) or not doc["curves"]:
        raise CalibrationError(f"{p}: curves: missing or empty")
    return {**doc, "path": str(p), "sha256": hashlib.sha256(data).hexdigest()}


def curve_for(doc: Mapping[str, Any], gain: float, bits: int) -> ResponseCurve:
    """The curve for a gain and bit depth; a curve of the same gain at the other bit depth is
    rescaled (x16). Raises :class:`CalibrationError` naming the file when there is none."""
    for want_bits, factor in ((bits, 1.0), (20 - bits, 16.0 if bits == 12 else 1 / 16.0)):
        for c in doc["curves"]:
            if abs(float(c.get("gain", -1)) - gain) < 1e-9 and int(c.get("bits", 0)) == want_bits:
                try:
                    return ResponseCurve(
                        gain=gain, bits=bits, black_level_dn=float(c["black_level_dn"]) * factor,
                        measured_dn=tuple(float(v) * factor for v in c["measured_dn"]),
                        linear_dn=tuple(float(v) * factor for v in c["linear_dn"]),
                    )
                except (KeyError, TypeError, ValueError) as exc:
                    raise CalibrationError(f"{doc.get('path')}: curve gain {gain:g} / {bits}-bit "
                                           f"is malformed ({exc})") from exc
    have = ", ".join(f"gain {c.get('gain')} {c.get('bits')}-bit" for c in doc["curves"])
    raise CalibrationError(f"{doc.get('path')}: no curve for gain {gain:g}, {bits}-bit "
                           f"(has {have})")


def linearisation_record(doc: Mapping[str, Any], gain: float, bits: int) -> dict[str, Any]:
    """What a result records about the linearisation it used."""
    return {"file": doc.get("path"), "sha256": doc.get("sha256"), "version": doc.get("version"),
            "gain": gain, "bits": bits}


#: Where a session keeps its copy of the calibration it was started with.
SESSION_CALIBRATION_DIR = "calibration"
#: ``session.json`` key of the record ``{file, sha256, copy}`` written at session start.
SESSION_CALIBRATION_KEY = "response_calibration"


def read_run_calibration(config: Any) -> tuple[Path, bytes] | None:
    """The calibration file a bench configuration references, read and checked before a run
    starts (so a missing or damaged one is refused before any session exists); None when
    there is none."""
    ref = config.camera.response_calibration
    if not ref:
        return None
    p = Path(ref).absolute()
    data = _read_bytes(p)
    parse_calibration(p, data)
    return p, data


def check_run_curve(calibration: tuple[Path, bytes], gain: float, bits: int) -> None:
    """Refuse, before a run starts, a calibration (from :func:`read_run_calibration`) without
    a curve for the gain and bit depth the run's analysis will linearise:
    :class:`CalibrationError` naming the file, the gain and bit depth and the curves it has."""
    curve_for(parse_calibration(*calibration), gain, bits)


def keep_session_calibration(session: Any, source: Path, data: bytes) -> dict[str, Any]:
    """Copy the calibration into the session folder (atomic, never overwritten) and record
    ``{file, sha256, copy}`` in ``session.json``: every analysis of the session uses the copy,
    whatever the original file becomes."""
    copy = Path(session.path) / SESSION_CALIBRATION_DIR / source.name
    copy.parent.mkdir(exist_ok=True)
    atomic_write_bytes(copy, data, overwrite=False)
    record = {"file": str(source), "sha256": hashlib.sha256(data).hexdigest(),
              "copy": copy.relative_to(session.path).as_posix()}
    session.update_meta(**{SESSION_CALIBRATION_KEY: record})
    session.log_event("response_calibration_recorded", **record)
    return record


def _earlier_sha256(session: Any) -> str | None:
    """The calibration sha256 an earlier results version of a session used (sessions started
    before the calibration was recorded at start): the oldest version that says."""
    for version in session.result_versions():
        try:
            doc = json.loads((session.results_dir / f"v{version}" / "summary.json")
                             .read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue
        used = (doc.get("summary") or {}).get("linearised") if isinstance(doc, dict) else None
        if isinstance(used, Mapping) and used.get("sha256"):
            return str(used["sha256"])
    return None


def session_calibration(session: Any) -> dict[str, Any] | None:
    """The calibration document a session was run with, or None when it used none.

    Read from the session's own copy (its sha256 checked against the record); a session
    started before the copy existed reads the file its bench snapshot names, and is refused
    when that file differs from the one an earlier results version used.

    Raises
    ------
    CalibrationError
        Naming the file and both sha256 when the calibration is not the one recorded.
    """
    rec = session.meta.get(SESSION_CALIBRATION_KEY)
    if isinstance(rec, Mapping) and rec.get("copy"):
        copy = Path(session.path) / str(rec["copy"])
        doc = parse_calibration(copy, _read_bytes(copy))
        if doc["sha256"] != rec.get("sha256"):
            raise CalibrationError(
                f"{copy}: response calibration changed since the session started (recorded "
                f"sha256 {rec.get('sha256')}, now {doc['sha256']}); not analysed")
        return {**doc, "path": str(rec.get("file") or copy), "copy": str(rec["copy"])}
    ref = ((session.params.get("bench") or {}).get("camera") or {}).get("response_calibration")
    if not ref:
        return None
    doc = load_calibration(ref)
    used = _earlier_sha256(session)
    if used is not None and used != doc["sha256"]:
        raise CalibrationError(
            f"{Path(ref).absolute()}: not the response calibration this session was analysed "
            f"with (sha256 then {used}, now {doc['sha256']}); not analysed")
    return {**doc, "path": str(Path(ref).absolute())}


def session_linearisation(
    session: Any, gain: float, bits: int
) -> tuple[Callable[[Any], Any], dict[str, Any] | None]:
    """``(linearise_fn, record)`` for a session: the calibration it was run with
    (:func:`session_calibration`), or the identity and None when there is none."""
    doc = session_calibration(session)
    if doc is None:
        return (lambda pixels: pixels), None
    curve = curve_for(doc, gain, bits)
    record = linearisation_record(doc, gain, bits)
    if doc.get("copy"):
        record["copy"] = doc["copy"]
    return (lambda pixels: linearise(pixels, curve)), record
