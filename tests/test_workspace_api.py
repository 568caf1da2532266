"""The workspace's JSON API against the command line: the composer's what-if gives the numbers
of ``fieldbank whatif`` (dose after dose, the cache warm), the optimiser those of ``--optimize``,
errors the same words; the OpenAPI document and docs/api.md name the same routes; accounts,
tokens, sessions and the throttle; the audit log stored and filtered on SQLite and PostgreSQL."""

from __future__ import annotations

import asyncio
import json
import re
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

import pytest
from aiohttp.test_utils import TestClient, TestServer
from click.testing import CliRunner

from fieldbank.cli.main import cli
from fieldbank.errors import ParameterError, StorageError
from fieldbank.interventions.workspace import ComposerRoutes
from fieldbank.storage import Database
from fieldbank.web.accounts import (
    ROLE_PERMISSIONS,
    add_user,
    new_token,
    token_owner,
    verify_login,
)
from fieldbank.web.app import make_app
from fieldbank.web.core_api import CoreRoutes
from fieldbank.web.sessions import FREE_FAILURES, IDLE_S, LoginThrottle, SessionStore
from tests.workspace_util import PASSWORDS, ROOT, build_db


@pytest.fixture(scope="module")
def db_url(tmp_path_factory: pytest.TempPathFactory) -> str:
    return build_db(tmp_path_factory.mktemp("api"))


def _with_client(db_url: str, fn: Callable[[TestClient[Any, Any]], Awaitable[Any]]) -> Any:
    """Run ``fn`` against the workspace app (core and composer routes) logged in as alice."""
    async def main() -> Any:
        db = Database.open(db_url)
        app = make_app(db, [CoreRoutes(), ComposerRoutes()])
        async with TestClient(TestServer(app)) as client:
            page = await (await client.get("/")).text()
            csrf = re.search(r'name="csrf-token" content="([^"]+)"', page)
            assert csrf
            r = await client.post("/api/login", json={"name": "alice",
                                                      "password": PASSWORDS["alice"]},
                                  headers={"X-CSRF-Token": csrf.group(1)})
            assert r.status == 200
            client.csrf = (await r.json())["csrf"]  # type: ignore[attr-defined]
            try:
                return await fn(client)
            finally:
                db.close()

    return asyncio.run(main())


def _post(client: TestClient[Any, Any], path: str, body: dict[str, Any]
          ) -> Awaitable[Any]:
    async def go() -> Any:
        r = await client.post(path, json=body,
                              headers={"X-CSRF-Token": client.csrf})  # type: ignore[attr-defined]
        return r.status, await r.json()

    return go()


def _cli_json(db_url: str, *args: str) -> dict[str, Any]:
    res = CliRunner().invoke(cli, ["whatif", "SYN-001", *args, "--db", db_url, "--json"])
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout)  # type: ignore[no-any-return]


def _comparable(doc: dict[str, Any]) -> dict[str, Any]:
    """The ``whatif --json`` part of an API answer (without what the page adds)."""
    out = {k: v for k, v in doc.items() if k not in ("figure_svg", "plan_label")}
    # the model as whatif names it (what it is, its ids, what it stands on); the page adds "id"
    out["model"] = {k: v for k, v in doc["model"].items() if k != "id"}
    return out


def test_the_composer_gives_the_numbers_of_fieldbank_whatif_dose_after_dose(
        db_url: str) -> None:
    cli_200 = _cli_json(db_url, "--botox", "ef=200U")
    cli_mix = _cli_json(db_url, "--botox", "ef=150U,bf=100U", "--weeks", "8",
                        "--lengthen", "bf=1cm", "--rhizotomy", "all:0.6")

    async def go(client: TestClient[Any, Any]) -> list[Any]:
        out = []
        for dose in ("ef=200U", "ef=180U", "ef=90U", "ef=200U"):
            out.append(await _post(client, "/api/whatif", {"patient": "SYN-001",
                                                           "botox": dose}))
        out.append(await _post(client, "/api/whatif", {
            "patient": "SYN-001", "botox": "ef=150U,bf=100U", "weeks": 8, "lengthen": "bf=1cm",
            "rhizotomy": "all:0.6"}))
        return out

    answers = _with_client(db_url, go)
    assert all(s == 200 for s, _ in answers), answers
    first, second, third, again, mix = (d for _, d in answers)
    # the whole document, every number to the last bit, cold and with the cache warm
    assert _comparable(first) == cli_200
    assert _comparable(again) == cli_200
    assert _comparable(mix) == cli_mix
    assert first["summary"]["lines"] == cli_200["summary"]["lines"]
    assert second["summary"] != first["summary"] and third["summary"] != second["summary"]
    # the figures are those of whatif --plot: SVG naming the plan
    assert "<svg" in first["figure_svg"] and "SYN-001" in first["figure_svg"]
    assert "Elbow extension" in first["figure_svg"]
    assert first["model"]["id"] == 1 and first["model"]["patient"] == "SYN-001"


