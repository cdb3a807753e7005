"""``studyapp run | export | bundle | key | merge``: running sessions and moving their results around."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any, Callable

from studyapp.bots import POLICIES, run_bot
from studyapp.errors import InputError, StudyappError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "run",
        help="run (or resume) one participant's session: a window, or a scripted bot",
        description="Run one participant through a study design (.toml) or a remote study bundle (.zip). "
        "Starting a participant again resumes at the first unanswered clip with the same order.",
    )
    p.add_argument("design", type=Path, help="study design (.toml) or study bundle (.zip)")
    p.add_argument("--participant", required=True, help="participant id (e.g. P01)")
    p.add_argument("--results", type=_results_arg, help="results database: a file, or postgresql://USER@HOST/DB "
                   "(default: <design>.results.sqlite next to the "
                   "design; for a bundle, in your user data folder)")
    p.add_argument("--row", type=int, help="Latin-square row for a new participant (default: the least used row)")
    p.add_argument("--group", action="append", default=[], metavar="KEY=VALUE",
                   help="participant group stored with the answers, e.g. --group device=vr (repeatable)")
    p.add_argument("--allow-rerun", action="store_true",
                   help="let a participant who finished run again (recorded as <id>-rerun<k>)")
    p.add_argument("--fullscreen", action="store_true", help="open the participant window full screen")
    p.add_argument("--audio-device", metavar="INDEX|NAME",
                   help="audio output for the window (index or part of the name; `studyapp doctor` lists them)")
    p.add_argument("--offscreen", action="store_true", help="no window: a scripted participant through the real UI")
    p.add_argument("--bot", choices=POLICIES, help="scripted participant policy (with --offscreen or --no-render)")
    p.add_argument("--seed", type=int, default=0, help="seed of the scripted participant")
    p.add_argument("--no-render", action="store_true", help="bot at the session level, no rendering (fast)")
    p.add_argument("--bot-pace", type=float, default=0.0, metavar="SECONDS",
                   help="with --no-render: seconds a bot 'watches' each clip (default 0)")
    p.set_defaults(func=_cmd_run)

    e = sub.add_parser(
        "export",
        help="export a results database as a tidy CSV (one row per rank)",
        description="Export a results database (.sqlite) as CSV for analysis: --csv writes one row per "
        "participant x trial x criterion x condition with its rank (and the criterion's and condition's labels, "
        "the design order, the study title and the participant's rated questionnaire answers, so "
        "results-analysis gives the same report from the CSV as from the database), --questionnaire-csv one row per participant "
        "x questionnaire item; with neither, the long table is printed to stdout. Practice trials are kept and flagged "
        "unless --exclude-practice.",
    )
    e.add_argument("db", type=_results_arg, help="results database (.sqlite, or postgresql://USER@HOST/DB)")
    e.add_argument("--csv", type=Path, help="long table: participant x trial x criterion x condition")
    e.add_argument("--questionnaire-csv", type=Path, help="questionnaire answers, one row per participant x item")
    e.add_argument("--exclude-practice", action="store_true",
                   help="leave practice trials out (by default they are kept and flagged in is_practice)")
    e.add_argument("--design", type=Path, metavar="STUDY.toml",
                   help="the study's design: records its labels in the database first, for a database that has "
                   "none (made before schema 7: criteria named by their ids); it must be the design the database "
                   "was made for")
    e.set_defaults(func=_cmd_export)

    b = sub.add_parser(
        "bundle",
        help="pack a study into one zip for remote participants (opaque file names)",
        description="Pack a study design and every file it uses into one zip (-o STUDY.zip) that remote "
        "participants run with `studyapp run STUDY.zip`. Inside it, condition ids, stimulus ids and file names "
        "are opaque; the key mapping them back is kept in the experimenter's results database only (for "
        "`studyapp merge`), never written next to the zip unless asked for with --export-key.",
    )
    b.add_argument("design", type=Path, help="study design (.toml)")
    b.add_argument("-o", "--output", type=Path, required=True, help="bundle to write (STUDY.zip)")
    b.add_argument("--participants", type=int, required=True,
                   help="make the bundle for N remote participants, ids R01..RN, on the Latin-square rows the "
                   "experimenter's database has used least; the bundle carries each one's trials")
    b.add_argument("--results", type=Path, help="the experimenter's results database, which keeps the bundle's key "
                   "(default: <design>.results.sqlite next to the design)")
    b.add_argument("--export-key", type=Path, metavar="FILE",
                   help="also write the key to FILE (for `merge --key` on another machine); keep it private, "
                   "never send it with the bundle")
    b.add_argument("--upload-url", metavar="URL",
                   help="the study server (`studyapp serve` with --db the --results database) participants upload "
                   "their answers to as they are committed, e.g. https://study.example.org (the results zip is "
                   "still written as the fallback)")
    b.set_defaults(func=_cmd_bundle)

    k = sub.add_parser(
        "key",
        help="export a bundle's key from the experimenter's results database (for merging elsewhere)",
        description="Write the key of a bundle (opaque ids -> real conditions, stimuli and files), which "
        "`studyapp bundle` keeps in the experimenter's results database, to a file for `merge --key` on another "
        "machine. Keep the file private: with it, anyone can tell the models apart in the bundle.",
    )
    k.add_argument("db", type=Path, help="the experimenter's results database")
    k.add_argument("bundle", help="the bundle (STUDY.zip) or the first digits of its hash")
    k.add_argument("-o", "--output", type=Path, required=True, help="key file to write (e.g. STUDY.key.json)")
    k.set_defaults(func=_cmd_key)

    m = sub.add_parser(
        "merge",
        help="import remote participants' results files into the experimenter's database",
        description="Import the results files (results-*.zip) that remote participants send back into the "
        "experimenter's results database, mapping the bundle's opaque ids back to the real ones. Before anything "
        "is imported, every answer is checked against the roster, the schedule recomputed from the design, the "
        "ranking rules, plausible timings and every other participant's answers (copies); a file with any problem "
        "imports nothing and each problem is one line. Damaged files and results of another design are refused "
        "too; a file merged before is reported as already merged. The exit status is 1 when any file was refused.",
    )
    m.add_argument("db", type=_results_arg, help="the experimenter's results database (a file, or "
                   "postgresql://USER@HOST/DB)")
    m.add_argument("files", type=Path, nargs="+", help="results-*.zip files sent back by participants")
    m.add_argument("--key", type=Path, help="a bundle key file (from `bundle --export-key` or `studyapp key`) "
                   "when the database does not hold it")
    m.add_argument("--design", type=Path, help="the study design the database was made for (default: NAME.toml "
                   "next to NAME.results.sqlite); every answer is checked against its schedule")
    m.add_argument("--allow-unlisted", action="store_true",
                   help="accept participant ids that are not on the bundle's roster (bundles made before bundles "
                   "carried each participant's trials, whose participants could choose their own ids)")
    m.set_defaults(func=_cmd_merge)


def _results_arg(text: str) -> Path | str:
    """A results database on the command line: a path, ``sqlite:///path`` or a ``postgresql://`` URL."""
    from studyapp.study.sql_backend import results_target

    return results_target(text)


