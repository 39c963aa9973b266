"""The session catalogue: an embedded SQLite cache of the session folders under one root.

``<root>/catalog.sqlite`` lists every session (id, procedure, status, operator, sample, devices
with serials, times, software version), each results version with its estimator, and the key
figures of each version, so "MTF at 70 lp/mm over the last 40 prototypes" is one query instead
of opening thousands of folders.

It is a cache, never the source of truth: every row is rebuilt from the folders by
:meth:`Catalog.reindex`, and a missing, corrupt or too-new catalogue is rebuilt rather than
trusted or fatal. Several processes may write it at once (a batch re-analysis while runs go
on): the file is in WAL mode with a busy timeout, and each session's rows are replaced in one
``BEGIN IMMEDIATE`` transaction that reads the folder *inside* the lock, so the last writer
always stores the newest state of the folder.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import os
import sqlite3
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, NamedTuple

from benchlab.catalog.extract import SessionRecord, is_session_folder, read_session_record
from benchlab.catalog.schema import SCHEMA_VERSION, CatalogSchemaError, migrate
from benchlab.drivers.errors import BenchlabError, UsageError
from benchlab.storage import printable_name

CATALOG_FILE = "catalog.sqlite"
#: How long a writer waits for another process's transaction before giving up.
BUSY_TIMEOUT_MS = 30_000
#: ``--freq F`` matches a figure within this relative distance (the thesis paired 73.2 lp/mm
#: with its 70 lp/mm Monte Carlo row: 5 % apart; 35 with 30: 17 %).
FREQ_MATCH_FRACTION = 0.2
ORIENTATION_ALIASES = {
    "s": "sagittal", "sagittal": "sagittal", "horizontal": "sagittal",
    "t": "tangential", "tangential": "tangential", "vertical": "tangential",
    "a": "averaged", "averaged": "averaged", "avg": "averaged", "": "",
}
#: Columns of a listing (everything but the devices' JSON).
_LIST_COLUMNS = ("s.id, s.path, s.procedure, s.status, s.operator, s.sample, s.lot, s.serials, "
                 "s.started_at, s.finished_at, s.software_version, s.results_version, "
                 "s.estimator, s.report, s.error, s.unreadable_version, s.indexed_at")
SORT_COLUMNS = ("started_at", "id", "procedure", "status", "sample", "operator",
                "results_version")

log = logging.getLogger(__name__)


class CatalogError(BenchlabError):
    """A catalogue query that cannot be answered (bad option, unknown session)."""


class CatalogUsageError(CatalogError, UsageError):
    """A query option that cannot be meant (unknown sort column, a date that is not one, a
    frequency <= 0): a usage error (exit 2), raised before the catalogue is opened."""


class TrendPoint(NamedTuple):
    """One session's value of the selected figure (its latest results version); a named
    tuple because a trend over 10,000 sessions builds 10,000 of them."""

    session_id: str
    started_at: str
    sample: str
    version: int
    estimator: str
    element: str
    orientation: str
    freq_lp_per_mm: float | None
    value: float | None
    text: str


def normalise_orientation(text: str | None) -> str | None:
    """``S``/``T``/``A`` (or the full words) -> sagittal / tangential / averaged."""
    if text is None:
        return None
    key = text.strip().lower()
    if key not in ORIENTATION_ALIASES:
        raise CatalogUsageError(f"--orientation {text!r}: use S (sagittal), T (tangential) "
                                "or A (averaged)")
    return ORIENTATION_ALIASES[key]


def _connect(path: Path) -> sqlite3.Connection:
    # isolation_level=None: transactions are explicit (BEGIN IMMEDIATE ... COMMIT).
    conn = sqlite3.connect(path, timeout=BUSY_TIMEOUT_MS / 1000, isolation_level=None)
    conn.row_factory = sqlite3.Row
    conn.execute(f"PRAGMA busy_timeout = {BUSY_TIMEOUT_MS}")
    conn.execute("PRAGMA journal_mode = WAL")
    # WAL + NORMAL: a committed transaction survives a process crash; a power cut may lose
    # the last ones, which reindex restores from the folders (the catalogue is a cache).
    conn.execute("PRAGMA synchronous = NORMAL")
    conn.execute("PRAGMA cache_size = -32768")  # 32 MiB: a 10,000-session trend stays cached
    return conn


class Catalog:
    """An open catalogue of the sessions under ``root``. Use :meth:`open`; close when done."""

    def __init__(self, root: Path, conn: sqlite3.Connection, *, in_memory: bool = False) -> None:
        self.root = Path(root)
        self.path = self.root / CATALOG_FILE
        self.conn = conn
        #: Built in memory (the folder cannot be written): what is recorded is not kept.
        self.in_memory = in_memory

    # ------------------------------------------------------------------ open / rebuild
    @classmethod
    def open(cls, root: str | Path) -> Catalog:
        """Open (creating, migrating or rebuilding as needed) the catalogue of ``root``.

        A catalogue that is missing, not a database, or of a newer schema is replaced by one
        rebuilt from the session folders; an older schema is migrated in place. A rebuild is
        built beside the file and moved into place only once complete, so one that fails (a
        full disk) leaves no half-built catalogue to be trusted later: the next open rebuilds.
        Where the catalogue cannot be written (read-only media), it is built in memory from
        the folders for this use only (:attr:`in_memory`): reads still work.
        """
        root = Path(root)
        root.mkdir(parents=True, exist_ok=True)
        path = root / CATALOG_FILE
        if _read_only(root, path):
            log.info("%s: read-only; reading the session folders into memory", path)
            return cls._in_memory(root)
        try:
            if not path.exists():
                _build(root, path)
            try:
                conn = _open_migrated(path)
            except (sqlite3.DatabaseError, CatalogSchemaError) as exc:
                log.warning("%s: %s; rebuilding it from the session folders", path, exc)
                _remove_catalog_files(path)
                _build(root, path)
                conn = _open_migrated(path)
        except (sqlite3.Error, OSError) as exc:
            raise CatalogError(f"{path}: cannot open or rebuild the catalogue ({exc})") from exc
        catalog = cls(root, conn)
        catalog._reindex_marked()
        return catalog

    @classmethod
    def _in_memory(cls, root: Path) -> Catalog:
        """A catalogue of ``root`` built from its folders in memory (nothing written)."""
        conn = sqlite3.connect(":memory:", isolation_level=None)
        conn.row_factory = sqlite3.Row
        migrate(conn)
        catalog = cls(root, conn, in_memory=True)
        catalog.reindex()
        return catalog

    def _reindex_marked(self) -> int:
        """Re-read the sessions a migration marked (``needs_reindex``: labels an older schema
        got wrong) from their folders; a folder that is gone keeps its migrated rows, unmarked.
        Returns how many were re-read."""
        rows = self.conn.execute(
            "SELECT id, path FROM sessions WHERE needs_reindex = 1").fetchall()
        done = 0
        for session_id, path in rows:
            folder = Path(path)
            if is_session_folder(folder):
                record = self.record(folder)  # a fresh row: unmarked
                done += 1
                if record.id == session_id:
                    continue
            with self._write() as conn:
                conn.execute("UPDATE sessions SET needs_reindex = 0 WHERE id = ?", (session_id,))
        if done:
            log.info("%s: %d sessions re-read after the schema migration", self.path, done)
        return done

    def close(self) -> None:
        self.conn.close()

    def __enter__(self) -> Catalog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @contextmanager
    def _write(self) -> Iterator[sqlite3.Connection]:
        self.conn.execute("BEGIN IMMEDIATE")
        try:
            yield self.conn
        except BaseException:
            if self.conn.in_transaction:  # SQLite rolls back by itself on a full disk
                self.conn.execute("ROLLBACK")
            raise
        self.conn.execute("COMMIT")

    # ------------------------------------------------------------------ writing
    def record(self, session_path: str | Path) -> SessionRecord:
        """Replace the rows of one session folder with what the folder holds now."""
        folder = Path(session_path).resolve()
        with self._write() as conn:
            # Read inside the write lock: the last writer stores the folder's newest state.
            record = read_session_record(folder)
            self._store(conn, record)
        return record

    def store(self, records: Iterable[SessionRecord]) -> int:
        """Store already-read records in one transaction (bulk loads, benchmarks)."""
        n = 0
        with self._write() as conn:
            for record in records:
                self._store(conn, record)
                n += 1
        return n

    def reindex(self) -> int:
        """Rebuild every row from the session folders; returns the number of sessions."""
        folders = sorted(p for p in self.root.iterdir() if p.is_dir() and is_session_folder(p))
        with self._write() as conn:
            conn.execute("DELETE FROM figures")
            conn.execute("DELETE FROM verdicts")
            conn.execute("DELETE FROM results")
            conn.execute("DELETE FROM sessions")
            for folder in folders:
                self._store(conn, read_session_record(folder.resolve()))
        return len(folders)

    @staticmethod
    def _delete(conn: sqlite3.Connection, session_id: str) -> None:
        for table, key in (("figures", "session_id"), ("results", "session_id"),
                           ("verdicts", "session_id"), ("sessions", "id")):
            conn.execute(f"DELETE FROM {table} WHERE {key} = ?", (session_id,))

    def _store(self, conn: sqlite3.Connection, r: SessionRecord) -> None:
        if not (_is_text(r.id) and _is_text(r.path)):
            # A folder name that is not UTF-8 (from another system): SQLite holds text only,
            # so its bytes are stored escaped (bad\xffname) - listed, never a crash (issue 38).
            r = dataclasses.replace(r, id=printable_name(r.id), path=printable_name(r.path))
        self._delete(conn, r.id)
        latest = r.latest
        conn.execute(
            "INSERT INTO sessions (id, path, procedure, status, operator, sample, lot,"
            " devices_json, serials, started_at, finished_at, software_version,"
            " results_version, estimator, report, error, unreadable_version, indexed_at)"
            " VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)",
            (r.id, r.path, r.procedure, r.status, r.operator, r.sample, r.lot,
             json.dumps(r.devices, sort_keys=True), r.serials, r.started_at, r.finished_at,
             r.software_version, latest.version if latest else None,
             latest.estimator if latest else None, r.report, r.error, r.unreadable_version,
             datetime.now(UTC).isoformat(timespec="seconds")),
        )
        conn.executemany(
            "INSERT INTO results (session_id, version, estimator, created_at) VALUES (?,?,?,?)",
            [(r.id, v.version, v.estimator, v.created_at) for v in r.results],
        )
        conn.executemany(
            "INSERT INTO figures (session_id, version, view, element, orientation,"
            " freq_lp_per_mm, quantity, value, text) VALUES (?,?,?,?,?,?,?,?,?)",
            [(r.id, f.version, f.view, f.element, f.orientation, f.freq_lp_per_mm,
              f.quantity, f.value, f.text) for f in r.figures],
        )
        conn.executemany(
            "INSERT INTO verdicts (session_id, version, created_at, serial, lot, spec_name,"
            " spec_revision, spec_sha256, decision_rule, verdict, disagreements)"
            " VALUES (?,?,?,?,?,?,?,?,?,?,?)",
            [(r.id, v.version, v.created_at, v.serial, v.lot, v.spec_name, v.spec_revision,
              v.spec_sha256, v.decision_rule, v.verdict, v.disagreements)
             for v in r.verdicts],
        )

    # ------------------------------------------------------------------ reading
    def refresh_running(self) -> int:
        """Re-read the folders of rows that say "running": a writer that died (kill -9, power
        loss) never updated its row, and the folder's owner lock now says "interrupted".
        Returns how many rows changed."""
        from benchlab.session import Session

        changed = 0
        rows = self.conn.execute("SELECT path FROM sessions WHERE status = 'running'").fetchall()
        for (path,) in rows:
            try:
                truth = Session.open(Path(path)).status
            except Exception:  # noqa: BLE001 - a folder gone or unreadable: reindex says why
                continue
            if truth != "running":
                self.record(path)
                changed += 1
        return changed

    def sessions(
        self,
        *,
        procedure: str | None = None,
        since: str | None = None,
        sample: str | None = None,
        status: str | None = None,
        sort: str = "started_at",
        descending: bool = True,
        limit: int | None = None,
        devices: bool = False,
        lot: str | None = None,
    ) -> list[dict[str, Any]]:
        """Sessions matching every given filter, sorted (newest first by default).

        ``devices=True`` adds each session's ``devices`` (identities; slower on big lists).
        """
        check_list_query(sort=sort, since=since)
        self.refresh_running()
        where, args = _session_filters(procedure, since, sample, status, lot)
        columns = "*" if devices else _LIST_COLUMNS
        sql = (f"SELECT {columns} FROM sessions s {where} ORDER BY s.{sort} "
               f"{'DESC' if descending else 'ASC'}, s.id")
        if limit is not None:
            sql += " LIMIT ?"
            args.append(int(limit))
        cursor = self.conn.execute(sql, args)
        names = [d[0] for d in cursor.description]
        rows = [dict(zip(names, row, strict=True)) for row in cursor]
        if devices:
            for row in rows:
                row["devices"] = json.loads(row.pop("devices_json") or "{}")
        return rows

    def show(self, session_id: str) -> dict[str, Any]:
        """One session with its results versions and the figures of its latest version."""
        self.refresh_running()
        session_id = printable_name(session_id)  # a name that is not UTF-8 is stored escaped
        row = self.conn.execute("SELECT * FROM sessions WHERE id = ?", (session_id,)).fetchone()
        if row is None:
            raise CatalogError(f"no session {session_id!r} in {self.path} "
                               "(benchlab sessions reindex rebuilds it from the folders)")
        out = _session_dict(row)
        out["results"] = [dict(r) for r in self.conn.execute(
            "SELECT version, estimator, created_at FROM results WHERE session_id = ? "
            "ORDER BY version", (session_id,))]
        out["figures"] = [dict(r) for r in self.conn.execute(
            "SELECT view, element, orientation, freq_lp_per_mm, quantity, value, text "
            "FROM figures WHERE session_id = ? AND version = ? ORDER BY rowid",
            (session_id, row["results_version"]))]
        return out

    def units(self, *, lot: str | None = None) -> list[dict[str, Any]]:
        """Units under test (sessions' serial numbers, ``sample``): lot, sessions, the newest
        session, and the latest stored verdict per spec (``verdicts``: spec name ->
        ``{verdict, revision, created_at, session_id, version, disagreements}``; the last: how
        many of its readings disagree with another session of the unit), by serial number."""
        self.refresh_running()
        args: list[Any] = []
        where = "WHERE s.sample != ''"
        if lot is not None:
            where += " AND s.lot = ?"
            args.append(lot)
        units: dict[str, dict[str, Any]] = {}
        for row in self.conn.execute(
                f"SELECT s.sample, s.lot, s.id, s.path, s.procedure, s.started_at FROM sessions s "
                f"{where} ORDER BY s.sample, s.started_at", args):
            unit = units.setdefault(row[0], {"serial": row[0], "lot": row[1], "sessions": [],
                                             "verdicts": {}})
            unit["lot"] = row[1] or unit["lot"]  # the newest session's lot
            unit["sessions"].append({"id": row[2], "path": row[3], "procedure": row[4],
                                     "started_at": row[5]})
        for row in self.conn.execute(
                "SELECT s.sample, v.spec_name, v.spec_revision, v.verdict, v.created_at, "
                "v.session_id, v.version, v.disagreements FROM verdicts v "
                "JOIN sessions s ON s.id = v.session_id "
                "ORDER BY v.created_at, v.version"):  # the session's serial now (relabelled)
            if row[0] in units:  # later rows win: the latest verdict per spec
                units[row[0]]["verdicts"][row[1]] = {
                    "revision": row[2], "verdict": row[3], "created_at": row[4],
                    "session_id": row[5], "version": row[6], "disagreements": row[7]}
        return list(units.values())

    def figure_keys(self) -> list[tuple[str, str, str, str]]:
        """Distinct ``(view, element, orientation, quantity)`` of the latest versions."""
        rows = self.conn.execute(
            "SELECT DISTINCT f.view, f.element, f.orientation, f.quantity FROM figures f "
            "JOIN sessions s ON s.id = f.session_id AND f.version = s.results_version "
            "ORDER BY f.view, f.element, f.orientation, f.quantity")
        return [(r[0], r[1], r[2], r[3]) for r in rows]

    def trend(
        self,
        *,
        view: str,
        element: str | None = None,
        orientation: str | None = None,
        freq_lp_per_mm: float | None = None,
        quantity: str = "modulation",
        procedure: str | None = None,
        since: str | None = None,
        sample: str | None = None,
        status: str | None = None,
    ) -> list[TrendPoint]:
        """The selected figure across sessions, oldest first (latest results version each).

        With ``freq_lp_per_mm`` each session contributes its figure nearest that frequency
        within :data:`FREQ_MATCH_FRACTION`; several figures per session (no element, no
        frequency) are all returned.
        """
        check_trend_query(element=element, freq_lp_per_mm=freq_lp_per_mm,
                          orientation=orientation, since=since)
        where, args = _session_filters(procedure, since, sample, status)
        where = where or "WHERE 1"
        sql = ("SELECT s.id, s.started_at, s.sample, f.version, s.estimator, f.element, "
               "f.orientation, f.freq_lp_per_mm, f.value, f.text FROM figures f "
               "JOIN sessions s ON s.id = f.session_id AND f.version = s.results_version "
               f"{where} AND f.view = ? AND f.quantity = ?")
        args += [view, quantity]
        orient = normalise_orientation(orientation)
        if orient is None and freq_lp_per_mm is not None:
            orient = "averaged"  # Table 4.15's figure, at its Monte Carlo frequencies
        if orient is not None:
            sql += " AND f.orientation = ?"
            args.append(orient)
        if element is not None:
            sql += " AND f.element = ?"
            args.append(element)
        if freq_lp_per_mm is not None:
            lo = freq_lp_per_mm * (1 - FREQ_MATCH_FRACTION)
            hi = freq_lp_per_mm * (1 + FREQ_MATCH_FRACTION)
            sql += " AND f.freq_lp_per_mm BETWEEN ? AND ?"
            args += [lo, hi]
        sql += " ORDER BY s.started_at, s.id"
        cursor = self.conn.cursor()
        cursor.row_factory = None  # plain tuples: 10,000 points without per-row objects
        points = [TrendPoint._make(row) for row in cursor.execute(sql, args)]
        if freq_lp_per_mm is None:
            return points
        best: dict[str, TrendPoint] = {}
        for p in points:  # nearest frequency per session
            have = best.get(p.session_id)
            if have is None or _dist(p, freq_lp_per_mm) < _dist(have, freq_lp_per_mm):
                best[p.session_id] = p
        return [p for p in points if best.get(p.session_id) is p]


def check_list_query(*, sort: str = "started_at", since: str | None = None) -> None:
    """Raise :class:`CatalogUsageError` for a listing that cannot be meant (before any work)."""
    if sort not in SORT_COLUMNS:
        raise CatalogUsageError(f"--sort {sort!r}: choose {', '.join(SORT_COLUMNS)}")
    if since:
        parse_since(since)


def check_trend_query(*, element: str | None, freq_lp_per_mm: float | None,
                      orientation: str | None, since: str | None = None) -> None:
    """Raise :class:`CatalogUsageError` for a trend that cannot be meant (before any work)."""
    if element is None and freq_lp_per_mm is None:
        raise CatalogUsageError("trend needs --element or --freq")
    if freq_lp_per_mm is not None and not (freq_lp_per_mm > 0 and math.isfinite(freq_lp_per_mm)):
        raise CatalogUsageError(f"--freq must be a number > 0 lp/mm, got {freq_lp_per_mm}")
    normalise_orientation(orientation)
    if since:
        parse_since(since)


def _dist(p: TrendPoint, freq: float) -> float:
    return abs((p.freq_lp_per_mm or 0.0) - freq)


def _session_filters(
    procedure: str | None, since: str | None, sample: str | None, status: str | None,
    lot: str | None = None,
) -> tuple[str, list[Any]]:
    clauses: list[str] = []
    args: list[Any] = []
    if procedure:
        clauses.append("s.procedure = ?")
        args.append(procedure)
    if since:
        clauses.append("s.started_at >= ?")
        args.append(parse_since(since))
    if sample:
        clauses.append("s.sample = ?")
        args.append(sample)
    if status:
        clauses.append("s.status = ?")
        args.append(status)
    if lot:
        clauses.append("s.lot = ?")
        args.append(lot)
    return ("WHERE " + " AND ".join(clauses) if clauses else ""), args


def parse_since(text: str) -> str:
    """``YYYY-MM-DD`` or an ISO date-time -> the ISO text ``started_at`` is compared with."""
    try:
        when = datetime.fromisoformat(text.strip())
    except ValueError:
        raise CatalogUsageError(f"--since {text!r}: give a date YYYY-MM-DD or an ISO time") \
            from None
    if when.tzinfo is None:
        when = when.replace(tzinfo=UTC)
    return when.astimezone(UTC).isoformat(timespec="microseconds")


def _session_dict(row: sqlite3.Row) -> dict[str, Any]:
    out = dict(row)
    out["devices"] = json.loads(out.pop("devices_json") or "{}")
    out.pop("needs_reindex", None)  # the catalogue's own bookkeeping
    return out


def _is_text(text: str) -> bool:
    """Whether ``text`` encodes as UTF-8 (a file name's undecodable bytes do not)."""
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


def session_folder(path: str) -> Path:
    """The folder of a catalogue row's ``path``: a folder whose name is not UTF-8 is stored
    escaped (:func:`~benchlab.storage.printable_name`), and found again among its parent's
    folders by that escaped name."""
    folder = Path(path)
    if "\\x" not in folder.name or folder.exists() or not folder.parent.is_dir():
        return folder  # no escape in the name (no file system call: listings are long)
    for child in folder.parent.iterdir():
        if child.name != folder.name and printable_name(child.name) == folder.name:
            return child
    return folder


def _read_only(root: Path, path: Path) -> bool:
    """Whether the catalogue cannot be written here (read-only media or permissions)."""
    return not os.access(root, os.W_OK) or (path.exists() and not os.access(path, os.W_OK))


def _open_migrated(path: Path) -> sqlite3.Connection:
    conn = _connect(path)
    try:
        migrate(conn)
    except BaseException:
        conn.close()
        raise
    return conn


def _build(root: Path, path: Path) -> None:
    """Build the catalogue of ``root`` in a file beside ``path`` and move it to ``path`` only
    once complete; on any failure nothing is left behind (issue 38: a rebuild that failed on
    a full disk left an empty catalogue that was trusted afterwards)."""
    building = path.with_name(f".{path.name}.{os.getpid()}.building")
    _remove_catalog_files(building)
    try:
        conn = _connect(building)
        try:
            migrate(conn)
            Catalog(root, conn).reindex()
        finally:
            conn.close()  # the last connection: its WAL is folded into the file and removed
        try:
            os.link(building, path)  # never replaces one another process built meanwhile
        except FileExistsError:
            pass
        except OSError:  # no hard links on this file system (FAT): the next best
            if not path.exists():
                os.replace(building, path)
    finally:
        _remove_catalog_files(building)


def _remove_catalog_files(path: Path) -> None:
    for suffix in ("", "-wal", "-shm", "-journal"):
        Path(f"{path}{suffix}").unlink(missing_ok=True)


@contextmanager
def session_recorder() -> Iterator[Callable[[str | Path], bool]]:
    """:func:`record_session` for many sessions in a row (a batch's parent process): each
    root's catalogue is opened once, not once per session (an open and a close cost ~25 ms
    of waiting on the disk each). The yielded function never raises either."""
    catalogs: dict[Path, Catalog] = {}

    def record(session_path: str | Path) -> bool:
        folder = Path(session_path)
        if not is_session_folder(folder):
            return False
        try:
            root = folder.resolve().parent
            if root not in catalogs:
                catalogs[root] = Catalog.open(root)
            if catalogs[root].in_memory:  # read-only media: no catalogue file to update
                return False
            catalogs[root].record(folder)
            return True
        except Exception as exc:  # noqa: BLE001 - the folders stay the truth; reindex repairs
            log.warning("catalogue not updated for %s: %s", folder, exc)
            return False

    try:
        yield record
    finally:
        for catalog in catalogs.values():
            catalog.close()


def record_session(session_path: str | Path) -> bool:
    """Update the catalogue of the session's root after a run, resume, analysis or report.

    Never raises: the catalogue is a cache, and a run must not fail because of it. Returns
    whether the catalogue was updated (a failure is logged as a warning).
    """
    folder = Path(session_path)
    if not is_session_folder(folder):
        return False
    try:
        with Catalog.open(folder.resolve().parent) as catalog:
            if catalog.in_memory:  # read-only media: there is no catalogue file to update
                return False
            catalog.record(folder)
        return True
    except Exception as exc:  # noqa: BLE001 - the folders stay the truth; reindex repairs
        log.warning("catalogue not updated for %s: %s", folder, exc)
        return False


__all__ = ["CATALOG_FILE", "SCHEMA_VERSION", "Catalog", "CatalogError", "CatalogUsageError",
           "TrendPoint", "check_list_query", "check_trend_query",
           "normalise_orientation", "parse_since", "record_session", "session_recorder"]
