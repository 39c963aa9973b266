"""Retakes: taking steps of a session again (``benchlab resume --retake``) while the earlier
takes stay on disk and current until the retake is adopted."""

from __future__ import annotations

from collections.abc import Collection
from typing import Any

from benchlab.session.frames import SessionFrames
from benchlab.session.layout import (
    FRAMES_DIR,
    RETAKE_ADOPTED,
    RETAKE_STARTED,
    RETAKE_STOPPED,
    SessionError,
    _check_name,
    _now_iso,
    take_of,
)
from benchlab.session.lock import session_holder


class SessionRetakes(SessionFrames):
    """Starts, adopts and stops retakes."""

    # ------------------------------------------------------------------ retakes
    def retakes(self) -> list[dict[str, Any]]:
        """Every retake, oldest first: ``id``, ``steps``, ``reason``, ``started_at`` and
        ``status`` - "adopted" (its takes are current), "running" (a live process is taking
        them), "interrupted" (stopped before adoption: the previous takes stay current) - with
        ``current`` (step -> take number) once adopted."""
        out: dict[str, dict[str, Any]] = {}
        for ev in self._journal()[1]:
            rid = ev.get("retake")
            if not isinstance(rid, str):
                continue
            kind = ev.get("kind")
            if kind == RETAKE_STARTED:
                out[rid] = {"id": rid, "steps": list(ev.get("steps") or ()),
                            "reason": str(ev.get("reason") or ""),
                            "started_at": str(ev.get("time", "")), "status": "running"}
            elif kind == RETAKE_ADOPTED and rid in out:
                out[rid].update(status="adopted", current=dict(ev.get("takes") or {}),
                                adopted_at=str(ev.get("time", "")))
            elif kind == RETAKE_STOPPED and rid in out and out[rid]["status"] == "running":
                out[rid].update(status="interrupted", stopped=str(ev.get("status", "")))
        # Running: the retake this object runs, or the last one while another live process
        # writes the session; any other that never ended was stopped by a kill.
        live = self._retake[0] if self._retake is not None else None
        last = next(reversed(out), None)
        other = live is None and not self.held and session_holder(self.path) is not None
        for rec in out.values():
            if rec["status"] == "running" and not (rec["id"] == live
                                                   or (other and rec["id"] == last)):
                rec.update(status="interrupted", stopped="writer gone")
        return list(out.values())

    def current_take(self, step_id: str) -> int:
        """The take number of a step's current frames (1: never taken again; the highest
        ``.take<N>`` of its current frame files)."""
        return max(map(take_of, self.step_frames(step_id).values()), default=1)

    def begin_retake(self, step_ids: Collection[str], reason: str = "",
                     previous_status: str | None = None) -> str:
        """Start taking ``step_ids`` again (their frames so far are kept, never edited). Until
        :meth:`adopt_retake`, frames those steps save are the retake's: this object sees them
        in place of the current takes, every other reader still sees the current takes.
        Journalled (``retake_started``) and recorded in ``session.json`` (``retake``).
        ``previous_status``: the session's status before this run set it "running" (a
        retake of a completed session that is stopped leaves it completed). Only the
        session's writer may do this. Returns the retake's id."""
        if not self.held:
            raise SessionError(f"{self.path}: only the session's writer starts a retake")
        if self._retake is not None:
            raise SessionError(f"{self.path}: retake {self._retake[0]} is already running")
        steps = [_check_name("step id", s) for s in step_ids]
        rid = f"r{sum(1 for ev in self._journal()[1] if ev.get('kind') == RETAKE_STARTED) + 1}"
        previous = {s: self.current_take(s) for s in steps}
        self.log_event(RETAKE_STARTED, retake=rid, steps=steps, reason=reason,
                       previous_takes=previous,
                       previous_frames={s: sorted(p.relative_to(self.path).as_posix()
                                                  for p in self.step_frames(s).values())
                                        for s in steps})
        record = {"id": rid, "steps": steps, "reason": reason, "status": "running",
                  "started_at": _now_iso(), "previous_status": previous_status or self.status,
                  "previous_takes": previous}
        self._retake = (rid, frozenset(steps))
        self.update_meta(status="running", retake=record)
        return rid

    @property
    def retake_running(self) -> str | None:
        """The id of the retake this object runs (not yet adopted), else None."""
        return self._retake[0] if self._retake is not None else None

    def adopt_retake(self) -> dict[str, int]:
        """Make the running retake's frames current, in ONE journal line that also sets the
        takes they supersede aside (kept on disk and in the hash checks, never analysed).
        Results written before are stale from then on (:meth:`results_stale`). Returns
        step -> its current take number."""
        if self._retake is None:
            raise SessionError(f"{self.path}: no retake is running")
        rid, steps = self._retake
        new = {s: self.step_frames(s) for s in sorted(steps)}
        missing = sorted(s for s, frames in new.items() if not frames)
        if missing:
            raise SessionError(f"{self.path}: retake {rid} has no frames for "
                               f"{', '.join(missing)}; nothing adopted")
        self._retake = None
        old = {s: self.step_frames(s) for s in sorted(steps)}
        superseded = [p.relative_to(self.path).as_posix() for s in sorted(steps)
                      for n, p in old[s].items() if n in new[s]]
        adopted = [p.relative_to(self.path).as_posix() for s in sorted(steps)
                   for p in new[s].values()]
        reason = str(self._meta.get("retake", {}).get("reason") or "")
        takes = {s: max(map(take_of, new[s].values())) for s in sorted(steps)}
        self.log_event(RETAKE_ADOPTED, retake=rid, steps=sorted(steps), files=superseded,
                       adopted=adopted, takes=takes,
                       reason=f"superseded by retake {rid}" + (f": {reason}" if reason else ""))
        meta_takes = dict(self._meta.get("takes") or {})
        for s in sorted(steps):
            meta_takes[s] = {"take": takes[s], "retake": rid, "reason": reason,
                             "frames": sorted(f for f in adopted
                                              if f.startswith(f"{FRAMES_DIR}/{s}__"))}
        retake = {**dict(self._meta.get("retake") or {}), "status": "adopted",
                  "adopted_at": _now_iso(), "current_takes": takes}
        self.update_meta(takes=meta_takes, retake=retake)
        return takes

    def stop_retake(self, status: str) -> None:
        """The running retake ended before adoption (``status``: interrupted, aborted,
        failed): journalled and recorded; the previous takes stay current, the retake's frames
        stay on disk beside them, never current."""
        if self._retake is None:
            return
        rid, steps = self._retake
        self._retake = None
        self.log_event(RETAKE_STOPPED, retake=rid, steps=sorted(steps), status=status,
                       message="previous takes stay current")
        retake = {**dict(self._meta.get("retake") or {}), "status": status,
                  "stopped_at": _now_iso(), "note": "previous takes stay current"}
        self.update_meta(retake=retake)