def default_results_path(design_path: Path) -> Path:
    """``<design stem>.results.sqlite`` next to the design."""
    return design_path.with_name(f"{design_path.stem}.results.sqlite")


def parse_groups(items: list[str]) -> dict[str, str]:
    groups = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise InputError(None, "--group", f"{item!r} is not KEY=VALUE (e.g. --group device=vr)")
        groups[key.strip()] = value.strip()
    return groups


def load_design_for_run(design_path: Path, results: Path | str) -> Any:
    """The design, fully validated (every stimulus file read and checked) before its first session, or found
    recorded as validated with exactly the same files.

    Later sessions on the same results database skip re-reading the files: the design hash, which covers
    the bytes of every referenced file, must equal the one stored with the database, so the files are
    exactly those validated when the database was created. Resuming after a crash then takes a moment,
    not a full validation.
    """
    from studyapp.study.design import load_design

    if isinstance(results, Path) and results.exists() and results.stat().st_size > 0:
        return load_design(design_path, check_files=False)  # ResultsDB compares the hash
    # A design validated before (`studyapp validate`) with exactly these files is not read again
    # (studyapp.study.design.validated); any changed file means a full check here.
    return load_design(design_path, reuse_check=True)


def _print_saved(plan: Any) -> None:
    # Printed only after the commit returned, so the kill tests may hold the database to it.
    print(f"saved trial {plan.trial_index}", flush=True)


