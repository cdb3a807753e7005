"""Remote bundles: opaque names, verified extraction, results files, and merging back with refusals."""
from __future__ import annotations

import json
import re
import zipfile
from pathlib import Path

import numpy as np
import pytest

from studyapp.errors import InputError
from studyapp.bots.session_driver import run_bot_session
from studyapp.study.bundle import make_bundle, merge_results, open_bundle, write_results_file
from studyapp.study.design import load_design
from studyapp.study.export import export_dataframe
from studyapp.study.storage import ResultsDB
from fixtures.bundles import remote_run, shipped_motions
from fixtures.synthetic import write_synthetic_study

REAL_CONDITIONS = ("synced", "lagged", "static")
#: Seconds per clip of the lab study. Merging refuses answers given sooner than a clip lasts (the design
#: requires watching it), so every bot whose results are merged watches each clip this long.
CLIP_S = 0.3


@pytest.fixture()
def lab(tmp_path: Path):
    """A study with two lab participants already in the experimenter's database."""
    design_path = write_synthetic_study(tmp_path / "study", n_stimuli=4, seconds=CLIP_S, attention_check=True,
                                        questionnaire=True)
    design = load_design(design_path)
    results = tmp_path / "study" / "tiny.results.sqlite"
    db = ResultsDB(results, design)
    run_bot_session(design, db, "P01", "ordered", 1)
    run_bot_session(design, db, "P02", "ordered", 1)
    db.close()
    return design_path, design, results


def _remote_run(zip_path: Path, tmp_path: Path, pid: str) -> Path:
    """What `studyapp run STUDY.zip` does on a participant's PC, at the session level."""
    return remote_run(zip_path, tmp_path, pid, pace_s=CLIP_S)


def test_bundle_hides_conditions_and_file_names(lab, tmp_path: Path) -> None:
    design_path, design, results = lab
    info = make_bundle(design_path, tmp_path / "out" / "study.zip", participants=4, results=results)
    zf = zipfile.ZipFile(info.path)
    names = zf.namelist()
    manifest = json.loads(zf.read("manifest.json"))
    media = [n for n in names if n not in ("manifest.json", "study.toml", "schedule.json")]
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
    key = info.key
    assert {c for t in key["trials"].values() for c in t["conditions"].values()} == set(REAL_CONDITIONS)
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
    assert re.fullmatch(r"results-Tiny-synthetic-study-tiny-R02-[0-9a-f]{8}\.zip", results_zip.name), results_zip.name
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
    # the duration each remote trial played travels back with it (the synthetic clips' length of audio each)
    assert remote["trial_duration_s"].tolist() == [CLIP_S] * len(remote)
    # the ordered bot ranked the shipped tokens x1 < x2 < x3, which stand for other conditions in every trial
    token_rank = {"x1": 1.0, "x2": 2.0, "x3": 3.0}
    trials = {(t["participant"], t["trial_index"]): t for t in info.key["trials"].values()}
    want = [next(token_rank[tok] for tok, real in trials[("R02", r.trial_index)]["conditions"].items()
                 if real == r.condition) for r in remote.itertuples()]
    assert remote["rank"].tolist() == want
    # tokens mean nothing across trials: over the bundle's trials (both participants') every condition stands
    # behind several tokens. (Over R02's six trials alone one condition keeps one token in ~1 % of salts: a
    # fresh-clone run met it; over all of the key's trials that is ~1e-5.)
    tokens_of: dict[str, set[str]] = {}
    for t in info.key["trials"].values():
        for tok, real in t["conditions"].items():
            tokens_of.setdefault(real, set()).add(tok)
    assert set(tokens_of) == set(REAL_CONDITIONS) and min(map(len, tokens_of.values())) > 1, tokens_of
    assert ResultsDB(results, design).participant("R02").latin_row == info.roster["R02"]

    # merging the same file again is reported as already merged (not an error), and nothing changes
    again = merge_results(results, [results_zip])
    assert again[0].ok and again[0].already and "already merged" in again[0].message
    assert len(export_dataframe(results)) == len(df)


