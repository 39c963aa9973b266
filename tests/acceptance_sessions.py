"""Shared helpers of the acceptance tests: sessions with known readings, spec files."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from benchlab.session import Session


def make_session(root: Path, name: str, *, serial: str = "", lot: str = "",
                 modulation: float | None = 0.60, sigma: float = 0.01, resolved: bool = True,
                 gain: float | None = None, started: str | None = None) -> Path:
    """A completed session whose latest results hold the given forward-view reading."""
    session = Session.create(root, procedure="mtf", params={}, operator="t", devices={},
                             software_version="test", name=name, sample=serial, lot=lot)
    tables: dict[str, list[dict[str, Any]]] = {"table_4_11": [
        {"element": "G1E5", "sagittal_modulation": 0.8, "sagittal_uncertainty": 0.01,
         "sagittal_resolved": True, "sagittal_aliased": False, "aliased": False},
        {"element": "G2E2", "sagittal_modulation": modulation, "sagittal_uncertainty": sigma,
         "sagittal_resolved": resolved, "sagittal_aliased": False, "aliased": False},
    ]}
    if gain is not None:
        tables["characterisation"] = [{"gain": 1.0, "system_gain_dn_per_e": gain,
                                       "system_gain_uncertainty_dn_per_e": 0.001}]
    session.write_results(tables, summary={}, estimator="test")
    session.finish("completed")
    session.release()
    if started is not None:  # a start time of the test's choosing (sessions refuse the edit)
        meta_path = session.path / "session.json"
        meta = json.loads(meta_path.read_text())
        meta_path.write_text(json.dumps({**meta, "started_at": started}))
    return session.path


def spec(tmp_path: Path, *limits: str, rule: str = "guarded") -> Path:
    path = tmp_path / f"spec-{len(list(tmp_path.glob('spec-*')))}.toml"
    path.write_text(f'format = "benchlab.spec"\nversion = 1\nname = "objective"\n'
                    f'revision = "B"\ndecision_rule = "{rule}"\n' + "".join(limits),
                    encoding="utf-8")
    return path


def limit(min_: float | None = None, max_: float | None = None, ident: str = "fwd-G2E2-S",
          table: str = "forward_view_modulation", column: str = "sagittal_modulation",
          where: str = '{ element = "G2E2" }') -> str:
    bounds = "".join(f"{k} = {v}\n" for k, v in (("min", min_), ("max", max_)) if v is not None)
    return (f'\n[[limit]]\nid = "{ident}"\ntable = "{table}"\nwhere = {where}\n'
            f'column = "{column}"\n{bounds}')
