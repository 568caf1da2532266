"""The workspace attacked on a real served socket (``fieldbank serve`` in its own process):
a stranger gets nothing, a change without the CSRF token is refused, a planted session id is
worth nothing, guessing passwords is throttled, static paths do not leave their list, a viewer
cannot write, a revoked token stops at once, and nothing binds beyond the loopback without TLS.
Every read and write that does happen names its account in the audit log."""

from __future__ import annotations

import datetime
import json
import socket
import ssl
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from fieldbank.storage import Database
from tests.workspace_util import PASSWORDS, ROOT, Workspace, build_db


@pytest.fixture(scope="module")
def served(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Workspace, str]]:
    root = tmp_path_factory.mktemp("ws")
    url = build_db(root)
    with Workspace(url) as ws:
        yield ws, url


def _api_routes(ws: Workspace) -> list[tuple[str, str]]:
    status, doc, _, _ = ws.client().request("GET", "/api/openapi.json")
    assert status == 200
    return [(m.upper(), p) for p, ops in doc["paths"].items() for m in ops]


def test_a_stranger_gets_401_from_every_api_route_and_no_data(served: tuple[Workspace, str]
                                                                ) -> None:
    ws, _ = served
    routes = _api_routes(ws)
    public = {("GET", "/api/session"), ("POST", "/api/login"), ("GET", "/api/openapi.json")}
    assert len(routes) >= 20 and public <= set(routes)
    c = ws.client()
    for method, path in routes:
        if (method, path) in public:
            continue
        concrete = (path.replace("{code}", "SYN-001").replace("{id}", "1")
                    .replace("{label}", "pre-BoNT"))
        status, doc, resp, body = c.request(method, concrete, {} if method == "POST" else None)
        assert status == 401, (method, path, status, body[:200])
        assert doc == {"error": "log in first (or send Authorization: Bearer TOKEN)"}
        assert b"SYN" not in body and resp.headers["Content-Type"].startswith(
            "application/json")
    # a forged bearer token and a forged session cookie get the same
    status, doc, _, _ = c.request("GET", "/api/patients",
                                  headers={"Authorization": "Bearer fbt_" + "A" * 43})
    assert status == 401 and "unknown or revoked" in doc["error"]
    c.cookies["fb_session"] = "x" * 43
    assert c.request("GET", "/api/patients")[0] == 401


def test_a_change_without_the_csrf_token_or_from_another_site_is_refused(
        served: tuple[Workspace, str]) -> None:
    ws, url = served
    c = ws.client()
    assert c.login("alice") == 200
    body = {"patient": "SYN-001", "botox": "ef=120U", "label": "csrf probe"}
    for kw in ({"csrf": False}, {"headers": {"X-CSRF-Token": "forged" * 7}, "csrf": False}):
        status, doc, _, _ = c.request("POST", "/api/plans", body, **kw)  # type: ignore[arg-type]
        assert status == 403 and "CSRF" in doc["error"]
    # the right token from another site's page: the Origin says so
    status, doc, _, _ = c.request("POST", "/api/plans", body,
                                  headers={"Origin": "http://evil.example"})
    assert status == 403 and "another site" in doc["error"]
    with Database.open(url) as db:
        assert not [p for p in db.list_plans("SYN-001") if p.label == "csrf probe"]
    # with the token, from the page itself: stored, and audited as alice from the loopback
    status, doc, _, _ = c.request("POST", "/api/plans", body)
    assert status == 200, doc
    with Database.open(url) as db:
        e = next(e for e in db.audit_entries(20, actor="alice") if e.entity == "plan")
        assert e.action == "add" and e.entity_id == str(doc["plan_id"])
        assert e.detail["request"] == {"via": "session", "from": "127.0.0.1"}


