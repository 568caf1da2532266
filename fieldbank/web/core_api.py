"""The core's own routes: patients, their sessions, maps, fits and models, the audit log.

Reads of a patient's data are recorded in the audit log (who, when, from where, what): the
patient's page (``GET /api/patients/{code}``) and each map figure. Listing patients shows codes
only and is not recorded. A data manager adds patients and ingests files (all or nothing, the
same check as ``fieldbank ingest``) and reads the audit log; nothing here changes or removes an
audit entry.
"""

from __future__ import annotations

from collections.abc import Sequence
from datetime import date, datetime
from typing import Any

from aiohttp import BodyPartReader, web

from fieldbank.errors import ParameterError
from fieldbank.figures import render
from fieldbank.figures.fields import map_figure
from fieldbank.ingest import ingest_data
from fieldbank.model import Arm
from fieldbank.storage import Database, FitRecord, StoredModel
from fieldbank.stored.records import StoredMap
from fieldbank.web.routes import ApiError, Asset, Call, Param, Route, need, optional

CODE = Param("code", description="patient code")
#: Most files one upload may carry, and the largest, bytes.
MAX_UPLOAD_FILES = 20
MAX_UPLOAD_BYTES = 8 * 1024 * 1024


def iso(d: date | datetime | None) -> str | None:
    return None if d is None else d.isoformat()


def map_dict(m: StoredMap) -> dict[str, Any]:
    return {"id": m.id, "session": m.session_label, "date": iso(m.session_date),
            "kind": m.kind, "frame": m.frame, "sign": m.sign,
            "velocity_m_per_s": list(m.velocity_m_per_s), "points": m.n_points,
            "unit": m.value_unit, "source": m.source_text, "file": m.source_file,
            "sha256": m.source_sha256, "ingested_at": iso(m.ingested_at),
            "ingested_by": m.ingested_by}


def model_dict(m: StoredModel) -> dict[str, Any]:
    return {"id": m.id, "origin": m.origin, "label": m.label, "parent_id": m.parent_id,
            "created_at": iso(m.created_at)}


def fit_dict(f: FitRecord) -> dict[str, Any]:
    """A fit with its verdict and what it rests on (the parameters its maps did not
    identify, with the reasons)."""
    r = f.result
    gof = r.get("goodness_of_fit") or {}
    return {"id": f.id, "model_id": f.model_id, "session": f.session_label,
            "algorithm": f.algorithm, "seed": f.seed, "evaluations": f.n_evals,
            "time_s": f.time_s, "cost": f.cost, "created_at": iso(f.created_at),
            "status": r.get("status"), "verdict": gof.get("verdict"),
            "reasons": list(gof.get("reasons") or []),
            "chi2_per_dof": gof.get("chi2_per_dof"), "r2": gof.get("r2"),
            "maps": [{"map_id": (m.get("metadata") or {}).get("map_id"), "kind": m.get("kind"),
                      "r2": m.get("r2"), "chi2_per_value": m.get("chi2_per_value"),
                      "verdict": m.get("verdict")} for m in r.get("maps") or []],
            "unidentified": [{"name": u.get("name"), "reason": u.get("reason")}
                             for u in r.get("unidentified") or [] if isinstance(u, dict)],
            "map_ids": list(f.map_ids)}


def patient_page(db: Database, code: str) -> dict[str, Any]:
    """Everything the patient's page shows but the plans (the composer's provider lists
    those): the patient, sessions, maps, fits, models."""
    p = db.get_patient(code)
    return {"patient": {"code": p.code, "body_mass_kg": p.body_mass_kg, "height_m": p.height_m,
                        "side": p.side, "notes": p.notes, "created_at": iso(p.created_at)},
            "sessions": [{"id": s.id, "label": s.label, "date": iso(s.session_date),
                          "maps": s.n_maps} for s in db.list_sessions(code)],
            "maps": [map_dict(m) for m in db.list_maps(code)],
            "fits": [fit_dict(f) for f in db.list_fits(code)],
            "models": [model_dict(m) for m in db.list_models(code)]}