def test_merge_refuses_damaged_foreign_and_non_results_files(lab, tmp_path: Path) -> None:
    design_path, design, results = lab
    info = make_bundle(design_path, tmp_path / "study.zip", results=results, participants=1)
    good = _remote_run(info.path, tmp_path, "R01")
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

    reports = merge_results(results, [damaged, foreign, junk, good], allow_unlisted=True)
    ok = {r.file.name: (r.ok, r.message) for r in reports}
    assert ok[damaged.name][0] is False and "checksum" in ok[damaged.name][1]
    assert ok[foreign.name][0] is False and "another design" in ok[foreign.name][1]
    assert ok[junk.name][0] is False and "not a readable results file" in ok[junk.name][1]
    assert ok[good.name] == (True, "participant R01")
    assert ResultsDB(results, design).participant("X1") is None


def test_results_files_of_ids_that_sanitize_alike_never_collide(lab, tmp_path: Path) -> None:
    """``p/1`` and ``p-1`` make the same safe name, ``A`` and ``a`` the same file on Windows/macOS:
    each participant still gets a file of their own, and merge imports all of them."""
    design_path, design, results = lab
    remote = ResultsDB(tmp_path / "remote.sqlite", design)
    ids = ["p/1", "p-1", "A", "a"]
    files = {}
    for pid in ids:
        run_bot_session(design, remote, pid, "ordered", 1, pace_s=CLIP_S)
        files[pid] = write_results_file(remote, pid, tmp_path / "outbox")
    remote.close()
    names = [f.name for f in files.values()]
    assert len({n.lower() for n in names}) == 4, names  # distinct even where case does not count
    assert sorted(p.name for p in (tmp_path / "outbox").iterdir()) == sorted(names)
    for pid, f in files.items():
        assert json.loads(zipfile.ZipFile(f).read("manifest.json"))["participant"] == pid
    # the same id always gets the same name
    again = ResultsDB(tmp_path / "remote.sqlite", design)
    assert write_results_file(again, "p/1", tmp_path / "outbox") == files["p/1"]
    again.close()
    assert len(list((tmp_path / "outbox").iterdir())) == 4

    reports = merge_results(results, list(files.values()))
    assert all(r.ok for r in reports), [r.message for r in reports]
    assert sorted(r.participant for r in reports) == sorted(ids)
    assert set(ids) <= set(export_dataframe(results)["participant"])


def test_results_file_never_overwrites_another_participants_file(lab, tmp_path: Path) -> None:
    design_path, design, results = lab
    remote = ResultsDB(tmp_path / "remote.sqlite", design)
    for pid in ("X1", "X2"):
        run_bot_session(design, remote, pid, "ordered", 1, pace_s=CLIP_S)
    first = write_results_file(remote, "X1", tmp_path / "outbox")
    # whatever sits where X2's file would go -- another participant's results, or any other file -- is kept
    target = write_results_file(remote, "X2", tmp_path / "scratch")
    squatter = tmp_path / "outbox" / target.name
    first.rename(squatter)
    kept = squatter.read_bytes()
    second = write_results_file(remote, "X2", tmp_path / "outbox")
    remote.close()
    assert second != squatter and second.name == target.name.replace(".zip", "-2.zip")
    assert squatter.read_bytes() == kept
    assert json.loads(zipfile.ZipFile(squatter).read("manifest.json"))["participant"] == "X1"
    assert json.loads(zipfile.ZipFile(second).read("manifest.json"))["participant"] == "X2"
    reports = merge_results(results, [squatter, second])
    assert [(r.ok, r.participant) for r in reports] == [(True, "X1"), (True, "X2")]


def test_tampered_bundle_is_refused(lab, tmp_path: Path) -> None:
    design_path, _, results = lab
    info = make_bundle(design_path, tmp_path / "study.zip", results=results, participants=1)
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