def _cmd_run(args: argparse.Namespace) -> int:
    audio = _start_audio(args)
    try:
        return _run_session(args, audio)
    finally:
        if audio is not None:  # closed on every way out (also before the window opened): no process left
            audio.close()


def _start_audio(args: argparse.Namespace) -> Any:
    """For a window session: the audio output, opening in its own process while the design, the database and
    the first trial load (:class:`~studyapp.audio.playback.PendingClock`; it takes ~0.7 s, all of it on the way
    to the participant's first frame otherwise). None for the scripted and offscreen modes, which play no sound."""
    import os

    if args.no_render or args.offscreen or args.bot:
        return None
    from studyapp.cli.demo import display_available

    if not display_available():
        return None  # _run_mode says so
    from studyapp.audio.playback import PendingClock

    device = args.audio_device or os.environ.get("STUDYAPP_AUDIO_DEVICE") or None
    if device is not None and device.isdigit():
        device = int(device)
    return PendingClock(device)


def _run_session(args: argparse.Namespace, audio: Any = None) -> int:
    from studyapp.study.session import ParticipantFinishedError, prepare_participant
    from studyapp.study.storage import ResultsDB

    opened = None
    if args.design.suffix.lower() == ".zip":
        from studyapp.study.bundle import open_bundle

        opened = open_bundle(args.design)
        design_path = opened.design_path
        results = args.results or opened.default_results
    else:
        design_path = args.design
        results = args.results or default_results_path(args.design)
    if args.no_render or args.offscreen:
        if not args.bot:
            raise StudyappError("--no-render and --offscreen need a scripted participant: add --bot random|ordered|careful")
    elif args.bot:
        raise StudyappError("--bot needs a mode: --offscreen (through the real UI, rendered offscreen) or "
                            "--no-render (session only, fast)")
    design = load_design_for_run(design_path, results)
    # a server database (postgresql://) is never deleted here, only the participant this run registered
    new_db = isinstance(results, Path) and not (results.exists() and results.stat().st_size > 0)
    db = ResultsDB(results, design)
    print(f"Results database: {db.path}", flush=True)  # a URL without its password
    finished_files: list[Path] = []
    known = {p.id for p in db.participants()}
    schedule: dict[str, Any] = {}
    try:
        row = args.row
        groups = parse_groups(args.group)
        if opened is not None:
            from studyapp.study.bundle import remote_plan, remote_row, write_results_file

            carried = remote_plan(opened, args.participant)
            if carried is not None:
                # the bundle carries this participant's trials (blinded: see studyapp.study.shipped)
                if row is not None and row != carried.row:
                    raise InputError(None, "--row", f"participant {args.participant!r} follows row {carried.row} "
                                     "in this study file; drop --row")
                row = carried.row
                schedule = {"plans": carried.plans, "n_rows": carried.n_rows}
            elif row is None:
                row = remote_row(design, opened, args.participant)
            groups.setdefault("remote", "yes")
            out_dir = opened.results_dir

            def pack(pid: str) -> Path:
                path = write_results_file(db, pid, out_dir, opened)
                finished_files.append(path)
                return path

            db.on_participant_finished = pack
        uploader = None
        if opened is not None and opened.upload is not None:
            from studyapp.study.upload import Uploader

            # its own read-only connection; it sends each answer once committed, off the session's thread, and
            # at once what an earlier run could not send
            uploader = Uploader(results, opened.bundle_hash, opened.study, args.participant, opened.upload["url"],
                                opened.upload["secret"])
            uploader.start()
        try:
            rec = prepare_participant(design, db, args.participant, row=row, groups=groups,
                                      allow_rerun=args.allow_rerun, n_rows=schedule.get("n_rows"))
        except ParticipantFinishedError:
            if uploader is None:
                raise
            from studyapp.study.upload import final_message

            outcome = uploader.finish()   # a finished participant's run only sends what is missing
            print(f"Participant {args.participant} already finished this study. {final_message(outcome)}")
            return 0 if outcome.all_sent else 1
        if rec.id != args.participant:
            print(f"Participant {args.participant} already finished; this run is recorded as {rec.id}.", flush=True)
        try:
            code = _run_mode(args, design, db, rec.id, schedule, uploader, audio)
        except BaseException:
            if uploader is not None:
                uploader.finish(0)
            _forget_unstarted(db, results, rec.id, known, new_db)
            raise
        final = db.participant(rec.id)
        checks = [t["attention_passed"] for t in db.trials(rec.id) if t["is_attention_check"]]
    finally:
        db.close()
    # For the experimenter at a lab PC; a remote participant is not told how their checks went.
    summary = "" if opened is not None or not checks else \
        f" Attention checks passed: {sum(1 for c in checks if c)} of {len(checks)}."
    if final is not None and final.status == "ended_early":
        from studyapp.study.session import ENDED_EARLY_MESSAGE

        print(ENDED_EARLY_MESSAGE + summary)
    elif final is not None and final.status == "done":
        print(f"Participant {rec.id} completed the study.{summary}")
    if uploader is not None:
        from studyapp.study.upload import final_message

        outcome = uploader.finish()
        print(final_message(outcome), flush=True)
        for f in finished_files:
            print(f"Your results file: {f}" + ("" if outcome.all_sent else "\nPlease send this file to the experimenter."))
        return code
    for f in finished_files:
        print(f"Your results file: {f}\nPlease send this file to the experimenter.")
    return code