def map_svg(db: Database, map_id: int,
            cache: dict[tuple[int, int | None], str] | None = None) -> tuple[str, str]:
    """The map's figure (SVG) drawn over the patient's latest fitted model (else the
    patient's unimpaired arm); (svg, patient code). ``cache``: figures already drawn, by map
    and model (both never change once stored)."""
    sm = db.get_stored_map(map_id)
    fitted = [m for m in db.list_models(sm.patient_code) if m.origin == "fitted"]
    latest = max(fitted, key=lambda m: m.id) if fitted else None
    key = (map_id, None if latest is None else latest.id)
    if cache is not None and key in cache:
        return cache[key], sm.patient_code
    fm = db.get_map(map_id)
    params = (latest.params if latest is not None
              else db.get_patient(sm.patient_code).arm_params())
    title = (f"{sm.kind} map {sm.id}, session {sm.session_label}"
             + (f" ({sm.session_date.isoformat()})" if sm.session_date else ""))
    svg = render(map_figure(Arm.from_params(params), fm, title), "svg").decode("utf-8")
    if cache is not None:
        if len(cache) > 256:
            cache.clear()
        cache[key] = svg
    return svg, sm.patient_code


def audit_dict(e: Any) -> dict[str, Any]:
    return {"id": e.id, "at": iso(e.at), "actor": e.actor, "action": e.action,
            "entity": e.entity, "entity_id": e.entity_id, "detail": e.detail}


def parse_since(text: str | None) -> datetime | None:
    if text is None:
        return None
    try:
        return datetime.fromisoformat(text)
    except ValueError:
        raise ParameterError(f"since must be a date or time, YYYY-MM-DD[THH:MM]; got "
                             f"{text!r}.") from None


