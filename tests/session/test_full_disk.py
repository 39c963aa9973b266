"""A full disk (issue 38): ``analyze`` and ``report`` name the file they could not write and
change nothing saved; ``run`` leaves no stub session folder that neither ``sessions list`` nor
``resume`` can read.

Two honest ways to run out of space without a small file system to mount: in process, every
``os.write`` and ``os.fsync`` fails with ENOSPC (a full disk fails whichever write comes first,
and delayed allocation reports it at fsync); in a subprocess, the kernel's own file size limit
(``RLIMIT_FSIZE``) makes a real ``write()`` fail part-way (EFBIG), as a full disk does.
"""

from __future__ import annotations

import errno
import hashlib
import os
import resource
import signal
import subprocess
import sys
from pathlib import Path
from typing import NoReturn

import pytest
from sim_runs import MTF_SMALL, run_sim

from benchlab.cli.main import main
from benchlab.session import Session, SessionError


def _full(*args: object) -> NoReturn:
    raise OSError(errno.ENOSPC, "No space left on device")


@pytest.fixture
def full_disk(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(os, "write", _full)
    monkeypatch.setattr(os, "fsync", _full)


def _tree(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file() and p.name != "owner.lock"}


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return run_sim("mtf", tmp_path_factory.mktemp("disk") / "root", MTF_SMALL).session_path


@pytest.mark.slow
def test_analyze_and_report_name_the_file_and_change_nothing(
        session: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    before = _tree(session)
    with monkeypatch.context() as m:
        m.setattr(os, "write", _full)
        m.setattr(os, "fsync", _full)
        assert main(["analyze", str(session)]) == 1
        err = capsys.readouterr().err
        assert f"benchlab: error: {session}/events.jsonl: no space left on device (disk full)" \
            in err, err
        assert main(["report", str(session)]) == 1
        err = capsys.readouterr().err
        assert f"benchlab: error: {session}/report.html: no space left on device (disk full)" \
            in err, err
    assert _tree(session) == before
    assert sorted(p.name for p in (session / "results").iterdir()) == ["v1"]  # no staging left
    assert not list(session.glob(".report.html.*"))


def test_a_session_that_cannot_be_created_leaves_no_folder(
        tmp_path: Path, full_disk: None) -> None:
    root = tmp_path / "root"
    root.mkdir()
    with pytest.raises(SessionError) as info:
        Session.create(root, procedure="mtf", params={}, operator="t", devices={},
                       software_version="test", name="s1")
    assert str(info.value) == (
        f"{root / 's1' / 'events.jsonl'}: cannot create the session (no space left on device); "
        f"nothing was acquired and the folder {root / 's1'} was removed")
    assert list(root.iterdir()) == []


def _limited(limit_bytes: int) -> None:
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # the write fails with EFBIG instead
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit_bytes, limit_bytes))


@pytest.mark.slow
def test_run_out_of_space_leaves_no_stub(tmp_path: Path) -> None:
    root = tmp_path / "root"
    done = subprocess.run(
        [sys.executable, "-m", "benchlab.cli.main", "run", "mtf", "--simulate", "--yes",
         "--params", str(MTF_SMALL), "--out", str(root)],
        preexec_fn=lambda: _limited(200), capture_output=True, text=True,  # noqa: PLW1509
        timeout=120)
    assert done.returncode == 1, done.stderr
    (line,) = [x for x in done.stderr.splitlines() if x.startswith("benchlab: error:")]
    assert "/session.json: cannot create the session (file too large); nothing was acquired " \
        "and the folder " in line and line.endswith("was removed")
    assert [p.name for p in root.iterdir() if p.is_dir()] == []