def _forget_unstarted(db: Any, results: Path, pid: str, known: set[str], new_db: bool) -> None:
    """A session that failed before its first answer leaves no trace: a participant registered by this run
    is removed (they can start once the design is fixed), and a database this run created and left empty is
    deleted (a fixed design has another hash, which that database would refuse)."""
    if pid in known or not db.discard_unstarted(pid):
        return
    if new_db and not db.participants():
        db.close()
        for suffix in ("", "-wal", "-shm"):
            Path(f"{results}{suffix}").unlink(missing_ok=True)


def _run_mode(args: argparse.Namespace, design: Any, db: Any, pid: str, schedule: dict[str, Any],
              uploader: Any = None, audio: Any = None) -> int:
    """Run the session; ``schedule``: ``plans`` and ``n_rows`` a bundle carries for its participant (or empty);
    ``uploader``: the bundle run's :class:`~studyapp.study.upload.Uploader` (its state on the window's final screen);
    ``audio``: the window's audio output, already opening (:func:`_start_audio`)."""
    if args.no_render or args.offscreen:
        # the offscreen participant shows its progress on screen (its PNGs), not as "saved trial" lines
        return run_bot(design, db, pid, args.bot, args.seed, render=args.offscreen,
                       on_trial=None if args.offscreen else _print_saved, pace_s=args.bot_pace, **schedule)
    from studyapp.cli.demo import display_available

    if not display_available():
        raise StudyappError("no display found to open the participant window; run on a desktop, or use "
                            "--offscreen --bot careful for a scripted check")
    from studyapp.ui.app import run_window

    device = args.audio_device
    if device is not None and device.isdigit():
        device = int(device)
    status = None if uploader is None else _upload_line(uploader)
    return int(run_window(design, db, pid, fullscreen=args.fullscreen, audio_device=device, upload_status=status,
                          audio=audio, **schedule) or 0)


def _upload_line(uploader: Any) -> Callable[[], str]:
    """The window's final-screen line on the uploads, as it stands when drawn."""
    from studyapp.study.upload import final_message

    return lambda: final_message(uploader.outcome())


def _cmd_export(args: argparse.Namespace) -> int:
    from studyapp.study.storage import ResultsDB

    with ResultsDB(args.db, create=False) as db:  # opened once: opening checks every row's checksum
        return _export(args, db)