def test_session_fixation_a_planted_id_is_never_adopted_and_login_issues_a_new_one(
        served: tuple[Workspace, str]) -> None:
    ws, _ = served
    victim = ws.client()
    victim.open_page()  # the attacker learns (or plants) this anonymous session id
    planted = victim.cookies["fb_session"]
    assert victim.login("alice") == 200
    after = victim.cookies["fb_session"]
    assert after != planted
    attacker = ws.client()
    attacker.cookies["fb_session"] = planted
    assert attacker.request("GET", "/api/patients")[0] == 401
    assert victim.request("GET", "/api/patients")[0] == 200
    # an id the server never made is not taken up either: a fresh one replaces it
    stranger = ws.client()
    stranger.cookies["fb_session"] = "chosen-by-the-attacker"
    stranger.open_page()
    assert stranger.cookies["fb_session"] != "chosen-by-the-attacker"
    # the cookie is HttpOnly and SameSite=Strict
    cookie = [h for h in victim.set_cookie_headers if h.startswith("fb_session=")][-1]
    assert "HttpOnly" in cookie and "SameSite=Strict" in cookie and "Path=/" in cookie
    # logging out ends the session on the server
    assert victim.request("POST", "/api/logout")[0] == 200
    replay = ws.client()
    replay.cookies["fb_session"] = after
    assert replay.request("GET", "/api/patients")[0] == 401


def test_a_data_manager_adds_a_patient_and_ingests_files_all_or_nothing(
        served: tuple[Workspace, str]) -> None:
    ws, url = served
    d = ws.client()
    assert d.login("dana") == 200
    status, doc, _, _ = d.request("POST", "/api/patients", {
        "code": "DM-7", "body_mass_kg": 72, "height_m": 1.74, "side": "right"})
    assert status == 200 and doc["code"] == "DM-7"
    status, doc, _, _ = d.request("POST", "/api/patients", {
        "code": "<b>x</b>", "body_mass_kg": 68, "height_m": 1.7, "side": "left"})
    assert status == 400 and "must be a pseudonym" in doc["error"]  # the CLI's words
    root = Path(url.removeprefix("sqlite:///")).parents[1] / "samples" / "SYN-001" / "pre-BoNT"
    # SYN-001's map as another lab's file of DM-7 (no patient named in it)
    good = b"".join(line for line in (root / "postural.csv").read_bytes().splitlines(True)
                    if not line.startswith((b"# patient:", b"# session:")))

    def upload(files: list[tuple[str, bytes]]) -> tuple[int, dict[str, object]]:
        b = "workspace-boundary"
        parts = [f'--{b}\r\nContent-Disposition: form-data; name="date"\r\n\r\n'
                 "2024-05-01\r\n".encode()]
        for name, data in files:
            parts.append(f'--{b}\r\nContent-Disposition: form-data; name="file"; '
                         f'filename="{name}"\r\nContent-Type: text/csv\r\n\r\n'.encode()
                         + data + b"\r\n")
        status, doc, _, _ = d.request(
            "POST", "/api/patients/DM-7/sessions/first/files",
            raw=b"".join(parts) + f"--{b}--\r\n".encode(),
            headers={"Content-Type": f"multipart/form-data; boundary={b}"})
        return status, doc
    # one bad file among good ones: nothing stored, every problem named
    status, doc = upload([("postural.csv", good), ("bad.csv", b"x_m,y_m\n1,2\n")])
    assert status == 400 and "Nothing was stored" in str(doc["error"])
    with Database.open(url) as db:
        assert db.list_maps("DM-7") == []
    status, doc = upload([("postural.csv", good)])
    assert status == 200 and doc["stored"] == 1, doc
    with Database.open(url) as db:
        assert [m.session_label for m in db.list_maps("DM-7")] == ["first"]
        e = next(e for e in db.audit_entries(5, actor="dana") if e.action == "ingest")
        assert e.detail["request"]["via"] == "session"
    # a clinician may not
    c = ws.client()
    assert c.login("alice") == 200
    assert c.request("POST", "/api/patients", {"code": "X-2", "body_mass_kg": 68,
                                               "height_m": 1.7, "side": "left"})[0] == 403


def test_guessing_a_password_is_throttled_even_when_the_guess_is_right(
        served: tuple[Workspace, str]) -> None:
    ws, url = served
    c = ws.client()
    c.open_page()
    codes = [c.request("POST", "/api/login", {"name": "dana", "password": f"guess {k}"})[0]
             for k in range(6)]
    assert codes[:5] == [401] * 5 and codes[5] in (401, 429), codes
    status, doc, resp, _ = c.request("POST", "/api/login",
                                     {"name": "dana", "password": PASSWORDS["dana"]})
    assert status == 429 and "too many failed logins" in doc["error"]
    assert int(resp.headers["Retry-After"]) >= 1
    with Database.open(url) as db:
        refused = db.audit_entries(50, action="login-refused")
        assert len([e for e in refused if e.detail.get("name") == "dana"]) >= 5
        assert all(e.detail["request"]["from"] == "127.0.0.1" for e in refused)