def test_live_model_is_bundled_as_its_generated_motion(tmp_path: Path) -> None:
    """A live condition must look like the others inside the zip: no .onnx singles it out, and the remote
    participant's PC plays exactly the frames the model streams in the lab."""
    from studyapp.motion.fk import joint_positions
    from studyapp.resources import designs_dir
    from studyapp.study.stimuli import load_condition_motion

    source = designs_dir() / "live_model_example.toml"
    lab_design = load_design(source)
    info = make_bundle(source, tmp_path / "live.zip", results=tmp_path / "live.sqlite", participants=1)
    with zipfile.ZipFile(info.path) as zf:
        names = zf.namelist()
    assert not [n for n in names if n.endswith(".onnx")], names
    opened = open_bundle(info.path, cache=tmp_path / "cache")
    text = opened.design_path.read_text()
    assert "model =" not in text and "reference" not in text and "onnx" not in text
    bundled = load_design(opened.design_path)
    assert all(c.model is None and c.motion.endswith(".bvh") for c in bundled.conditions)
    lab_live = lab_design.condition("reference")
    checked = 0
    for m in shipped_motions(info.key, opened.design_path):
        if m.condition != "reference":
            continue
        shipped = load_condition_motion(bundled, bundled.condition(m.token), bundled.stimulus(m.shipped_stimulus))
        generated = load_condition_motion(lab_design, lab_live, lab_design.stimulus(m.stimulus))
        assert shipped.n_frames == generated.n_frames
        # BVH keeps 6 decimals of a degree: compare world joint positions, not bits
        err = np.abs(joint_positions(shipped) - joint_positions(generated)).max()
        assert err < 1e-3, err
        checked += 1
    assert checked == len(bundled.stimuli)


# ------------------------------------------------------------------------------------------ blinding of file names
def _grams(text: str, n: int = 4) -> set[str]:
    return {text[i:i + n] for i in range(len(text) - n + 1)}


def _speaker_pattern_study(tmp_path: Path) -> Path:
    """The tiny study with one condition's motion shared per speaker (``{speaker}`` pattern), not per clip."""
    design_path = write_synthetic_study(tmp_path / "spk", n_stimuli=4, attention_check=True)
    for k, spk in enumerate(("spk1", "spk2")):
        (design_path.parent / "motion" / "static" / f"{spk}.bvh").write_bytes(
            (design_path.parent / "motion" / "static" / f"s{k + 1}.bvh").read_bytes())
    text = design_path.read_text().replace('"motion/static/{stimulus}.bvh"', '"motion/static/{speaker}.bvh"')
    design_path.write_text(text)
    return design_path


@pytest.mark.parametrize("which", ["synthetic", "speaker-pattern"])
def test_bundle_file_names_cannot_be_grouped_by_condition(which: str, tmp_path: Path) -> None:
    """Motion files used to be ``m_<stimulus hash><condition hash>``: the last six hex digits named the model
    across every clip. No name fragment may be common to one condition's files now, even where one file
    serves several clips (a ``{speaker}`` pattern). (The demo design: test_bundle_blinding.)"""
    from studyapp.study.design import motion_path

    design_path = {"synthetic": lambda: write_synthetic_study(tmp_path / "s", n_stimuli=5, attention_check=True),
                   "speaker-pattern": lambda: _speaker_pattern_study(tmp_path)}[which]()
    design = load_design(design_path)
    info = make_bundle(design_path, tmp_path / "out" / "study.zip", results=tmp_path / "lab.sqlite", salt="qa-salt",
                       participants=3)
    opened = open_bundle(info.path, cache=tmp_path / "cache")
    by_cond: dict[str, set[str]] = {}
    for m in shipped_motions(info.key, opened.design_path):
        assert m.path.parent == opened.folder / "media" and m.path.is_file(), m.path
        # the per-trial indirection must still play the right model's file for the right clip
        assert m.path.read_bytes() == motion_path(design, m.condition, m.stimulus).read_bytes(), m
        by_cond.setdefault(m.condition, set()).add(m.path.stem[len("m_"):])
    assert sorted(by_cond) == sorted(c.id for c in design.conditions)
    on_disk = sorted(p.name for p in (opened.folder / "media").iterdir())
    assert on_disk == sorted(n[len("media/"):] for n in zipfile.ZipFile(info.path).namelist() if n.startswith("media/"))
    assert all(re.fullmatch(r"m_[0-9a-f]{12}\.(bvh|wav|csv)", n) for n in on_disk), on_disk
    for real, stems in by_cond.items():
        assert len(stems) >= 2, (real, stems)
        shared = set.intersection(*(_grams(t) for t in stems))
        assert not shared, f"{real}'s files all contain {sorted(shared)}: {stems}"
    # nor does a real id or file name show anywhere a participant can look (cache folder included)
    visible = [str(p.relative_to(opened.folder.parent)) for p in opened.folder.rglob("*")]
    for secret in [c.id for c in design.conditions] + [s.id for s in design.stimuli]:
        assert not any(secret in v for v in visible), secret