def _export(args: argparse.Namespace, db: Any) -> int:
    from studyapp.study.export import criteria_unlabelled, export_dataframe, questionnaire_dataframe, record_design

    if args.design is not None:
        record_design(db, args.design)

    def table() -> Any:
        df = export_dataframe(db, include_practice=not args.exclude_practice)
        if len(df) and args.design is None and criteria_unlabelled(db):  # on stderr: stdout may be the CSV
            print("note: the database records no criterion labels (made before schema 7), so the export names "
                  "criteria by their ids; add --design STUDY.toml to record the design's labels", file=sys.stderr)
        return df

    if not args.csv and not args.questionnaire_csv:
        # no output named: the long table goes to stdout (for a pipe or a quick look); nothing else is printed
        table().to_csv(sys.stdout, index=False)
        return 0
    if args.csv:
        df = table()
        args.csv.parent.mkdir(parents=True, exist_ok=True)
        df.to_csv(args.csv, index=False)
        n_part = df["participant"].nunique() if len(df) else 0
        print(f"Wrote {len(df)} row{'s' * (len(df) != 1)} ({n_part} participant{'s' * (n_part != 1)}) to {args.csv}")
    if args.questionnaire_csv:
        q = questionnaire_dataframe(db)
        args.questionnaire_csv.parent.mkdir(parents=True, exist_ok=True)
        q.to_csv(args.questionnaire_csv, index=False)
        print(f"Wrote {len(q)} questionnaire answers to {args.questionnaire_csv}")
    return 0


def _cmd_bundle(args: argparse.Namespace) -> int:
    from studyapp.study.bundle import make_bundle

    results = args.results or default_results_path(args.design)
    info = make_bundle(args.design, args.output, participants=args.participants, results=results,
                       export_key=args.export_key, upload_url=args.upload_url)
    print(f"Wrote {info.path} ({info.n_files} files: {info.n_media} media files, study.toml, schedule.json and "
          f"manifest.json; {info.size_bytes / 1e6:.1f} MB)")
    print(f"The key (opaque ids -> conditions and files) is kept in {results}, so `studyapp merge` can map "
          "results back; it is not written next to the zip.")
    if info.key_path is not None:
        print(f"Key also written to {info.key_path}: keep it private, never send it with the bundle.")
    if args.upload_url:
        print(f"Participants upload their answers to {args.upload_url.rstrip('/')}/upload as they go; serve the study "
              f"with `studyapp serve {args.design} --db {results}` there.")
    if info.roster:
        print("Remote participant ids and their rows: " + ", ".join(f"{k} (row {v})" for k, v in info.roster.items()))
    if info.small_seed:
        print("Note: the design's seed is small. With random ordering or slots the schedule is drawn from the seed, so "
              "someone holding the bundle could try every small seed to tell the models apart; set `seed` to a large "
              "random number (python -c \"import secrets; print(secrets.randbits(62))\") before the first participant.")
    return 0


def _cmd_key(args: argparse.Namespace) -> int:
    from studyapp.study.bundle import export_key

    path = export_key(args.db, args.bundle, args.output)
    print(f"Wrote the bundle key to {path}: keep it private, never send it with the bundle.")
    return 0


def _cmd_merge(args: argparse.Namespace) -> int:
    from studyapp.study.bundle import merge_results

    reports = merge_results(args.db, args.files, key_file=args.key, design=args.design,
                            allow_unlisted=args.allow_unlisted)
    for r in reports:
        # an already-merged file's message says so itself
        print(("" if r.already else "imported: " if r.ok else "REFUSED: ") + f"{r.file}: {r.message}")
        for problem in r.problems:  # one line per problem: the file, the place in it, what is wrong
            print(f"  {r.file}: {problem}")
    bad = sum(not r.ok for r in reports)
    already = sum(r.already for r in reports)
    imported = len(reports) - bad - already
    print(f"{imported} of {len(reports)} file(s) imported into {args.db}"
          + (f", {already} already merged" if already else "") + (f", {bad} refused" if bad else ""))
    return 1 if bad else 0
