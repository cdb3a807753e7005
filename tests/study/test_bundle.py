"""Remote bundles: opaque names, verified extraction, results files, and merging back with refusals."""
from __future__ import annotations

import json
import re
import zipfile
from pathlib import Path

import pytest

from studyapp.errors import InputError
from studyapp.study.bots import run_bot_session
from studyapp.study.bundle import make_bundle, merge_results, open_bundle, remote_row, write_results_file
from studyapp.study.design import load_design
from studyapp.study.export import export_dataframe
from studyapp.study.storage import ResultsDB
from studyapp.study.synthetic import write_synthetic_study

REAL_CONDITIONS = ("synced", "lagged", "static")


@pytest.fixture()
def lab(tmp_path: Path):
    """A study with two lab participants already in the experimenter's database."""
    design_path = write_synthetic_study(tmp_path / "study", n_stimuli=4, attention_check=True, questionnaire=True)
    design = load_design(design_path)
    results = tmp_path / "study" / "tiny.results.sqlite"
    db = ResultsDB(results, design)
    run_bot_session(design, db, "P01", "ordered", 1)
    run_bot_session(design, db, "P02", "ordered", 1)
    db.close()
    return design_path, design, results


def _remote_run(zip_path: Path, tmp_path: Path, pid: str) -> Path:
    """What `studyapp run STUDY.zip` does on a participant's PC, at the session level."""
    opened = open_bundle(zip_path, cache=tmp_path / "cache")
    design = load_design(opened.design_path)
    db = ResultsDB(tmp_path / "remote.sqlite", design)
    db.on_participant_finished = lambda p: write_results_file(db, p, tmp_path / "outbox", opened)
    session = run_bot_session(design, db, pid, "ordered", 3, row=remote_row(design, opened, pid))
    db.close()
    assert session.results_file is not None
    return session.results_file


def test_bundle_hides_conditions_and_file_names(lab, tmp_path: Path) -> None:
    design_path, design, results = lab
    info = make_bundle(design_path, tmp_path / "out" / "study.zip", participants=4, results=results)
    zf = zipfile.ZipFile(info.path)
    names = zf.namelist()
    manifest = json.loads(zf.read("manifest.json"))
    media = [n for n in names if n not in ("manifest.json", "study.toml")]
    assert len(media) == 6 * (1 + 3)  # 6 clips: audio + 3 motions each
    assert all(re.fullmatch(r"media/m_[0-9a-f]{12,14}\.(bvh|wav)", n) for n in media), media
    text = zf.read("study.toml").decode()
    originals = [s.id for s in design.stimuli] + [s.audio.stem for s in design.stimuli]
    for secret in REAL_CONDITIONS + tuple(originals):
        assert not any(secret in n for n in names), secret
        assert not re.search(rf"\b{re.escape(secret)}\b", text), secret
    # every file is listed with its checksum
    for n in names[1:]:
        import hashlib
        assert manifest["files"][n] == hashlib.sha256(zf.read(n)).hexdigest()
    # rows continue the lab's balance (rows 0 and 1 are taken once each)
    assert info.roster == {"R01": 2, "R02": 3, "R03": 4, "R04": 5}
    key = json.loads(info.key_path.read_text())
    assert sorted(key["conditions"].values()) == sorted(REAL_CONDITIONS)
    assert ResultsDB(results, design).bundle_key(info.bundle_hash)["design_hash"] == design.design_hash
    # a second bundle hands out new ids, so merging both never meets the same participant twice
    again = make_bundle(design_path, tmp_path / "out" / "study2.zip", participants=2, results=results)
    assert list(again.roster) == ["R05", "R06"]
    third = make_bundle(design_path, tmp_path / "out" / "study3.zip", participants=1, results=results)
    assert list(third.roster) == ["R07"]


def test_remote_run_and_merge_maps_back_to_real_ids(lab, tmp_path: Path) -> None:
    design_path, design, results = lab
    info = make_bundle(design_path, tmp_path / "study.zip", participants=2, results=results)
    opened = open_bundle(info.path, cache=tmp_path / "cache")
    bundled = load_design(opened.design_path)
    assert bundled.design_hash == info.bundle_hash != design.design_hash
    assert {c.id for c in bundled.conditions}.isdisjoint(REAL_CONDITIONS)
    results_zip = _remote_run(info.path, tmp_path, "R02")
    assert results_zip.name == "results-tiny-R02.zip"
    assert set(zipfile.ZipFile(results_zip).namelist()) == {"results.json", "manifest.json"}

    reports = merge_results(results, [results_zip])
    assert [r.ok for r in reports] == [True], reports[0].message
    df = export_dataframe(results)
    remote = df[df["participant"] == "R02"]
    assert len(remote) == 6 * 9
    assert set(remote["condition"]) == set(REAL_CONDITIONS)
    assert set(remote["stimulus"]) == {s.id for s in design.stimuli}
    assert (remote["design_hash"] == design.design_hash).all()
    assert (remote["remote"] == "yes").all()
    # the ordered bot ranked bundle conditions in bundle order, which is the design's order: synced first
    assert (remote["rank"] == remote["condition"].map({"synced": 1.0, "lagged": 2.0, "static": 3.0})).all()
    assert ResultsDB(results, design).participant("R02").latin_row == info.roster["R02"]

    # merging the same file again is refused as a duplicate, and nothing changes
    again = merge_results(results, [results_zip])
    assert not again[0].ok and "already" in again[0].message
    assert len(export_dataframe(results)) == len(df)


