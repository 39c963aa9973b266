"""The session catalogue's SQLite schema and its migrations.

The schema version is SQLite's ``PRAGMA user_version``. ``MIGRATIONS[i]`` takes a catalogue
from version ``i`` to ``i + 1``; :func:`migrate` applies the missing ones in order, each in its
own transaction, so a catalogue written by an older benchlab is upgraded in place and keeps its
rows. A catalogue from a *newer* benchlab is refused (:class:`CatalogSchemaError`): the caller
rebuilds a private cache rather than guess at columns it does not know.
"""

from __future__ import annotations

import sqlite3

from benchlab.drivers.errors import BenchlabError


class CatalogSchemaError(BenchlabError):
    """The catalogue file has a schema this benchlab cannot read or upgrade."""


#: v1: sessions, their results versions and the key figures of each version.
_V1 = """
CREATE TABLE sessions (
    id TEXT PRIMARY KEY,
    path TEXT NOT NULL,
    procedure TEXT NOT NULL,
    status TEXT NOT NULL,
    operator TEXT NOT NULL DEFAULT '',
    devices_json TEXT NOT NULL DEFAULT '{}',
    serials TEXT NOT NULL DEFAULT '',
    started_at TEXT NOT NULL DEFAULT '',
    finished_at TEXT,
    software_version TEXT NOT NULL DEFAULT '',
    results_version INTEGER,
    estimator TEXT,
    error TEXT NOT NULL DEFAULT '',
    indexed_at TEXT NOT NULL
);
CREATE TABLE results (
    session_id TEXT NOT NULL REFERENCES sessions(id) ON DELETE CASCADE,
    version INTEGER NOT NULL,
    estimator TEXT NOT NULL DEFAULT '',
    created_at TEXT NOT NULL DEFAULT '',
    PRIMARY KEY (session_id, version)
);
CREATE TABLE figures (
    session_id TEXT NOT NULL REFERENCES sessions(id) ON DELETE CASCADE,
    version INTEGER NOT NULL,
    view TEXT NOT NULL,
    element TEXT NOT NULL DEFAULT '',
    orientation TEXT NOT NULL DEFAULT '',
    freq_lp_per_mm REAL,
    quantity TEXT NOT NULL,
    value REAL,
    text TEXT NOT NULL DEFAULT ''
);
CREATE INDEX figures_by_session ON figures(session_id, version);
"""

#: v2: the lens/sample identifier (``run --sample``), the report marker, and the indexes that
#: keep a 10,000-session query fast: covering indexes, so a trend reads no table row.
_V2 = """
ALTER TABLE sessions ADD COLUMN sample TEXT NOT NULL DEFAULT '';
ALTER TABLE sessions ADD COLUMN report TEXT NOT NULL DEFAULT '';
CREATE INDEX sessions_by_start ON sessions(started_at);
CREATE INDEX sessions_by_sample ON sessions(sample, started_at);
CREATE INDEX sessions_for_trend ON sessions(id, results_version, started_at, sample, estimator,
                                            procedure, status);
CREATE INDEX figures_by_figure ON figures(view, quantity, orientation, element, freq_lp_per_mm,
                                          session_id, version, value, text);
"""

#: v3: a reading that is not resolved or aliased has no value (NULL, its text says which); v2
#: stored the 0 its table holds, which trends drew as a measured 0. (v2 called aliased readings
#: "unresolved": v4 has them re-read from their folders.) A Table 4.15 average that
#: v2 took over such a 0 (a not-resolved half within the Monte Carlo match, 20 % of the
#: frequency) has no value either. ``unreadable_version``: a
#: latest results version that cannot be read (``error`` says why); ``results_version`` is then
#: the newest readable one.
_V3 = """
UPDATE figures
SET value = NULL, text = 'not available: a half not resolved (reindex to say which)'
WHERE orientation = 'averaged' AND quantity = 'modulation' AND EXISTS (
    SELECT 1 FROM figures AS half WHERE half.session_id = figures.session_id
    AND half.version = figures.version AND half.view = figures.view
    AND half.quantity = 'modulation' AND half.text = 'unresolved'
    AND abs(half.freq_lp_per_mm - figures.freq_lp_per_mm) <= 0.2 * figures.freq_lp_per_mm);
UPDATE figures SET value = NULL WHERE quantity = 'modulation' AND text IN ('unresolved', 'aliased');
ALTER TABLE sessions ADD COLUMN unreadable_version INTEGER;
"""

