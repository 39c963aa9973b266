"""Start-up of ``analyze SESSION`` (issue 11): frames loaded ahead on threads are the same
hash-checked frames, the threaded MTF analysis fails as the sequential one did, and the faster
results serialisation writes the same JSON."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from sim_runs import MTF_SMALL, run_sim, tables_of

from benchlab.catalog.index import Catalog
from benchlab.cli.main import main
from benchlab.protocols.mtf.analysis import analyze_mtf
from benchlab.protocols.runs import reanalyze, session_params
from benchlab.session import Session, SessionError, _plain


def _session(root: Path, n: int) -> tuple[Session, list[np.ndarray]]:
    s = Session.create(root, procedure="mtf", params={}, operator="ada", devices={},
                       software_version="0.1.0")
    frames = [np.random.default_rng(k).integers(0, 256, (16, 20), dtype=np.uint8)
              for k in range(n)]
    for k, px in enumerate(frames):
        s.save_frame(f"step{k}", "raw", px, {})
    return s, frames


def _flip_byte(path: Path) -> None:
    data = bytearray(path.read_bytes())
    data[-10] ^= 0xFF
    path.write_bytes(bytes(data))


def test_prefetched_frames_are_the_saved_frames_and_hash_checked(tmp_path: Path) -> None:
    s, frames = _session(tmp_path, 3)
    _flip_byte(s.frame_path("step1", "raw"))
    s = Session.open(s.path)
    s.prefetch_frames(2)
    assert s.prefetching
    pixels, meta = s.load_frame("step0", "raw")
    assert np.array_equal(pixels, frames[0]) and meta["step_id"] == "step0"
    with pytest.raises(SessionError, match=r"step1__raw\.tiff.*sha256 mismatch"):
        s.load_frame("step1", "raw")
    # handed out once; a second load reads the file again, with the same check
    assert np.array_equal(s.load_frame("step0", "raw")[0], frames[0])
    with pytest.raises(SessionError, match="sha256 mismatch"):
        s.load_frame("step1", "raw")
    s.stop_prefetch()
    assert not s.prefetching
    assert np.array_equal(s.load_frame("step2", "raw")[0], frames[2])
    with pytest.raises(SessionError, match="no such frame recorded"):
        s.load_frame("step9", "raw")


def test_release_drops_the_frames_loaded_ahead(tmp_path: Path) -> None:
    s, frames = _session(tmp_path, 2)
    s.hold()
    s.prefetch_frames(1)
    s.release()
    assert not s.prefetching
    assert np.array_equal(s.load_frame("step1", "raw")[0], frames[1])


def test_plain_keeps_types_and_turns_non_finite_into_none() -> None:
    doc = {"a": 1.5, "b": math.nan, "c": -math.inf, "d": (1, 2), "e": [np.float64(np.nan)],
           "f": np.int64(7), "g": True, "h": None, "i": "x", 3: Path("/p"),
           "j": np.array([1.0, np.inf]), "k": {"n": np.float32(0.5), "m": [float("inf")]}}
    out = _plain(doc)
    assert out == {"a": 1.5, "b": None, "c": None, "d": [1, 2], "e": [None], "f": 7,
                   "g": True, "h": None, "i": "x", "3": "/p", "j": [1.0, None],
                   "k": {"n": 0.5, "m": [None]}}
    assert type(out["g"]) is bool and type(out["f"]) is int and type(out["k"]["n"]) is float


@pytest.fixture(scope="module")
def small_mtf(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return run_sim("mtf", tmp_path_factory.mktemp("mtf"), MTF_SMALL).session_path


@pytest.mark.slow
def test_cli_and_api_reanalysis_match_the_run_and_accept_an_open_session(
    small_mtf: Path,
) -> None:
    first = small_mtf / "results" / "v1"
    run_tables = tables_of(first)
    # A stored summary the re-analysis does not repeat (an identical one would match v1 and
    # add no version): the re-analysis writes v2, with the run's own tables.
    summary = json.loads((first / "summary.json").read_text())
    (first / "summary.json").write_text(json.dumps({**summary, "estimator": "older"}))
    assert main(["analyze", str(small_mtf)]) == 0
    assert tables_of(small_mtf / "results" / "v2") == run_tables
    # the catalogue, updated beside the printing, has the new version when the command ends
    with Catalog.open(small_mtf.parent) as catalog:
        shown = catalog.show(small_mtf.name)
    assert shown["results_version"] == 2
    assert [r["version"] for r in shown["results"]] == [1, 2]
    opened = Session.open(small_mtf)
    opened.prefetch_frames(2)
    again = reanalyze(opened)
    assert again.name == "v2" and tables_of(again) == run_tables  # matched v2: none added
    assert not opened.prefetching and not opened.held  # released, loads dropped


def _copy(src: Path, dst: Path) -> Path:
    import shutil

    return Path(shutil.copytree(src, dst / src.name))


@pytest.mark.parametrize(("bad", "named"), [
    (("forward", "radial-0.5-tangential"), "forward__forward"),
    (("radial-0.5-tangential",), "radial-0.5-tangential__radial"),
])
def test_threaded_analysis_raises_the_first_bad_frame_and_ends(
    small_mtf: Path, tmp_path: Path, bad: tuple[str, ...], named: str,
) -> None:
    path = _copy(small_mtf, tmp_path)
    session = Session.open(path)
    for step in bad:
        frame = next(p for p in session.step_frames(step).values())
        _flip_byte(frame)
    with pytest.raises(SessionError, match=named):
        analyze_mtf(session, session_params(session), None)  # type: ignore[arg-type]


def test_results_csv_has_every_column_missing_cells_and_json_cells() -> None:
    import csv
    import io

    from benchlab.session import CSV_MISSING, _csv_text

    rows = [{"a": 1, "b": None, "c": 'say "hi", twice'},
            {"b": [1, 2], "d": {"k": 0.5}, "a": 2.25},
            {"e": True}]
    text = _csv_text(rows)
    assert text.splitlines()[0] == "a,b,c,d,e"
    back = list(csv.DictReader(io.StringIO(text)))
    assert back[0] == {"a": "1", "b": CSV_MISSING, "c": 'say "hi", twice', "d": CSV_MISSING,
                       "e": CSV_MISSING}
    assert back[1] == {"a": "2.25", "b": "[1, 2]", "c": CSV_MISSING, "d": '{"k": 0.5}',
                       "e": CSV_MISSING}
    assert back[2]["e"] == "True" and back[2]["a"] == CSV_MISSING
    assert _csv_text([]) == "\n"
