"""Remote haptic sessions: the link a session ran over, and the supervised assessment.

A remote session is an ordinary haptic session (:mod:`fieldbank.storage.traces`) with, beside
it, one ``haptic_remote_links`` row — the site's role, the peer, the session key's fingerprint
(never the key), the link's settings (rate, clock mode, injected impairment, passivity) and
what was measured (round trip, loss, the passivity controller's activity) — and one
``haptic_assessments`` row per probe: the classifier's prior and posterior over the candidate
arms when the probe ended, the most probable group and level with their probabilities, whether
the best candidate explains the recording, and the clinician's own answer given after that
probe (none: NULL). The link's per-tick columns are traces of the session (``link.*``).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from typing import Any

from sqlalchemy import select

from fieldbank.errors import StorageError
from fieldbank.redact import mask_url
from fieldbank.storage.core import DatabaseCore, now, to_utc
from fieldbank.storage.orm import AssessmentRow, HapticSessionRow, RemoteLinkRow
from fieldbank.storage.records import AssessmentRecord, RemoteLinkRecord

ROLES = ("clinician", "patient")
#: Longest clinician's note kept with an answer.
MAX_NOTE_CHARS = 2000
_DETAIL = ("group_posterior", "level_posterior", "next_probe", "link", "predictor",
           "revisions")


def _json(doc: Any) -> str:
    return json.dumps(doc, sort_keys=True, default=str, allow_nan=False)


def _probability(v: Any, what: str) -> float | None:
    if v is None:
        return None
    p = float(v)
    if not (math.isfinite(p) and -1e-9 <= p <= 1.0 + 1e-9):
        raise StorageError(f"{what} must be a probability in [0, 1]; got {v!r}")
    return p


class RemoteLinks(DatabaseCore):
    """Remote links and assessments of :class:`~fieldbank.storage.Database`."""

    def add_remote_link(self, haptic_session_id: int, role: str, peer: str,
                        key_fingerprint: str, settings: Mapping[str, Any],
                        summary: Mapping[str, Any]) -> int:
        """Record the link a session ran over; its id. ``peer`` is stored masked."""
        if role not in ROLES:
            raise StorageError(f"a remote link's role is one of {', '.join(ROLES)}; got "
                               f"{role!r}")
        with self._write() as s:
            if s.get(HapticSessionRow, haptic_session_id) is None:
                raise StorageError(f"No haptic session with id {haptic_session_id}.")
            row = RemoteLinkRow(haptic_session_id=haptic_session_id, role=role,
                                peer=mask_url(peer)[:255], key_fingerprint=key_fingerprint[:32],
                                settings_json=_json(dict(settings)),
                                summary_json=_json(dict(summary)), created_at=now())
            s.add(row)
            s.flush()
            self._audit(s, "add", "haptic_remote_link", row.id,
                        {"haptic_session": haptic_session_id, "role": role})
            return int(row.id)

    def get_remote_link(self, haptic_session_id: int) -> RemoteLinkRecord | None:
        """The link of a session (None: not a remote session)."""
        with self._read() as s:
            r = s.scalar(select(RemoteLinkRow)
                         .where(RemoteLinkRow.haptic_session_id == haptic_session_id))
            if r is None:
                return None
            return RemoteLinkRecord(r.id, r.haptic_session_id, r.role, r.peer,
                                    r.key_fingerprint, json.loads(r.settings_json),
                                    json.loads(r.summary_json), to_utc(r.created_at))

    def add_assessments(self, haptic_session_id: int,
                        rows: Sequence[Mapping[str, Any]]) -> int:
        """Record a session's posteriors (one per probe, each with the answer given after it)
        in one transaction; the number recorded.

        Each row: ``probe`` (int), ``posterior`` ({candidate: p}), ``verdict`` (text), and
        optionally ``started_s``, ``ended_s``, ``prior``, ``group``, ``group_probability``,
        ``level``, ``level_probability``, ``explains``, ``group_posterior``,
        ``level_posterior``, ``next_probe``, ``link``, ``revisions`` (posteriors recomputed
        for the probe under another prior), ``answer_group``, ``answer_level``,
        ``answer_note``, ``answered_s``.
        """
        with self._write() as s:
            if s.get(HapticSessionRow, haptic_session_id) is None:
                raise StorageError(f"No haptic session with id {haptic_session_id}.")
            for i, r in enumerate(rows):
                where = f"assessment {i} of haptic session {haptic_session_id}"
                missing = [k for k in ("probe", "posterior", "verdict") if r.get(k) is None]
                if missing:
                    raise StorageError(f"{where} lacks {', '.join(missing)}")
                post = dict(r["posterior"])
                for k, v in post.items():
                    _probability(v, f"{where}: posterior[{k!r}]")
                note = r.get("answer_note")
                if note is not None and len(str(note)) > MAX_NOTE_CHARS:
                    raise StorageError(f"{where}: the answer's note is longer than "
                                       f"{MAX_NOTE_CHARS} characters")
                detail = {k: r.get(k) for k in _DETAIL if r.get(k) is not None}
                s.add(AssessmentRow(
                    haptic_session_id=haptic_session_id, probe=int(r["probe"]),
                    started_s=r.get("started_s"), ended_s=r.get("ended_s"),
                    prior_json=_json(dict(r.get("prior") or {})), posterior_json=_json(post),
                    impaired_group=r.get("group"),
                    group_probability=_probability(r.get("group_probability"),
                                                   f"{where}: group_probability"),
                    level=r.get("level"),
                    level_probability=_probability(r.get("level_probability"),
                                                   f"{where}: level_probability"),
                    explains=r.get("explains"), verdict=str(r["verdict"]),
                    detail_json=_json(detail), answer_group=r.get("answer_group"),
                    answer_level=r.get("answer_level"),
                    answer_note=None if note is None else str(note),
                    answered_s=r.get("answered_s")))
            s.flush()
            self._audit(s, "add", "haptic_assessments", haptic_session_id, {"n": len(rows)})
            return len(rows)

    def list_assessments(self, haptic_session_id: int) -> list[AssessmentRecord]:
        """A session's posteriors in probe order, each with the answer beside it."""
        q = (select(AssessmentRow).where(AssessmentRow.haptic_session_id == haptic_session_id)
             .order_by(AssessmentRow.probe))
        with self._read() as s:
            return [AssessmentRecord(
                r.id, r.haptic_session_id, r.probe, r.started_s, r.ended_s,
                json.loads(r.prior_json), json.loads(r.posterior_json), r.impaired_group,
                r.group_probability, r.level, r.level_probability, r.explains, r.verdict,
                json.loads(r.detail_json), r.answer_group, r.answer_level, r.answer_note,
                r.answered_s) for r in s.scalars(q)]
