"""The study server's security rules: headers on every response, no listing or file by path, CSRF and origin
checks on every state-changing request, rate limits, the experimenter's dashboard behind a password, and the
video endpoint answering only the current trial of the participant the address belongs to."""
from __future__ import annotations

import io
import warnings

import pandas as pd

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from starlette.testclient import TestClient

from fixtures.web_study import state_of
from studyapp.study.export import export_dataframe
from studyapp.web.security import CSP, RateLimiter

PASSWORD = "correct horse battery"


def _participant(client, study, browser_for, pid: str = "pp1"):
    b = browser_for(client, study)
    b.open(f"PROLIFIC_PID={pid}")
    b.consent()
    b.act("continue")
    b.act("sound", {})
    return b


def test_every_response_carries_the_security_headers(study, browser_for) -> None:
    with TestClient(study.app(password=PASSWORD)) as client:
        b = _participant(client, study, browser_for)
        responses = [client.get("/"), client.get(b.base), client.get(b.state["video"]), client.get("/a/app.js"),
                     client.get("/nothing"), client.get("/dashboard"),
                     client.post(b.base + "play", json={}, headers={"X-CSRF-Token": b.csrf})]
        for r in responses:
            h = r.headers
            assert h["content-security-policy"] == CSP and "frame-ancestors 'none'" in CSP, r.url
            assert "script-src 'self'" in CSP and "unsafe-inline" not in CSP
            assert h["x-content-type-options"] == "nosniff" and h["referrer-policy"] == "no-referrer"
            assert h["x-frame-options"] == "DENY" and "server" not in h
            assert h["cache-control"] == ("public, max-age=300" if "/a/" in str(r.url) else "no-store")


def test_no_listing_and_no_file_by_path(study, browser_for) -> None:
    with TestClient(study.app()) as client:
        b = _participant(client, study, browser_for)
        for url in ("/a/", "/a", "/s/", "/a/../flow.py", "/a/%2e%2e/flow.py", "/a/app.py", "/a/assets", "/assets/app.js",
                    "/studyapp/web/assets/app.js", "/s/" + "A" * 22 + "/", b.base + "x.mp4", b.base + "../",
                    "/" + study.db_path.name, "/dashboard"):
            r = client.get(url, follow_redirects=False)
            assert r.status_code in (404, 405), (url, r.status_code)
            assert "<a href" not in r.text and "flow.py" not in r.text


def test_the_video_address_serves_only_the_current_trial_of_its_participant(study, browser_for) -> None:
    with TestClient(study.app()) as client:
        a = _participant(client, study, browser_for, "pa")
        b = _participant(client, study, browser_for, "pb")
        first = a.state["video"]
        assert first != b.state["video"]
        name = first.rsplit("/", 1)[1]
        assert client.get(b.base + name).status_code == 404          # a's video under b's address
        r = client.get(first, headers={"range": "bytes=0-99"})      # a browser streams by byte ranges
        assert r.status_code == 206 and len(r.content) == 100
        full = client.get(first)
        assert full.headers["etag"] == f'"{name[:-4]}"' and full.headers["last-modified"].startswith("Thu, 01 Jan 1970")
        assert "content-disposition" not in full.headers
        assert full.content == study.videos.video(a.plan()).read_bytes()
        a.watch()
        a.answer_well()
        assert client.get(first).status_code == 404                 # an answered trial's video is gone


def test_state_changes_need_json_the_csrf_token_and_the_same_origin(study, browser_for) -> None:
    with TestClient(study.app()) as client:
        b = _participant(client, study, browser_for)
        url = b.base + "play"
        assert client.post(url, json={}).status_code == 400                                       # no token
        assert client.post(url, json={}, headers={"X-CSRF-Token": "x" * 22}).status_code == 400   # wrong token
        other = _participant(client, study, browser_for, "pp2")
        assert client.post(url, json={}, headers={"X-CSRF-Token": other.csrf}).status_code == 400  # another's
        assert client.post(url, data={"a": "1"}, headers={"X-CSRF-Token": b.csrf}).status_code == 400  # a form
        r = client.post(url, json={}, headers={"X-CSRF-Token": b.csrf, "Origin": "https://evil.example"})
        assert r.status_code == 400
        s = browser_for(client, study).open("PROLIFIC_PID=pp3")
        bad = client.post("/start", json={"nonce": s["nonce"], "csrf": "forged", "consent": True, "params": {}})
        assert bad.status_code == 400
        db = study.db()
        assert db.plays() == [] and db.participant("pp3") is None
        db.close()
        ok = client.post(url, json={}, headers={"X-CSRF-Token": b.csrf, "Origin": "http://testserver"})
        assert ok.status_code == 200