def test_static_files_come_only_from_their_list(served: tuple[Workspace, str]) -> None:
    ws, _ = served
    c = ws.client()
    assert c.request("GET", "/static/core/app.js")[0] == 200
    for path in ("/static/core/../../../../etc/passwd", "/static/core/..%2f..%2fapp.py",
                 "/static/core/%2e%2e/%2e%2e/etc/passwd", "/static/core/app.py",
                 "/static/core/index.html", "/static/core/app.js%00.png",
                 "/static/..%2fweb/app.py", "/static/composer/..%2f..%2fstorage%2form.py",
                 "//etc/passwd", "/static/core/%252e%252e%252fapp.py"):
        with socket.create_connection((ws.host, ws.port), timeout=30) as s:
            # sent as typed: no client normalises the path first
            s.sendall(f"GET {path} HTTP/1.1\r\nHost: {ws.host}\r\nConnection: close\r\n\r\n"
                      .encode())
            raw = b""
            while chunk := s.recv(65536):
                raw += chunk
        head = raw.split(b"\r\n", 1)[0]
        assert b" 404 " in head or b" 400 " in head or b" 301 " in head, (path, head)
        assert b"root:" not in raw and b"import " not in raw and b"class " not in raw, path


def test_a_viewer_reads_but_cannot_write_and_a_revoked_token_stops_at_once(
        served: tuple[Workspace, str]) -> None:
    ws, url = served
    v = ws.client()
    assert v.login("victor") == 200
    assert v.request("GET", "/api/patients/SYN-001")[0] == 200
    status, doc, _, _ = v.request("POST", "/api/whatif", {"patient": "SYN-001",
                                                          "botox": "ef=100U"})
    assert status == 200 and doc["summary"]["lines"]
    for path, body in (("/api/plans", {"patient": "SYN-001", "botox": "ef=100U"}),
                       ("/api/plans/1/give", {"on": "2024-01-10"}),
                       ("/api/whatif/feel", {"patient": "SYN-001", "botox": "ef=100U"}),
                       ("/api/patients", {"code": "X-1", "body_mass_kg": 70, "height_m": 1.7,
                                          "side": "left"})):
        status, doc, _, _ = v.request("POST", path, body)
        assert status == 403 and "a viewer may not" in doc["error"], (path, doc)
    assert v.request("GET", "/api/audit")[0] == 403
    # an API client: a token, used, revoked, refused
    with Database.open(url) as db:
        from fieldbank.web.accounts import new_token

        token, rec = new_token(db, "alice", "ward laptop")
    api = ws.client()
    auth = {"Authorization": f"Bearer {token}"}
    status, doc, _, _ = api.request("POST", "/api/plans", {"patient": "SYN-001",
                                                          "botox": "ef=90U"}, headers=auth)
    assert status == 200, doc  # no cookie, so no CSRF token needed
    with Database.open(url) as db:
        e = next(e for e in db.audit_entries(10, actor="alice") if e.entity == "plan")
        assert e.detail["request"]["via"] == f"token {rec.id}"
        db.revoke_token(rec.id)
    status, doc, _, _ = api.request("GET", "/api/patients", headers=auth)
    assert status == 401 and "revoked" in doc["error"]