def test_the_optimiser_and_the_errors_speak_as_the_command_line(db_url: str) -> None:
    cli_opt = _cli_json(db_url, "--optimize", "--total-units", "300", "--groups", "ef,bf")
    bad = CliRunner().invoke(cli, ["whatif", "SYN-001", "--botox", "ef=200mg", "--db", db_url])
    assert bad.exit_code == 1
    cli_error = bad.output.strip().removeprefix("Error: ")

    async def go(client: TestClient[Any, Any]) -> list[Any]:
        return [await _post(client, "/api/whatif/optimise", {
                    "patient": "SYN-001", "total_units": 300, "groups": ["ef", "bf"]}),
                await _post(client, "/api/whatif", {"patient": "SYN-001", "botox": "ef=200mg"}),
                await _post(client, "/api/whatif", {"patient": "NOPE", "botox": "ef=200U"}),
                await _post(client, "/api/whatif", {"patient": "SYN-001"})]

    (s1, opt), (s2, err), (s3, nope), (s4, none) = _with_client(db_url, go)
    assert s1 == 200
    # the same split, numbers and document; only the search's own wall time differs
    assert opt["inverse"].pop("elapsed_s") > 0 and cli_opt["inverse"].pop("elapsed_s") > 0
    assert _comparable(opt) == cli_opt
    assert s2 == 400 and err["error"] == cli_error
    assert s3 == 400 and "No patient with code 'NOPE'" in nope["error"]
    assert s4 == 400 and none["error"].startswith("No intervention given")


def test_openapi_and_docs_api_md_name_the_same_routes(db_url: str) -> None:
    async def go(client: TestClient[Any, Any]) -> Any:
        r = await client.get("/api/openapi.json")
        return await r.json()

    doc = _with_client(db_url, go)
    assert doc["openapi"].startswith("3.1")
    ops = {(m.upper(), p) for p, o in doc["paths"].items() for m in o}
    text = (ROOT / "docs" / "api.md").read_text("utf-8")
    documented = set(re.findall(r"^\| `(GET|POST) (/api/[^`]+)`", text, re.M))
    # the robot's routes come from the haptic provider, not started here
    robot = {x for x in documented if x[1].startswith("/api/robot")}
    assert documented - robot == ops
    assert len(robot) == 3
    for (method, path), op in ((k, doc["paths"][k[1]][k[0].lower()]) for k in ops):
        assert op["summary"] and op["responses"]["401"], (method, path)


def test_accounts_tokens_and_roles(tmp_path: Path) -> None:
    from fieldbank.storage.accounts import check_role

    assert all(check_role(r) == r for r in ROLE_PERMISSIONS)
    with Database.open(f"sqlite:///{tmp_path / 'a.sqlite3'}") as db:
        u = add_user(db, "ann", "clinician", "a long enough one")
        assert u.password_hash.startswith("$argon2id$") and "long" not in u.password_hash
        assert verify_login(db, "ann", "a long enough one") == u
        assert verify_login(db, "ann", "a long enough On3") is None
        assert verify_login(db, "nobody", "a long enough one") is None
        with pytest.raises(ParameterError, match="10-1024 characters"):
            add_user(db, "bob", "viewer", "short")
        with pytest.raises(ParameterError, match="role must be one of"):
            add_user(db, "bob", "admin", "a long enough one")
        with pytest.raises(StorageError, match="already exists"):
            add_user(db, "ann", "viewer", "a long enough one")
        with pytest.raises(ParameterError, match="Account name"):
            add_user(db, "<b>x</b>", "viewer", "a long enough one")
        token, rec = new_token(db, "ann", "laptop")
        assert token.startswith("fbt_") and len(token) > 40
        assert token_owner(db, token) == (db.get_user("ann"), rec.id)
        assert token_owner(db, token + "x") is None
        db.revoke_token(rec.id)
        assert token_owner(db, token) is None
        t2, _ = new_token(db, "ann")
        db.set_user("ann", disabled=True)
        assert token_owner(db, t2) is None and verify_login(db, "ann",
                                                            "a long enough one") is None
        acts = [(e.action, e.entity) for e in db.audit_entries()]
        assert ("add", "user") in acts and ("revoke", "api_token") in acts
        assert not any("long enough" in json.dumps(e.detail) for e in db.audit_entries())