#: v4: ``needs_reindex`` marks sessions whose rows the folders must rebuild: every session
#: with a reading labelled "unresolved", which v2 (and a v3 migrated from it) also called an
#: aliased one. :meth:`benchlab.catalog.index.Catalog.open` re-reads marked sessions from their
#: folders (once: a rebuilt row is unmarked; a folder that is gone keeps its migrated rows).
_V4 = """
ALTER TABLE sessions ADD COLUMN needs_reindex INTEGER NOT NULL DEFAULT 0;
UPDATE sessions SET needs_reindex = 1 WHERE id IN (
    SELECT session_id FROM figures WHERE text = 'unresolved');
CREATE INDEX sessions_to_reindex ON sessions(id, path) WHERE needs_reindex = 1;
"""

#: v5: a clipped radiometry row (Table 4.16 holds no number for it) is labelled "clipped" and
#: has a ``clipped_pixels`` figure; v4 listed it with no value and no text, as if nothing had
#: been measured. Sessions with such rows are re-read from their folders.
_V5 = """
UPDATE sessions SET needs_reindex = 1 WHERE id IN (
    SELECT session_id FROM figures WHERE view = 'radiometry' AND value IS NULL AND text = '');
"""

#: v6: units and lots (issue 28): the unit's lot beside its serial number (``sample``), and
#: the acceptance verdicts stored in the folders (``verdicts/v<N>.json``), one row per version.
_V6 = """
ALTER TABLE sessions ADD COLUMN lot TEXT NOT NULL DEFAULT '';
CREATE TABLE verdicts (
    session_id TEXT NOT NULL REFERENCES sessions(id) ON DELETE CASCADE,
    version INTEGER NOT NULL,
    created_at TEXT NOT NULL DEFAULT '',
    serial TEXT NOT NULL DEFAULT '',
    lot TEXT NOT NULL DEFAULT '',
    spec_name TEXT NOT NULL,
    spec_revision TEXT NOT NULL DEFAULT '',
    spec_sha256 TEXT NOT NULL DEFAULT '',
    decision_rule TEXT NOT NULL DEFAULT '',
    verdict TEXT NOT NULL,
    PRIMARY KEY (session_id, version)
);
CREATE INDEX verdicts_by_unit ON verdicts(serial, spec_name, created_at);
CREATE INDEX sessions_by_lot ON sessions(lot, started_at);
"""

#: v7: how many readings of a stored verdict disagree with another session of the unit
#: beyond their uncertainties (issue 38); verdicts stored before were never checked: 0.
_V7 = """
ALTER TABLE verdicts ADD COLUMN disagreements INTEGER NOT NULL DEFAULT 0;
"""

MIGRATIONS: tuple[str, ...] = (_V1, _V2, _V3, _V4, _V5, _V6, _V7)
SCHEMA_VERSION = len(MIGRATIONS)


def schema_version(conn: sqlite3.Connection) -> int:
    """The catalogue's ``user_version`` (0 for a new, empty file)."""
    return int(conn.execute("PRAGMA user_version").fetchone()[0])


def migrate(conn: sqlite3.Connection, target: int = SCHEMA_VERSION) -> int:
    """Bring the catalogue up to ``target``; returns the version it was at before.

    Raises
    ------
    CatalogSchemaError
        If the file is newer than ``target`` (written by a newer benchlab).
    """
    before = schema_version(conn)
    if before > target:
        raise CatalogSchemaError(f"catalogue schema v{before} is newer than this benchlab's "
                                 f"v{target}")
    for version in range(before, target):
        # executescript commits first; BEGIN IMMEDIATE makes each step all-or-nothing and
        # serialises two processes that open the same old catalogue at once.
        conn.execute("BEGIN IMMEDIATE")
        try:
            if schema_version(conn) == version:  # another process may have migrated it
                for statement in _statements(MIGRATIONS[version]):
                    conn.execute(statement)
                conn.execute(f"PRAGMA user_version = {version + 1}")
            conn.execute("COMMIT")
        except BaseException:
            if conn.in_transaction:  # SQLite rolls back by itself on a full disk
                conn.execute("ROLLBACK")
            raise
    return before


def _statements(script: str) -> list[str]:
    return [s.strip() for s in script.split(";") if s.strip()]