def test_rate_limits(study, browser_for) -> None:
    limits = {"action": RateLimiter(per_s=0.001, burst=5), "start": RateLimiter(per_s=0.001, burst=3)}
    with TestClient(study.app(limits=limits)) as client:
        b = browser_for(client, study)
        codes = []
        for k in range(4):
            s = b.open(f"PROLIFIC_PID=r{k}")
            codes.append(client.post("/start", json={"nonce": s["nonce"], "csrf": s["entry_csrf"], "consent": True,
                                                     "params": s["params"]}).status_code)
        assert codes == [200, 200, 200, 429]
        b.open("PROLIFIC_PID=r0")
        b.base = client.get("/?PROLIFIC_PID=r0", follow_redirects=False).headers["location"]
        b.reload()
        got = [client.post(b.base + "continue", json={}, headers={"X-CSRF-Token": b.csrf}).status_code
               for _ in range(7)]
        assert got[-1] == 429 and got.count(429) == 2


def test_bad_prolific_parameters_are_refused(study) -> None:
    with TestClient(study.app()) as client:
        for q in ("PROLIFIC_PID=<script>", "PROLIFIC_PID=" + "a" * 65, "STUDY_ID=a%20b"):
            r = client.get("/?" + q)
            assert r.status_code == 403 and "not valid" in r.text and "<script>" not in r.text


def test_the_dashboard_is_off_without_a_password(study) -> None:
    with TestClient(study.app()) as client:
        assert client.get("/dashboard").status_code == 404
        assert client.get("/dashboard/export.csv").status_code == 404
        assert client.post("/dashboard/login", json={"password": ""}).status_code == 404


def test_the_dashboard_needs_the_password_and_shows_progress(study, browser_for) -> None:
    with TestClient(study.app(password=PASSWORD)) as client:
        b = _participant(client, study, browser_for)
        while b.state["screen"] == "trial":
            b.watch()
            b.answer_well()
        b.questionnaire()
        c = _participant(client, study, browser_for, "pp2")
        c.watch()
        c.answer_well()
        page = client.get("/dashboard")
        assert page.status_code == 200 and '"screen": "login"' in page.text and "pp1" not in page.text
        assert client.get("/dashboard/export.csv").status_code == 401
        assert client.post("/dashboard/login", json={"password": "wrong"}).status_code == 403
        r = client.post("/dashboard/login", json={"password": PASSWORD})
        assert r.status_code == 200
        cookie = r.headers["set-cookie"]
        assert "httponly" in cookie.lower() and "samesite=strict" in cookie.lower()
        st = state_of(client.get("/dashboard").text)
        assert st["screen"] == "dashboard" and st["participants"] == 2
        assert st["totals"]["done"] == 1 and st["totals"]["active"] == 1
        assert sum(r["done"] + r["active"] for r in st["rows"]) == 2 and st["rows"][0]["done"] == 1
        assert st["median_seconds_per_trial"] is not None and st["median_minutes_to_complete"] is not None
        csv = client.get("/dashboard/export.csv")
        assert csv.status_code == 200 and csv.headers["content-type"].startswith("text/csv")
        db = study.db()
        expected = export_dataframe(db)
        db.close()
        got = pd.read_csv(io.StringIO(csv.text))
        assert len(got) == len(expected) > 0 and list(got.columns) == list(expected.columns)
        assert got["rank"].tolist() == expected["rank"].tolist()
        client.cookies.clear()
        assert client.get("/dashboard/export.csv").status_code == 401
        client.cookies.set("studyapp_dashboard", "forged.value", path="/dashboard")
        assert client.get("/dashboard/export.csv").status_code == 401


def test_logins_are_rate_limited(study) -> None:
    with TestClient(study.app(password=PASSWORD)) as client:
        codes = [client.post("/dashboard/login", json={"password": "guess"}).status_code for _ in range(6)]
        assert codes == [403] * 5 + [429]
        assert client.post("/dashboard/login", json={"password": PASSWORD}).status_code == 429
