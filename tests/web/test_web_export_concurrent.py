"""The dashboard's CSV export of a large results database does not hold up the participants: a participant's
request made while an export runs is answered before the export is (the export reads on a connection of its
own in another thread, :func:`studyapp.web.dashboard.export_csv`)."""
from __future__ import annotations

import io
import threading
import warnings

import pandas as pd
import pytest

pytest.importorskip("starlette")
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from starlette.testclient import TestClient

from studyapp.study import export  # noqa: E402
from studyapp.study.export import export_dataframe  # noqa: E402
from studyapp.study.storage import ResultsDB  # noqa: E402

PASSWORD = "correct horse battery"
#: Copies of the finished participant: a database of tens of thousands of result rows.
COPIES = 600
#: Only a limit for a broken server (the export would hold the event loop): a working one answers at once.
GIVE_UP_S = 30.0


def grow(db: ResultsDB, template: str, copies: int) -> None:
    """Add ``copies`` participants with every row ``template`` has (their ids prefixed), in one transaction
    (sealed with their checksums, as the app's own writes are)."""
    con = db.connection
    with db.transaction() as tx:
        for table in ("participants", "sessions", "trials", "trial_slots", "responses", "plays", "questionnaire"):
            cols = [r[1] for r in con.execute(f"PRAGMA table_info({table})")]
            key = "id" if table == "participants" else "participant"
            kept = [c for c in cols if not (c == "id" and table in ("sessions", "plays"))]  # new row ids
            for k in range(copies):
                picked = ", ".join(f"'c{k}-' || {c}" if c == key else c for c in kept)
                tx.execute(f"INSERT INTO {table} ({', '.join(kept)}) SELECT {picked} FROM {table} WHERE {key} = ?",
                           (template,))


def test_a_participant_is_answered_while_the_export_of_a_large_database_runs(study, browser_for, monkeypatch) -> None:
    with TestClient(study.app(password=PASSWORD)) as client:
        done = browser_for(client, study)
        done.open("PROLIFIC_PID=full1")
        done.consent()
        done.act("continue")
        done.act("sound", {"user_agent": "test"})
        while done.state["screen"] == "trial":
            done.watch()
            done.answer_well()
        done.questionnaire()
        db = study.db()
        grow(db, "full1", COPIES)
        expected = export_dataframe(db)
        db.close()
        assert len(expected) > 20_000

        waiting = browser_for(client, study)
        waiting.open("PROLIFIC_PID=wait1")
        waiting.consent()
        assert waiting.state["screen"] == "instructions"
        assert client.post("/dashboard/login", json={"password": PASSWORD}).status_code == 200

        # the export reads the whole table, then stays running until the participant has been answered
        exporting, release = threading.Event(), threading.Event()
        real = export.export_dataframe

        def export_held_open(*args, **kw):
            table = real(*args, **kw)
            exporting.set()
            release.wait(GIVE_UP_S)
            return table

        monkeypatch.setattr(export, "export_dataframe", export_held_open)
        got: dict[str, object] = {}
        exporter = threading.Thread(target=lambda: got.setdefault("csv", client.get("/dashboard/export.csv")))
        exporter.start()
        try:
            assert exporting.wait(GIVE_UP_S * 4), "the export never ran"
            answered = threading.Event()

            def participant() -> None:
                waiting.act("continue")
                answered.set()

            threading.Thread(target=participant, daemon=True).start()
            in_time = answered.wait(GIVE_UP_S)
            export_still_running = exporter.is_alive() and "csv" not in got
        finally:
            release.set()
            exporter.join(GIVE_UP_S * 4)
        assert in_time and export_still_running, "the participant waited for the export"
        assert waiting.state["screen"] == "soundcheck"   # their action was done and stored
        csv = got["csv"]
        assert csv.status_code == 200
        table = pd.read_csv(io.StringIO(csv.text))
        assert len(table) == len(expected) and list(table.columns) == list(expected.columns)
        assert sorted(table["participant"].unique()) == sorted(expected["participant"].unique())