def test_bundle_names_are_reproducible_with_the_salt_only(tmp_path: Path) -> None:
    """The same salt and roster give the same bundle (ids, names, hash); another salt shares nothing, so the
    opaque ids cannot be computed from the model names."""
    design_path = write_synthetic_study(tmp_path / "study", n_stimuli=4, attention_check=True)

    def contents(name: str, salt: str) -> tuple[str, list[str], str]:
        info = make_bundle(design_path, tmp_path / name, results=tmp_path / f"{name}.sqlite", salt=salt,
                           participants=2)
        zf = zipfile.ZipFile(info.path)
        return info.bundle_hash, sorted(zf.namelist()), zf.read("study.toml").decode()

    first, again, other = contents("a.zip", "s1"), contents("b.zip", "s1"), contents("c.zip", "s2")
    assert first == again
    assert first[0] != other[0]
    assert set(first[1]) & set(other[1]) == {"manifest.json", "schedule.json", "study.toml"}
    ids = set(re.findall(r'^id = "([0-9a-f]{12})"', first[2], flags=re.M))
    assert len(ids) > 3 and ids.isdisjoint(re.findall(r'^id = "([0-9a-f]{12})"', other[2], flags=re.M))


def test_bundle_is_refused_without_participants_and_for_ids_not_on_it(lab, tmp_path: Path) -> None:
    """The trials of an id the bundle was not made for cannot be computed on the participant's PC without
    telling the models apart: a bundle is made for a roster, and another id is refused by name."""
    from studyapp.study.bundle import remote_plan

    design_path, design, results = lab
    with pytest.raises(InputError, match="--participants N"):
        make_bundle(design_path, tmp_path / "none.zip", results=results)
    assert not (tmp_path / "none.zip").exists()
    info = make_bundle(design_path, tmp_path / "study.zip", results=results, participants=2)
    opened = open_bundle(info.path, cache=tmp_path / "cache")
    with pytest.raises(InputError, match="'P77' is not one of the participant ids .* R01, R02"):
        remote_plan(opened, "P77")
    from studyapp.study.schedule import participant_schedule

    real = participant_schedule(design, "R02", info.roster["R02"])
    assert [p.trial_index for p in remote_plan(opened, "R02").plans] == list(range(len(real)))


# ------------------------------------------------------------------------------------------ reported counts
def test_bundle_reports_the_files_that_are_in_the_zip(lab, tmp_path: Path, capsys) -> None:
    from studyapp.cli import main

    design_path, _, results = lab
    out = tmp_path / "send" / "study.zip"
    assert main(["bundle", str(design_path), "-o", str(out), "--results", str(results), "--participants", "1"]) == 0
    printed = capsys.readouterr().out
    names = zipfile.ZipFile(out).namelist()
    total = re.search(r"\((\d+) files\b", printed)
    assert total and int(total.group(1)) == len(names) == 3 + 6 * (1 + 3), (printed, names)
    media = re.search(r"\(\d+ files: (\d+) media files, study\.toml, schedule\.json and manifest\.json; [\d.]+ MB\)",
                      printed)
    assert media and int(media.group(1)) == sum(n.startswith("media/") for n in names) == len(names) - 3, printed
    assert {"manifest.json", "study.toml", "schedule.json"} <= set(names)
    info = make_bundle(design_path, tmp_path / "again.zip", results=results, participants=1)
    assert info.n_files == len(zipfile.ZipFile(info.path).namelist())
    assert info.n_media == info.n_files - 3