def test_reads_of_a_patient_are_in_the_audit_log_and_fieldbank_audit_shows_them(
        served: tuple[Workspace, str]) -> None:
    ws, url = served
    c = ws.client()
    assert c.login("victor") == 200
    assert c.request("GET", "/api/patients/SYN-001")[0] == 200
    assert c.request("GET", "/api/maps/1/figure.svg")[0] == 200
    status, _, resp, body = c.request("GET", "/api/patients/SYN-001/report.html")
    assert status == 200 and b"SYN-001" in body and b"<h1>" in body
    assert resp.headers["Content-Disposition"] == 'attachment; filename="report-SYN-001.html"'
    out = subprocess.run([sys.executable, "-m", "fieldbank.cli", "audit", "--patient",
                          "SYN-001", "--user", "victor", "--since",
                          datetime.date.today().isoformat(), "--json", "--db", url],
                         capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert out.returncode == 0, out.stderr
    rows = json.loads(out.stdout)
    whats = [r["detail"]["what"] for r in rows if r["action"] == "read"]
    assert "map 1 figure" in whats and any(w.startswith("patient page") for w in whats)
    assert "report of its plans" in whats
    assert all(r["actor"] == "victor" and r["detail"]["request"]["from"] == "127.0.0.1"
               for r in rows)
    # the text form names the same, one line each
    text = subprocess.run([sys.executable, "-m", "fieldbank.cli", "audit", "--user", "victor",
                           "--db", url], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert text.returncode == 0 and "victor" in text.stdout and "read" in text.stdout
    assert all(len(line) <= 100 for line in text.stdout.splitlines())
    # nothing in the application edits the log: no route changes it, and the database
    # refuses it to anyone who tries
    assert not [p for p in _api_routes(ws) if p[1].startswith("/api/audit")
                and p[0] != "GET"]
    with Database.open(url) as db, pytest.raises(Exception, match=r"(?i)append-only|audit"):
        db.raw_sql("DELETE FROM audit_log")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_beyond_the_loopback_only_with_tls_refused_before_binding(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'db.sqlite3'}"
    Database.open(url).close()
    port = _free_port()
    out = subprocess.run([sys.executable, "-m", "fieldbank.cli", "serve", "--host", "0.0.0.0",
                          "--port", str(port), "--db", url], capture_output=True, text=True,
                         cwd=ROOT, timeout=300)
    assert out.returncode == 1
    assert "only with TLS" in out.stderr and "Nothing was bound" in out.stderr
    with socket.socket() as s:  # the port was never taken
        s.bind(("0.0.0.0", port))
    key = tmp_path / "key.pem"
    key.write_text("not a key")
    out = subprocess.run([sys.executable, "-m", "fieldbank.cli", "serve", "--host", "0.0.0.0",
                          "--port", str(port), "--db", url, "--tls-cert", str(key),
                          "--tls-key", str(key)], capture_output=True, text=True, cwd=ROOT,
                         timeout=300)
    assert out.returncode == 1 and "not a certificate and its key" in out.stderr


def _self_signed(tmp_path: Path) -> tuple[Path, Path]:
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID

    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "127.0.0.1")])
    now = datetime.datetime.now(datetime.UTC)
    import ipaddress

    cert = (x509.CertificateBuilder().subject_name(name).issuer_name(name)
            .public_key(key.public_key()).serial_number(x509.random_serial_number())
            .not_valid_before(now - datetime.timedelta(minutes=5))
            .not_valid_after(now + datetime.timedelta(days=1))
            .add_extension(x509.SubjectAlternativeName(
                [x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]), critical=False)
            .sign(key, hashes.SHA256()))
    c, k = tmp_path / "cert.pem", tmp_path / "key.pem"
    c.write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    k.write_bytes(key.private_bytes(serialization.Encoding.PEM,
                                    serialization.PrivateFormat.PKCS8,
                                    serialization.NoEncryption()))
    return c, k


def test_tls_serves_https_with_secure_cookies_and_refuses_plain_http(tmp_path: Path) -> None:
    url = build_db(tmp_path)
    cert, key = _self_signed(tmp_path)
    with Workspace(url, "--tls-cert", str(cert), "--tls-key", str(key)) as ws:
        assert ws.url.startswith("https://127.0.0.1:")
        ctx = ssl.create_default_context(cafile=str(cert))
        c = ws.client(ctx)
        assert c.login("alice") == 200
        cookie = [h for h in c.set_cookie_headers if h.startswith("fb_session=")][-1]
        assert "Secure" in cookie and "HttpOnly" in cookie
        status, doc, resp, _ = c.request("GET", "/api/patients")
        assert status == 200 and [p["code"] for p in doc["patients"]] == ["SYN-001"]
        assert resp.headers["Strict-Transport-Security"].startswith("max-age=")
        # a client that does not trust the certificate gets nothing
        with pytest.raises(ssl.SSLError):
            ws.client(ssl.create_default_context()).request("GET", "/api/session")
        # plain HTTP to the TLS port gets no page
        with socket.create_connection((ws.host, ws.port), timeout=30) as s:
            s.sendall(b"GET /api/session HTTP/1.1\r\nHost: x\r\n\r\n")
            s.settimeout(30)
            try:
                raw = s.recv(4096)
            except (ConnectionResetError, TimeoutError):
                raw = b""
        assert b"csrf" not in raw
