"""Result versions: ``results/v<N>/`` written atomically and never edited, and the one
reader of such a folder."""

from __future__ import annotations

import csv
import errno
import hashlib
import io
import json
import os
import shutil
from collections.abc import Collection, Iterable, Mapping
from pathlib import Path
from typing import Any

from benchlab.session.layout import (
    _VERSION_DIR,
    CSV_MISSING,
    SessionError,
    _check_name,
    _now_iso,
    _plain,
)
from benchlab.session.retakes import SessionRetakes
from benchlab.storage import (
    atomic_write_json,
    atomic_write_text,
    flush_folder,
    fsync_dir,
    fsync_tree,
    json_default,
    json_rows_text,
    make_staging_dir,
    write_new_file,
)

#: Flush policy of a results version: "syncfs" (files written, then ONE flush of the file
#: system, syncfs(2), before the rename; falls back to "per-version" off Linux),
#: "per-version" (each file fsync'd once before the rename) or "per-file" (each file and its
#: folder fsync'd as it is written, the old behaviour). ``benchlab benchmark batch`` measures
#: all three. The journal lines resume depends on are fsync'd one by one whatever this says.
RESULTS_FSYNC = "syncfs"


class SessionResults(SessionRetakes):
    """Writes and reads result versions."""

    def __init__(self, path: Path, meta: dict[str, Any]) -> None:
        super().__init__(path, meta)
        #: Set by :meth:`mark_results_partial`: written into every new results version.
        self._partial: dict[str, Any] | None = None
        #: Set by a re-analysis: :meth:`write_results` first checks every recorded frame
        #: (:meth:`verify_frames`), so results are never written from changed frames - also
        #: when the analysis started before the last frames had finished loading.
        self.verify_frames_before_results = False
        #: Set by a re-analysis: :meth:`write_results` adds no version when an existing one
        #: has the same inputs (frames), settings, software version and byte-identical
        #: results; it returns that version and sets :attr:`matched_version`.
        self.reuse_identical_results = False
        #: The version the last :meth:`write_results` matched instead of writing (or None).
        self.matched_version: int | None = None

    def results_stale(self) -> str | None:
        """Why the latest results no longer describe the current frames (a retake adopted
        after they were written), or None."""
        latest = self.latest_results()
        adopted = [r for r in self.retakes() if r["status"] == "adopted"]
        if latest is None or not adopted:
            return None
        try:
            created = str(json.loads((latest / "summary.json").read_text(encoding="utf-8"))
                          .get("created_at", ""))
        except (OSError, ValueError, AttributeError):
            created = ""
        later = [r for r in adopted if str(r.get("adopted_at", "")) > created]
        if not later:
            return None
        steps = sorted({s for r in later for s in r["steps"]})
        return (f"results {latest.name} predate retake {later[-1]['id']} of "
                f"{', '.join(steps)}; run benchlab analyze {self.path}")

    # ------------------------------------------------------------------ results
    def mark_results_partial(self, status: str, steps_done: int, steps_total: int) -> None:
        """Results written from now on come from an incomplete session: ``summary.json`` says
        ``"partial": true`` with the session status and the steps done."""
        self._partial = {"partial": True, "session_status": status,
                         "steps_done": steps_done, "steps_total": steps_total}

    def result_versions(self) -> list[int]:
        """Existing results versions, ascending: ``results/v<N>`` folders holding their
        summary.json (an empty or partial folder - a crash of older software between
        claiming a number and filling it - is no version)."""
        if not self.results_dir.is_dir():
            return []
        found = []
        for p in self.results_dir.iterdir():
            m = _VERSION_DIR.match(p.name)
            if m and (p / "summary.json").is_file():
                found.append(int(m.group(1)))
        return sorted(found)

    def latest_results(self) -> Path | None:
        """The newest ``results/v<N>`` folder, or None before the first analysis."""
        versions = self.result_versions()
        return self.results_dir / f"v{versions[-1]}" if versions else None

    def tables(self) -> list[str]:
        """The tables of the latest results version, by file name (``forward_view_modulation``,
        ...), in the thesis' table order; empty before the first analysis."""
        latest = self.latest_results()
        return [] if latest is None else _table_names(read_results(latest, only=())[1])

    def table(self, name: str) -> list[dict[str, Any]]:
        """One table of the latest results version: a list of rows (column -> value).

        Parameters
        ----------
        name : str
            Its file name (``"forward_view_modulation"``, see :meth:`tables`) or its thesis
            label (``"table_4_11"``).

        Returns
        -------
        list of dict
            Read from the table's JSON file, so values keep their types (numbers, booleans,
            lists); a missing value (NaN when written) is ``None``.

        Raises
        ------
        SessionError
            No results yet, or no such table (the message lists the tables there are), or the
            file is damaged.
        """
        latest = self.latest_results()
        if latest is None:
            raise SessionError(f"{self.path}: no results yet (session {self.status}), so no "
                               f"table {name!r}")
        label = _LABEL_OF_FILE.get(name, name)
        tables, summary = read_results(latest, only=(label,))
        rows = tables.get(label)
        if label not in _table_labels(summary) or not isinstance(rows, list):
            raise SessionError(f"{latest}: no table {name!r}; its tables: "
                               f"{', '.join(_table_names(summary)) or 'none'}")
        return rows

    def _identical_version(self, staged: Path, same: Mapping[str, Any]) -> int | None:
        """The newest existing version with the summary ``same`` (inputs, settings, software
        version, summary) and byte-identical files to the ``staged`` folder; None if none."""
        staged_files: dict[str, bytes] | None = None
        for version in reversed(self.result_versions()):
            folder = self.results_dir / f"v{version}"
            if not _same_summary(folder, same):
                continue
            if staged_files is None:
                staged_files = _tree_bytes(staged)
            if _tree_bytes(folder) == staged_files:
                return version
        return None

    def write_results(
        self,
        tables: Mapping[str, list[dict[str, Any]]],
        *,
        summary: Mapping[str, Any],
        estimator: str,
        extra_dirs: Mapping[str, Path] | None = None,
    ) -> Path:
        """Write a new results version: ``<file>.csv`` + ``<file>.json`` per table (file names
        from :data:`RESULT_FILE_STEMS`, e.g. ``forward_view_modulation`` for ``table_4_11``),
        and summary.json (which maps each table label to its file). ``extra_dirs``: folders
        already written under ``results/`` (``name -> folder``), moved into the version as
        ``name`` before it appears, so the version never exists without them.

        The version folder is assembled under a temporary name and renamed into place, so a
        crash never leaves a half-written version; existing versions are never touched.
        NaN is written as ``null`` in JSON and ``NA`` in CSV. With :attr:`reuse_identical_results`
        (a re-analysis) a version whose summary differs only in its number and time and whose
        files are byte-identical is returned instead (:attr:`matched_version`; journal event
        ``results_matched``): fifty identical re-analyses leave one version, anything else
        still adds one. With :data:`RESULTS_FSYNC`
        ``"syncfs"`` (default) or ``"per-version"`` the files are flushed together just before
        the rename (one file-system flush, or one fsync per file), instead of a file and
        directory fsync per file; either way the version is on disk before this returns.
        """
        per_file = RESULTS_FSYNC == "per-file"
        for table in tables:
            _check_name("table name", table)
        if self.verify_frames_before_results:
            bad = self.verify_frames()
            if bad:
                raise SessionError(f"{self.path}: frames changed since acquisition: "
                                   f"{', '.join(bad)}; no results written")
        self.results_dir.mkdir(exist_ok=True)
        tmp = make_staging_dir(self.results_dir, ".v-")

        def write(path: Path, text: str) -> None:
            if per_file:
                atomic_write_text(path, text)
            else:  # the folder is private until its rename: no temporary file per file
                write_new_file(path, text.encode("utf-8"))

        try:
            for name, folder in (extra_dirs or {}).items():
                _check_name("folder name", name)
                os.replace(folder, tmp / name)  # same file system: a rename
            files_sha256: dict[str, str] = {}
            for table, rows in tables.items():
                plain_rows = [_plain(dict(r)) for r in rows]
                stem = result_file_stem(table)
                for name, text in ((f"{stem}.json", json_rows_text(plain_rows)),
                                   (f"{stem}.csv", _csv_text(plain_rows))):
                    write(tmp / name, text)
                    files_sha256[name] = hashlib.sha256(text.encode("utf-8")).hexdigest()
            self.matched_version = None
            same = {
                "estimator": estimator,
                "software_version": _software_version(),
                "tables": sorted(tables),
                "table_files": {t: result_file_stem(t) for t in sorted(tables)},
                "frames_sha256": self.frames(),
                # The tables certify themselves: read_results refuses a file that changed.
                "files_sha256": dict(sorted(files_sha256.items())),
                "summary": _plain(summary),
                **(self._partial or {"partial": False}),
            }
            if self.reuse_identical_results:
                matched = self._identical_version(tmp, same)
                if matched is not None:
                    shutil.rmtree(tmp, ignore_errors=True)
                    self.matched_version = matched
                    self.log_event("results_matched", durable=False, version=matched,
                                   estimator=estimator)
                    return self.results_dir / f"v{matched}"
            version = (self.result_versions() or [0])[-1] + 1
            while True:
                doc = {"version": version, "created_at": _now_iso(), **same}
                atomic_write_json(tmp / "summary.json", doc, durable=per_file)
                if RESULTS_FSYNC == "syncfs":
                    flush_folder(tmp)
                elif not per_file:
                    fsync_tree(tmp)
                target = self.results_dir / f"v{version}"
                try:
                    # Atomic, and only onto a free name (or an empty folder, left by a crash
                    # of older software): no moment where v<N> exists but is not complete.
                    os.rename(tmp, target)
                except OSError as exc:
                    if not (isinstance(exc, FileExistsError)
                            or exc.errno in (errno.EEXIST, errno.ENOTEMPTY)):
                        raise
                    # Another writer's version, or a folder that is none: the next number.
                    version = max(version + 1, (self.result_versions() or [0])[-1] + 1)
                    continue
                fsync_dir(self.results_dir)  # the rename itself
                break
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        # Not fsync'd: the version is already durable and resume does not read this line.
        self.log_event("results_written", durable=False, version=version, estimator=estimator)
        return target