def test_results_file_is_updated_on_resume_but_never_replaced_by_a_fresh_run(lab, tmp_path: Path) -> None:
    """Resuming extends the participant's file in place; a run from a reset local database (other answers)
    goes beside it, so answers the participant may not have sent yet are never overwritten."""
    _, design, _ = lab
    outbox = tmp_path / "outbox"
    remote = ResultsDB(tmp_path / "remote.sqlite", design)

    class Stop(Exception):
        pass

    def stop_after_two(plan) -> None:
        if plan.trial_index >= 1:
            raise Stop

    with pytest.raises(Stop):
        run_bot_session(design, remote, "X1", "ordered", 1, on_trial=stop_after_two)
    partial = write_results_file(remote, "X1", outbox)
    n_partial = len(json.loads(zipfile.ZipFile(partial).read("results.json"))["trials"])
    run_bot_session(design, remote, "X1", "ordered", 1)  # resumes
    full = write_results_file(remote, "X1", outbox)
    remote.close()
    assert full == partial
    n_full = len(json.loads(zipfile.ZipFile(full).read("results.json"))["trials"])
    assert 1 <= n_partial < n_full
    kept = full.read_bytes()

    reset = ResultsDB(tmp_path / "reset.sqlite", design)  # the participant's local data was wiped
    run_bot_session(design, reset, "X1", "ordered", 1)
    again = write_results_file(reset, "X1", outbox)
    reset.close()
    assert again.name == full.name.replace(".zip", "-2.zip")
    assert full.read_bytes() == kept