def test_users_and_audit_commands(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'c.sqlite3'}"
    Database.open(url).close()
    run = CliRunner().invoke
    r = run(cli, ["users", "add", "kim", "--role", "viewer", "--password-stdin", "--db", url],
            input="kim's password here\n")
    assert r.exit_code == 0, r.output
    r = run(cli, ["users", "add", "lee", "--role", "nurse", "--password-stdin", "--db", url],
            input="x" * 12 + "\n")
    assert r.exit_code == 2 and "nurse" in r.output
    r = run(cli, ["users", "token", "kim", "--label", "script", "--db", url])
    assert r.exit_code == 0 and r.stdout.strip().startswith("fbt_")
    with Database.open(url) as db:
        assert token_owner(db, r.stdout.strip()) is not None
    r = run(cli, ["users", "revoke", "1", "--db", url])
    assert r.exit_code == 0 and "revoked" in r.output
    r = run(cli, ["users", "tokens", "--json", "--db", url])
    assert json.loads(r.stdout)[0]["revoked_at"] is not None
    r = run(cli, ["audit", "--json", "--action", "revoke", "--db", url])
    assert r.exit_code == 0 and [e["entity"] for e in json.loads(r.stdout)] == ["api_token"]
    r = run(cli, ["audit", "--since", "2999-01-01", "--db", url])
    assert r.exit_code == 0 and "0 entries" in r.output
    r = run(cli, ["audit", "--since", "yesterday", "--db", url])
    assert r.exit_code == 2 and "not a date" in r.output


def test_audit_by_patient_on_every_backend(any_db_url: str) -> None:
    with Database.open(any_db_url, upgrade="always") as db:
        db.add_patient("PA-1", 70, 1.7, "right")
        db.add_patient("PB-2", 70, 1.7, "left")
        web = db.acting_as("ann", via="session", **{"from": "127.0.0.1"})
        web.ensure_session("PA-1", "s1")
        web.record_read("PA-1", "patient page")
        db.ensure_session("PB-2", "s1")
        mine = web.audit_entries(patient="PA-1")
        assert [(e.action, e.entity) for e in mine] == [("read", "patient"), ("add", "session"),
                                                       ("add", "patient")]
        assert [e.actor for e in mine][:2] == ["ann", "ann"]
        assert mine[0].detail == {"patient": "PA-1", "what": "patient page",
                                  "request": {"via": "session", "from": "127.0.0.1"}}
        assert len(db.audit_entries(patient="PB-2")) == 2
        assert len(db.audit_entries(actor="ann")) == 2
        with pytest.raises(StorageError, match="No patient with code"):
            db.audit_entries(patient="PZ-9")


def test_sessions_expire_and_the_throttle_doubles() -> None:
    now = [0.0]
    store = SessionStore(clock=lambda: now[0])
    anon = store.anonymous(None)
    assert store.get(anon.id) is anon and store.anonymous("forged") is not anon
    s = store.login(anon, "ann")
    assert s.id != anon.id and store.get(anon.id) is None and s.user == "ann"
    assert s.csrf_ok(s.csrf) and not s.csrf_ok(None) and not s.csrf_ok(s.csrf + "x")
    now[0] += IDLE_S + 1
    assert store.get(s.id) is None
    t = LoginThrottle(clock=lambda: now[0])
    waits = []
    for _ in range(FREE_FAILURES + 3):
        t.failed("name:ann")
        waits.append(t.wait_s("name:ann"))
    assert waits[:FREE_FAILURES - 1] == [0.0] * (FREE_FAILURES - 1)
    assert waits[FREE_FAILURES - 1:] == [1.0, 2.0, 4.0, 8.0]
    now[0] += 8.0
    assert t.wait_s("name:ann") == 0.0
    t.succeeded("name:ann")
    t.failed("name:ann")
    assert t.wait_s("name:ann") == 0.0