def _software_version() -> str:
    import benchlab

    return str(benchlab.__version__)


def _tree_bytes(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (relative path -> bytes), ``summary.json`` left out."""
    files = {p.relative_to(folder).as_posix(): p for p in folder.rglob("*") if p.is_file()}
    return {rel: p.read_bytes() for rel, p in sorted(files.items()) if rel != "summary.json"}


def _same_summary(folder: Path, same: Mapping[str, Any]) -> bool:
    """Whether ``folder``'s summary.json is ``same`` but for its version number and time."""
    try:
        doc = json.loads((folder / "summary.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    if not isinstance(doc, dict):
        return False
    doc.pop("version", None)
    doc.pop("created_at", None)
    try:  # through JSON: the stored document's types (lists for tuples, str keys)
        want = json.loads(json.dumps(same, allow_nan=False, default=json_default))
    except (TypeError, ValueError):
        return False
    return bool(doc == want)


#: Result files are named after what they hold; the thesis table stays the table's label
#: (the key in ``tables``, the report's caption). Labels not listed are their own file names.
RESULT_FILE_STEMS: dict[str, str] = {
    "table_4_11": "forward_view_modulation",
    "table_4_12": "radial_view_modulation",
    "table_4_13": "image_heights_field_points",
    "table_4_15": "averaged_mtf_vs_monte_carlo",
    "table_4_16": "relative_radiometry",
}
_LABEL_OF_FILE = {stem: label for label, stem in RESULT_FILE_STEMS.items()}


def result_file_stem(label: str) -> str:
    """The file name (without ``.csv`` / ``.json``) a results table is written under."""
    return RESULT_FILE_STEMS.get(label, label)


def read_results(folder: str | os.PathLike[str], only: Collection[str] | None = None,
                 skip: Collection[str] = ()) -> tuple[dict[str, Any], dict[str, Any]]:
    """Tables (``label -> rows``) and ``summary.json`` of one ``results/vN`` folder; with
    ``only``, just the tables of those labels; tables labelled in ``skip`` are not read (the
    catalogue skips the SFR curves, the largest file of a version).

    Reads both the descriptive file names and the older thesis-table file names
    (``table_4_11.json``), so sessions written before the rename still load.
    Raises :class:`SessionError` naming the file when a JSON file is unreadable, when
    ``summary.json`` is not an object, or when a table it lists (and that was asked for) is
    missing or is not a list of row objects: a damaged version is an error, never a report or
    a listing with a table silently left out.
    """
    tables: dict[str, Any] = {}
    summary: dict[str, Any] = {}
    read_bytes: dict[str, bytes] = {}
    for p in sorted(Path(folder).glob("*.json")):
        label = _LABEL_OF_FILE.get(p.stem, p.stem)
        if p.stem != "summary" and ((only is not None and label not in only) or label in skip):
            continue
        try:
            raw = p.read_bytes()
            data = json.loads(raw.decode("utf-8"))
        except (OSError, ValueError) as exc:
            raise SessionError(f"{p}: unreadable results file ({exc})") from exc
        if p.stem != "summary":
            read_bytes[p.name] = raw
        if p.stem == "summary":
            if not isinstance(data, dict):
                raise SessionError(f"{p}: not a results summary (a JSON object expected, "
                                   f"found {type(data).__name__})")
            summary = data
        else:
            tables[label] = data
    _check_files_sha256(Path(folder), summary, read_bytes)
    listed = summary.get("tables")
    named = summary.get("table_files")
    files: dict[str, Any] = named if isinstance(named, dict) else {}
    for label in listed if isinstance(listed, list) else []:
        if not isinstance(label, str) or (only is not None and label not in only) \
                or label in skip:
            continue
        path = Path(folder) / f"{files.get(label) or result_file_stem(label)}.json"
        if label not in tables:
            raise SessionError(f"{path}: missing (summary.json lists table {label})")
        rows = tables[label]
        if not isinstance(rows, list) or not all(isinstance(r, dict) for r in rows):
            raise SessionError(f"{path}: not a table (a JSON list of row objects expected, "
                               f"found {_json_kind(rows)})")
    return {label: tables[label] for label in in_table_order(tables)}, summary


def _check_files_sha256(folder: Path, summary: Mapping[str, Any],
                        read: Mapping[str, bytes]) -> None:
    """Refuse a table file whose bytes are not those its version wrote (``files_sha256`` of
    ``summary.json``; versions written before it existed have none and are taken as they are).

    Raises
    ------
    SessionError
        Naming the file that changed.
    """
    recorded = summary.get("files_sha256")
    if not isinstance(recorded, Mapping):
        return
    for name, raw in read.items():
        want = recorded.get(name)
        if want is None:
            raise SessionError(f"{folder / name}: not written with this results version "
                               "(summary.json records no such file)")
        if hashlib.sha256(raw).hexdigest() != want:
            raise SessionError(f"{folder / name}: changed since it was written (its sha256 is "
                               "not the one summary.json records); results are never edited: "
                               f"run benchlab analyze {folder.parent.parent} for a new version")


def in_table_order(labels: Iterable[str]) -> list[str]:
    """Table labels in label order, as the thesis numbers them, with the simulator's truth
    after what was measured (``simulator_truth`` sorts before ``table_4_11``)."""
    return sorted(labels, key=lambda label: (label == "simulator_truth", label))


def _table_labels(summary: Mapping[str, Any]) -> list[str]:
    """The table labels a results ``summary.json`` lists."""
    listed = summary.get("tables")
    return in_table_order(t for t in listed if isinstance(t, str)) if isinstance(listed, list) \
        else []


def _table_names(summary: Mapping[str, Any]) -> list[str]:
    """The file names of the tables a results ``summary.json`` lists."""
    named = summary.get("table_files")
    files: Mapping[str, Any] = named if isinstance(named, Mapping) else {}
    return [str(files.get(t) or result_file_stem(t)) for t in _table_labels(summary)]


def _json_kind(value: Any) -> str:
    if isinstance(value, list):
        bad = next(v for v in value if not isinstance(v, dict))
        return f"a list holding {'null' if bad is None else type(bad).__name__}"
    return "null" if value is None else type(value).__name__


def _csv_text(rows: list[dict[str, Any]]) -> str:
    columns: list[str] = []
    seen: set[str] = set()
    for row in rows:
        for k in row:
            if k not in seen:
                seen.add(k)
                columns.append(k)
    buf = io.StringIO()
    # csv.writer with lists: the text DictWriter writes, without its per-row key checks (a
    # results version has ~700 rows, most of them the SFR curves).
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(columns)
    # a cell: NA for a missing value, JSON for a list or table, else the value (inline: a
    # function call per cell was a third of the time)
    writer.writerows([CSV_MISSING if v is None else json.dumps(v) if isinstance(v, dict | list)
                      else v for v in map(row.get, columns)] for row in rows)
    return buf.getvalue()