class CoreRoutes:
    """The core's routes (a :class:`~fieldbank.web.routes.RouteProvider`)."""

    name = "core"

    def __init__(self) -> None:
        self._figures: dict[tuple[int, int | None], str] = {}

    def assets(self) -> Sequence[Asset]:
        return ()

    def routes(self) -> Sequence[Route]:
        pat = ("patients",)
        return [
            Route("GET", "/api/patients", self.patients, "read",
                  "Patients, their codes matching q (case-insensitive), with counts",
                  (Param("q", "query", required=False, description="part of a code"),),
                  tags=pat),
            Route("POST", "/api/patients", self.add_patient, "manage",
                  "Register a patient (a pseudonymous code, anthropometry, side)",
                  body={"type": "object", "required": ["code", "body_mass_kg", "height_m",
                                                       "side"],
                        "properties": {"code": {"type": "string"},
                                       "body_mass_kg": {"type": "number"},
                                       "height_m": {"type": "number"},
                                       "side": {"enum": ["left", "right"]},
                                       "notes": {"type": "string"}}}, tags=pat),
            Route("GET", "/api/patients/{code}", self.patient, "read",
                  "A patient's sessions, maps, fits (verdict, what they rest on) and models "
                  "(recorded as a read)", (CODE,), tags=pat),
            Route("GET", "/api/maps/{id}/figure.svg", self.map_figure, "read",
                  "A stored map's figure, SVG (recorded as a read)",
                  (Param("id", type="integer", description="map id"),),
                  response={"type": "string", "format": "svg"}, tags=pat),
            Route("GET", "/api/models/{id}", self.model, "read",
                  "A stored model: origin, label, lineage and parameters",
                  (Param("id", type="integer", description="model id"),), tags=pat),
            Route("POST", "/api/patients/{code}/sessions/{label}/files", self.ingest, "manage",
                  "Ingest map files into a session (multipart form, field 'file', repeatable; "
                  "optional 'date'): all or nothing, as 'fieldbank ingest'",
                  (CODE, Param("label", description="session label")),
                  body={"type": "string", "format": "multipart/form-data"}, tags=pat),
            Route("GET", "/api/audit", self.audit, "manage",
                  "The audit log, newest first, as 'fieldbank audit'",
                  (Param("patient", "query", required=False),
                   Param("user", "query", required=False),
                   Param("since", "query", required=False, description="YYYY-MM-DD[THH:MM]"),
                   Param("limit", "query", "integer", required=False)), tags=("audit",)),
        ]

    async def patients(self, call: Call) -> Any:
        q = (call.query("q") or "").strip().lower()

        def work() -> list[dict[str, Any]]:
            sessions: dict[str, int] = {}
            for s in call.db.list_sessions():
                sessions[s.patient_code] = sessions.get(s.patient_code, 0) + 1
            return [{"code": p.code, "side": p.side, "sessions": sessions.get(p.code, 0)}
                    for p in call.db.list_patients() if q in p.code.lower()]

        return {"patients": await call.run(work)}

    async def add_patient(self, call: Call) -> Any:
        body = await call.json()
        code = need(body, "code", str)
        mass = need(body, "body_mass_kg", (int, float))
        height = need(body, "height_m", (int, float))
        side = need(body, "side", str)
        notes = optional(body, "notes", str, "")
        p = await call.run(lambda: call.db.add_patient(code, float(mass), float(height),
                                                       side, notes))
        return {"code": p.code, "id": p.id}

    async def patient(self, call: Call) -> Any:
        code = call.match("code")

        def work() -> dict[str, Any]:
            page = patient_page(call.db, code)
            call.record_read(code, "patient page: sessions, maps, fits, models")
            return page

        return await call.run(work)

    async def map_figure(self, call: Call) -> web.StreamResponse:
        map_id = call.match_int("id")

        def work() -> str:
            svg, code = map_svg(call.db, map_id, self._figures)
            call.record_read(code, f"map {map_id} figure")
            return svg

        return web.Response(text=await call.run(work), content_type="image/svg+xml")

    async def model(self, call: Call) -> Any:
        model_id = call.match_int("id")

        def work() -> dict[str, Any]:
            m = call.db.get_model(model_id)
            if m.patient_code is not None:
                call.record_read(m.patient_code, f"model {model_id}")
            return {**model_dict(m), "patient": m.patient_code,
                    "lineage": [model_dict(x) for x in call.db.model_lineage(model_id)],
                    "params": m.params.to_dict()}

        return await call.run(work)

    async def ingest(self, call: Call) -> Any:
        code, label = call.match("code"), call.match("label")
        blobs: list[tuple[str, bytes]] = []
        when: date | None = None
        reader = await call.request.multipart()
        while (part := await reader.next()) is not None:
            if not isinstance(part, BodyPartReader):
                raise ApiError(400, "a nested multipart body is not accepted")
            data = await part.read()
            if len(data) > MAX_UPLOAD_BYTES:
                raise ApiError(413, f"a file is at most {MAX_UPLOAD_BYTES} bytes here")
            if part.name == "date" and data:
                try:
                    when = date.fromisoformat(data.decode())
                except (UnicodeDecodeError, ValueError):
                    raise ApiError(400, "date must be YYYY-MM-DD") from None
            elif part.name == "file":
                blobs.append((part.filename or "upload", data))
            if len(blobs) > MAX_UPLOAD_FILES:
                raise ApiError(413, f"at most {MAX_UPLOAD_FILES} files at once")
        if not blobs:
            raise ApiError(400, "no file in the upload (form field 'file')")
        report = await call.run(lambda: ingest_data(call.db, blobs, code, label, when))
        return report.to_json_dict()

    async def audit(self, call: Call) -> Any:
        limit_text = call.query("limit") or "500"
        if not limit_text.isdigit():
            raise ApiError(400, "limit must be a whole number")
        since = parse_since(call.query("since"))
        entries = await call.run(lambda: call.db.audit_entries(
            min(int(limit_text), 5000), patient=call.query("patient"),
            actor=call.query("user"), since=since))
        return {"entries": [audit_dict(e) for e in entries]}