def test_merge_refuses_byte_damaged_truncated_and_malformed_files_one_line_each(lab, tmp_path: Path) -> None:
    """Bytes flipped inside the compressed data, a cut-off download, a forged file with a matching checksum:
    each is refused with a message, the others still import, and the database keeps nothing of the bad ones."""
    import hashlib
    import json

    design_path, design, results = lab
    info = make_bundle(design_path, tmp_path / "study.zip", results=results, participants=1)
    good = _remote_run(info.path, tmp_path, "R01")
    raw = good.read_bytes()
    with zipfile.ZipFile(good) as zf:
        member = zf.getinfo("results.json")
        manifest = json.loads(zf.read("manifest.json"))
    start = member.header_offset + 30 + len(member.filename.encode()) + len(member.extra)
    flipped = tmp_path / "flipped.zip"
    data = bytearray(raw)
    for i in range(start + 8, start + member.compress_size - 8, 97):  # inside the deflate stream
        data[i] ^= 0xFF
    flipped.write_bytes(bytes(data))
    truncated = tmp_path / "truncated.zip"
    truncated.write_bytes(raw[: len(raw) // 2])
    forged = tmp_path / "forged.zip"
    body = json.dumps({"design_hash": manifest["design_hash"], "participants": [{"id": "R99"}]}).encode()
    manifest["files"]["results.json"] = hashlib.sha256(body).hexdigest()
    with zipfile.ZipFile(forged, "w") as zf:
        zf.writestr("results.json", body)
        zf.writestr("manifest.json", json.dumps(manifest))

    # a matching checksum over rows whose values SQLite cannot store (a list where a number belongs)
    listy = tmp_path / "listy.zip"
    with zipfile.ZipFile(good) as zf:
        payload = json.loads(zf.read("results.json"))
        manifest2 = json.loads(zf.read("manifest.json"))
    payload["trials"][0]["plays"] = [1, 2]
    body2 = json.dumps(payload).encode()
    manifest2["files"]["results.json"] = hashlib.sha256(body2).hexdigest()
    with zipfile.ZipFile(listy, "w") as zf:
        zf.writestr("results.json", body2)
        zf.writestr("manifest.json", json.dumps(manifest2))

    reports = {r.file.name: r for r in merge_results(results, [flipped, truncated, forged, listy, good],
                                                     allow_unlisted=True)}
    for bad in (flipped, truncated, forged, listy):
        assert reports[bad.name].ok is False and reports[bad.name].message, bad.name
    assert "not a readable results file" in reports[truncated.name].message
    assert "layout" in reports[forged.name].message
    assert reports[good.name].ok and reports[good.name].participant == "R01"
    db = ResultsDB(results, design)
    assert db.participant("R99") is None and db.participant("R01") is not None
    db.close()


def test_design_file_name_never_reaches_the_participant(lab, tmp_path: Path) -> None:
    """Experimenters name files after their models; the participant's cache, results database and results
    file are named after the (validated) title instead, and a bundle named after a model is refused."""
    design_path, design, results = lab
    telling = design_path.with_name("synced_vs_static.toml")
    telling.write_text(design_path.read_text())
    with pytest.raises(InputError, match="names condition 'synced'"):
        make_bundle(telling, tmp_path / "synced-study.zip", results=results, participants=1)
    info = make_bundle(telling, tmp_path / "study.zip", results=results, participants=1)
    with zipfile.ZipFile(info.path) as zf:
        manifest = json.loads(zf.read("manifest.json"))
    assert "synced" not in json.dumps(manifest).lower() and "static" not in json.dumps(manifest).lower()
    results_file = _remote_run(info.path, tmp_path, "R01")
    seen = [results_file.name, *(p.name for p in (tmp_path / "cache").rglob("*"))]
    assert not [n for n in seen if "synced" in n.lower() or "static" in n.lower()], seen


def test_bundle_keeps_the_avatar_and_its_bone_map(tmp_path: Path) -> None:
    import shutil

    design_path = write_synthetic_study(tmp_path / "study", n_stimuli=4)
    robot = Path(__file__).resolve().parents[1] / "data" / "samples" / "avatars" / "RobotExpressive.glb"
    shutil.copy(robot, design_path.parent / "robot.glb")
    bone_map = {"Abdomen": "Spine", "Torso": "Chest", "UpperArm.L": "LeftUpperArm", "LowerArm.L": "LeftLowerArm",
                "Palm2.L": "LeftHand", "UpperArm.R": "RightUpperArm", "LowerArm.R": "RightLowerArm",
                "Palm2.R": "RightHand", "UpperLeg.L": "LeftUpperLeg", "LowerLeg.L": "LeftLowerLeg",
                "Foot.L": "LeftFoot", "UpperLeg.R": "RightUpperLeg", "LowerLeg.R": "RightLowerLeg",
                "Foot.R": "RightFoot"}
    table = "\n".join(f'"{k}" = "{v}"' for k, v in bone_map.items())
    design_path.write_text(design_path.read_text() + f'\n[avatar]\nmodel = "robot.glb"\n\n[avatar.bone_map]\n{table}\n')
    make_bundle(design_path, tmp_path / "out" / "study.zip", participants=1)
    opened = open_bundle(tmp_path / "out" / "study.zip", cache=tmp_path / "cache")
    remote = load_design(opened.design_path)
    assert remote.avatar_bone_map == bone_map
    assert Path(remote.avatar_for(remote.stimuli[0])).read_bytes() == robot.read_bytes()


def test_smpl_motion_on_the_labs_body_model_is_bundled_without_the_model_file(tmp_path: Path) -> None:
    """The SMPL-family licences do not allow passing the model file on: a condition that names one travels as
    its motion on that model's skeleton (BVH), which plays as the lab plays it."""
    from studyapp.motion.fk import joint_positions
    from studyapp.motion.smpl import builtin_rest_joints, parents
    from studyapp.resources import designs_dir
    from studyapp.study.stimuli import load_condition_motion

    # a synthetic SMPL-X model (the licensed one cannot be used in tests): one vertex per joint, a taller figure
    rest = builtin_rest_joints("smplx") * 1.2
    model = tmp_path / "models" / "SMPLX_TEST.npz"
    model.parent.mkdir()
    kin = np.stack([np.where(parents("smplx") < 0, 2**32 - 1, parents("smplx")), np.arange(55)]).astype(np.uint32)
    np.savez(model, J_regressor=np.eye(55), v_template=rest, shapedirs=np.zeros((55, 3, 10)), kintree_table=kin)
    text = (designs_dir() / "smplx_example.toml").read_text().replace('"demo/', f'"{designs_dir()}/demo/').replace(
        '"smplx_example/', f'"{designs_dir()}/smplx_example/').replace(
        '# body_model = "models/SMPLX_NEUTRAL.npz"', 'body_model = "models/SMPLX_TEST.npz"')
    source = tmp_path / "smplx.toml"
    source.write_text(text)
    lab_design = load_design(source)
    assert lab_design.conditions[0].body_model == "models/SMPLX_TEST.npz"
    info = make_bundle(source, tmp_path / "smpl.zip", results=tmp_path / "smpl.sqlite", participants=1)
    with zipfile.ZipFile(info.path) as zf:
        contents = [zf.read(n) for n in zf.namelist()]
    assert model.read_bytes() not in contents
    opened = open_bundle(info.path, cache=tmp_path / "cache")
    assert "body_model" not in opened.design_path.read_text()
    bundled = load_design(opened.design_path)
    assert all(c.motion.endswith(".bvh") for c in bundled.conditions)
    smpl = [m for m in shipped_motions(info.key, opened.design_path) if m.condition == "emage_like"]
    assert len(smpl) == len(bundled.stimuli)
    for m in smpl:
        lab_stim = lab_design.stimulus(m.stimulus)
        shipped = load_condition_motion(bundled, bundled.condition(m.token), bundled.stimulus(m.shipped_stimulus))
        lab = load_condition_motion(lab_design, lab_design.conditions[0], lab_stim)
        assert shipped.n_frames == lab.n_frames == 300
        order = [shipped.skeleton.names.index(n) for n in lab.skeleton.names]  # a BVH lists joints depth-first
        err = np.abs(joint_positions(shipped)[:, order] * shipped.skeleton.unit_scale - joint_positions(lab)).max()
        assert err < 1e-3, err
        # and it is the model's skeleton, not the built-in one: 1.2 times as tall
        arm = np.linalg.norm(lab.skeleton.offsets[18])
        assert abs(arm / np.linalg.norm(builtin_rest_joints("smplx")[18] - builtin_rest_joints("smplx")[16]) - 1.2) < 1e-9


def test_condition_labels_are_never_shipped(tmp_path: Path) -> None:
    """A label names a model for the experimenter's analysis: no byte of the bundle may carry it."""
    design_path = write_synthetic_study(tmp_path / "study", n_stimuli=2, seconds=CLIP_S)
    labels = {"synced": "Gesticulator v2", "lagged": "Baseline Lag", "static": "Frozen Pose"}
    text = design_path.read_text()
    for cid, label in labels.items():
        text = text.replace(f'id = "{cid}"\n', f'id = "{cid}"\nlabel = "{label}"\n', 1)
    design_path.write_text(text)
    assert [c.label for c in load_design(design_path).conditions] == list(labels.values())
    info = make_bundle(design_path, tmp_path / "out" / "study.zip", participants=1,
                       results=tmp_path / "study" / "r.sqlite")
    zf = zipfile.ZipFile(info.path)
    for name in zf.namelist():
        data = zf.read(name).lower()
        for label in labels.values():
            assert label.lower().encode() not in data, (name, label)
    shipped = load_design(open_bundle(info.path, cache=tmp_path / "cache").design_path)
    assert [c.label for c in shipped.conditions] == [None, None, None]
    assert all(re.fullmatch(r"x[0-9]+", c.shown_as) for c in shipped.conditions)  # neutral tokens