def test_merge_refuses_damaged_foreign_and_non_results_files(lab, tmp_path: Path) -> None:
    design_path, design, results = lab
    info = make_bundle(design_path, tmp_path / "study.zip", results=results)
    good = _remote_run(info.path, tmp_path, "R07")
    # damaged: results.json altered after packing (checksum no longer matches)
    damaged = tmp_path / "damaged.zip"
    with zipfile.ZipFile(good) as src, zipfile.ZipFile(damaged, "w") as dst:
        dst.writestr("manifest.json", src.read("manifest.json"))
        dst.writestr("results.json", src.read("results.json").replace(b'"rank": 1.0', b'"rank": 3.0'))
    # another design: a results file made from a different study
    other_path = write_synthetic_study(tmp_path / "other", n_stimuli=2, practice=False, name="other", seed=99)
    other = load_design(other_path)
    odb = ResultsDB(tmp_path / "other.sqlite", other)
    run_bot_session(other, odb, "X1", "random", 1)
    foreign = write_results_file(odb, "X1", tmp_path / "foreign")
    odb.close()
    junk = tmp_path / "results-junk.zip"
    junk.write_bytes(b"not a zip at all")

    reports = merge_results(results, [damaged, foreign, junk, good])
    ok = {r.file.name: (r.ok, r.message) for r in reports}
    assert ok[damaged.name][0] is False and "checksum" in ok[damaged.name][1]
    assert ok[foreign.name][0] is False and "another design" in ok[foreign.name][1]
    assert ok[junk.name][0] is False and "not a readable results file" in ok[junk.name][1]
    assert ok[good.name] == (True, "participant R07")
    assert ResultsDB(results, design).participant("X1") is None


def test_tampered_bundle_is_refused(lab, tmp_path: Path) -> None:
    design_path, _, results = lab
    info = make_bundle(design_path, tmp_path / "study.zip", results=results)
    bad = tmp_path / "bad.zip"
    with zipfile.ZipFile(info.path) as src, zipfile.ZipFile(bad, "w") as dst:
        for n in src.namelist():
            data = src.read(n)
            if n.endswith(".bvh") and "swapped" not in dst.comment.decode():
                data = data.replace(b"0.0000", b"1.0000", 1)
                dst.comment = b"swapped"
            dst.writestr(n, data)
    with pytest.raises(InputError, match="checksum mismatch"):
        open_bundle(bad, cache=tmp_path / "cache2")
    with pytest.raises(InputError, match="not a zip"):
        (tmp_path / "x.zip").write_text("hello")
        open_bundle(tmp_path / "x.zip", cache=tmp_path / "cache3")
    # an intact bundle whose cached copy was altered is extracted again
    opened = open_bundle(info.path, cache=tmp_path / "cache4")
    victim = next((opened.folder / "media").iterdir())
    victim.write_bytes(b"changed")
    again = open_bundle(info.path, cache=tmp_path / "cache4")
    assert victim.read_bytes() != b"changed" and again.design_path.is_file()


def test_live_model_is_bundled_without_revealing_metadata(tmp_path: Path) -> None:
    import onnx

    from studyapp.resources import designs_dir

    source = designs_dir() / "live_model_example.toml"
    original = onnx.load(str(designs_dir() / "models" / "reference_gesture.onnx"))
    info = make_bundle(source, tmp_path / "live.zip", results=tmp_path / "live.sqlite")
    opened = open_bundle(info.path, cache=tmp_path / "cache")
    design = load_design(opened.design_path)  # validates the stripped model against the model contract
    live = [c for c in design.conditions if c.model]
    assert len(live) == 1 and re.fullmatch(r"media/m_[0-9a-f]{12}\.onnx", live[0].model)
    model = onnx.load(str(opened.folder / live[0].model))
    meta = {p.key: p.value for p in model.metadata_props}
    assert model.graph.name == "model" and model.producer_name == "" and not any("description" in k for k in meta)
    kept = {p.key: p.value for p in original.metadata_props if "description" not in p.key}
    assert meta == kept
    assert "reference" not in opened.design_path.read_text()
