"""Mutation fuzzer of every reader, through the command line a user runs (issue 16, item 4).

``python -m tests.hardening.fuzz --cases N [--seed S] [--jobs 2] [--readers bvh,npz] [--samples DIR]``

Case ``i`` of seed ``S`` is fixed by ``(S, i)`` alone: its reader is ``READERS[i % len(READERS)]``, and a
:class:`random.Random` seeded with ``"S/i"`` picks the seed file, one to three mutations
(:mod:`tests.hardening.mutations`) and the command. ``--case I`` re-runs one case in the foreground, prints
its command and output and keeps its files (``--keep DIR``), so a failure reported by a big run is
reproduced by ``python -m tests.hardening.fuzz --seed S --case I``.

Seed files: the real samples (``tests/data/samples``: BVH, face CSV/JSON, the BEAT2 SMPL-X NPZ, GLB/VRM
avatars and a .gltf made from one), the demo study (its WAVs, face CSVs, BVHs and the ``demo.toml`` and
``smplx_example.toml`` designs with their SMPL-X/SMPL-H NPZs), face and rotation NPY arrays, an NPZ written
by ``studyapp convert`` and a results database written by a scripted participant (``studyapp run --bot``).

Each case runs in its own forked process (the parent has imported studyapp, so a case starts in
milliseconds), in its own folder, under ``RLIMIT_AS`` (``--mem-mb``, 1536 by default) and a time cap
(``--timeout`` CPU seconds, and four times that in wall-clock time, since a shared machine may keep a
case waiting), calling ``studyapp.cli.main`` with the argument list a user types. Outcome:

* ``ok``: exit status 0;
* ``error``: exit status not 0 and no traceback (the one-line messages of ``InputError``);
* ``traceback``: an exception escaped the command;
* ``blowup``: ``MemoryError`` / "Unable to allocate" / "Cannot allocate memory": the cap was hit;
* ``hang``: still running at the time cap (killed);
* ``crash``: the process died of a signal (segfault, abort).

The run prints a table of counts per reader and, for every case that is not ``ok`` or ``error``, its
reproducer; the exit status is 1 when there is any. ``tests/hardening/test_fuzz.py`` runs a small size in CI.
"""
from __future__ import annotations

import argparse
import json
import os
import random
import resource
import shutil
import signal
import sys
import tempfile
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path

# one BLAS thread: the children run two at a time on small inputs, and a BLAS pool would reserve address space
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

if __package__ in (None, ""):  # `python tests/hardening/fuzz.py`
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
    from tests.hardening import mutations  # type: ignore[no-redef]
else:
    from . import mutations

REPO = Path(__file__).resolve().parents[2]
READERS = mutations.READERS
OUTCOMES = ("ok", "error", "traceback", "blowup", "hang", "crash")
FAILURES = frozenset({"traceback", "blowup", "hang", "crash"})
IN = "{in}"  # placeholder of the mutated file in a command


@dataclass(frozen=True)
class Seed:
    """One file to mutate, the reader it exercises and the commands that read it."""

    reader: str
    path: Path
    commands: tuple[tuple[str, ...], ...]
    ext: str
    context: str = ""  # "design:<toml>": the case folder is a copy of that design's folder (see _prepare)


@dataclass
class Case:
    seed: int
    index: int
    reader: str
    source: Path
    mutations: list[str]
    argv: list[str]
    outcome: str = ""
    detail: str = ""
    seconds: float = 0.0
    max_rss_mb: float = 0.0
    folder: Path | None = field(default=None, repr=False)

    def reproducer(self) -> str:
        return f"python -m tests.hardening.fuzz --seed {self.seed} --case {self.index}"


# --- seed corpus -----------------------------------------------------------------------------------

_INSPECT = (("inspect", IN), ("inspect", IN, "--json"))


def _sh(argv: list[str], cwd: Path) -> None:
    import subprocess

    subprocess.run([sys.executable, "-m", "studyapp.cli", *argv], cwd=cwd, check=True, capture_output=True,
                   env={**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")})


def build_corpus(samples: Path, work: Path) -> dict[str, list[Seed]]:
    """The seed files of every reader (made under ``work`` where they are generated)."""
    import numpy as np

    demo = REPO / "study_designs" / "demo"
    seeds: dict[str, list[Seed]] = {r: [] for r in READERS}
    design_face = ("validate", "design.toml")

    bvhs = sorted(samples.glob("*.bvh")) + sorted((samples / "motion").glob("*.bvh")) + [demo / "motion/synced/clip01.bvh"]
    for p in bvhs:
        seeds["bvh"].append(Seed("bvh", p, _INSPECT + (("convert", IN, "out.bvh", "--order", "ZXY", "--fps", "30"),
                                                        ("convert", IN, "out.npz"), design_face), ".bvh", "slot:bvh"))
    for p in sorted(samples.glob("*.csv")) + [demo / "face/clip01.csv"]:
        seeds["face_csv"].append(Seed("face_csv", p, _INSPECT + (design_face,), ".csv", "slot:face"))
    for p in sorted(samples.glob("*.json")):
        seeds["face_json"].append(Seed("face_json", p, _INSPECT + (design_face,), ".json", "slot:face"))
    for p in sorted(demo.glob("audio/*.wav"))[:2]:
        seeds["wav"].append(Seed("wav", p, _INSPECT + (design_face,), ".wav", "slot:audio"))

    work.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(16)
    face = work / "face52.npy"
    np.save(face, rng.random((45, 52)).astype(np.float32))
    seeds["npy"].append(Seed("npy", face, (("inspect", IN, "--fps", "30"), ("inspect", IN)), ".npy"))
    rot = work / "rot_beat75_axis_angle.npy"
    np.save(rot, (rng.standard_normal((20, 75 * 3)) * 0.2).astype(np.float32))
    seeds["npy"].append(Seed("npy", rot, (
        ("inspect", IN),
        ("convert", IN, "out.bvh", "--template", "beat", "--representation", "axis_angle", "--in-fps", "15"))
        , ".npy"))

    npz_cmds = (("inspect", IN), ("convert", IN, "out.bvh"), ("convert", IN, "out.bvh", "--fps", "15"))
    written = work / "app_written.npz"
    _sh(["convert", str(demo / "motion/synced/clip02.bvh"), str(written)], work)
    npzs = sorted((samples / "motion").glob("*.npz")) + sorted((REPO / "study_designs/smplx_example").glob("*/clip01.npz"))
    for p in npzs + [written]:
        cmds = npz_cmds + ((("convert", IN, "out.csv"),) if "smplx" in str(p) else ())
        seeds["npz"].append(Seed("npz", p, cmds, ".npz"))

    avatar_cmds = _INSPECT + (("convert", str(demo / "motion/synced/clip03.bvh"), "out.bvh", "--avatar", IN),)
    for p in sorted((samples / "avatars").glob("*.glb")):
        if "gltfpack" not in p.name:  # meshopt-compressed copies: the same JSON, slower to load
            seeds["glb"].append(Seed("glb", p, avatar_cmds, ".glb"))
    for p in sorted((samples / "avatars").glob("*.vrm")):
        seeds["vrm"].append(Seed("vrm", p, avatar_cmds, ".vrm"))
    for name in ("Fox.glb", "CesiumMan.glb"):
        src = samples / "avatars" / name
        if src.exists():
            out = work / (src.stem + ".gltf")
            out.write_bytes(mutations.glb_to_gltf(src.read_bytes()))
            seeds["gltf"].append(Seed("gltf", out, avatar_cmds, ".gltf"))

    design_cmds = (("validate", IN), ("validate", IN, "--quick"), ("schedule", IN, "-n", "3"))
    for name in ("demo.toml", "smplx_example.toml"):
        seeds["toml"].append(Seed("toml", REPO / "study_designs" / name, design_cmds, ".toml", "design"))

    db = work / "results.sqlite"
    db.unlink(missing_ok=True)
    _sh(["run", str(REPO / "study_designs/demo.toml"), "--participant", "P01", "--no-render", "--bot", "careful",
         "--results", str(db)], work)
    seeds["sqlite"].append(Seed("sqlite", db, (("export", IN, "--csv", "out.csv"), ("export", IN)), ".sqlite"))
    missing = [r for r, s in seeds.items() if not s]
    if missing:
        raise SystemExit(f"no seed files for {', '.join(missing)} under {samples}")
    return seeds


# --- cases -----------------------------------------------------------------------------------------


def make_case(seed: int, index: int, corpus: dict[str, list[Seed]]) -> tuple[Case, Seed, bytes]:
    """Case ``index`` of ``seed``: the same pair always gives the same mutated bytes and command."""
    reader = READERS[index % len(READERS)]
    rng = random.Random(f"{seed}/{index}")
    s = rng.choice(corpus[reader])
    data, names = mutations.mutate(rng, reader, s.path.read_bytes())
    argv = list(rng.choice(s.commands))
    return Case(seed, index, reader, s.path, names, argv), s, data


def _prepare(case: Case, s: Seed, data: bytes, folder: Path) -> list[str]:
    """Write the case's files into ``folder``; the argument list with the mutated file's name filled in."""
    folder.mkdir(parents=True)
    name = "fuzzed" + s.ext
    if s.context == "design" or (s.context.startswith("slot:") and "design.toml" in case.argv):
        for sub in ("demo", "smplx_example"):
            os.symlink(REPO / "study_designs" / sub, folder / sub)
    if s.context == "design":
        name = "design.toml"
    elif s.context.startswith("slot:") and "design.toml" in case.argv:
        # the demo design cut to two clips, clip01's file of this kind replaced by the mutated one
        text = _two_clip_demo()
        slot = s.context[5:]
        if slot == "bvh":
            (folder / "m").mkdir()
            for k in (2, 3, 4):
                os.symlink(REPO / f"study_designs/demo/motion/synced/clip0{k}.bvh", folder / f"m/clip0{k}.bvh")
            name = "m/clip01.bvh"
            text = text.replace('"demo/motion/synced/{stimulus}.bvh"', '"m/{stimulus}.bvh"')
        else:
            old = {"face": '"demo/face/clip01.csv"', "audio": '"demo/audio/clip01.wav"'}[slot]
            text = text.replace(old, f'"{name}"')
        (folder / "design.toml").write_text(text, encoding="utf-8")
    (folder / name).write_bytes(data)
    return [name if a == IN else a for a in case.argv]


def _two_clip_demo() -> str:
    """``demo.toml`` without clip03, clip04 and the attention check (on clip03): ``validate`` opens half the files."""
    text = (REPO / "study_designs/demo.toml").read_text(encoding="utf-8")
    blocks = text.split("\n[")
    keep = [b for b in blocks if not ('id = "clip03"' in b or 'id = "clip04"' in b or b.startswith("[attention_checks]"))]
    return "\n[".join(keep)


#: Wall-clock cap as a multiple of the CPU-time cap: on a shared, loaded machine a case may wait for a core.
WALL_FACTOR = 4


def _child(argv: list[str], folder: Path, mem_mb: int, cpu_s: float) -> None:
    """Runs in the forked process: caps, redirections, the command; never returns."""
    code = 70
    try:
        os.chdir(folder)
        resource.setrlimit(resource.RLIMIT_AS, (mem_mb << 20, mem_mb << 20))
        # CPU seconds, not wall seconds, decide a hang: SIGXCPU ends a case that computes past the cap
        resource.setrlimit(resource.RLIMIT_CPU, (int(cpu_s), int(cpu_s) + 5))
        resource.setrlimit(resource.RLIMIT_FSIZE, (256 << 20, 256 << 20))
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # an oversized output is an OSError, not a kill
        out = os.open("stdout.txt", os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        err = os.open("stderr.txt", os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        os.dup2(out, 1)
        os.dup2(err, 2)
        from studyapp.cli import main

        try:
            code = main(argv)
        except SystemExit as exc:  # argparse
            code = exc.code if isinstance(exc.code, int) else 1
        except BaseException:  # noqa: BLE001 - what escapes the command is what the fuzzer measures
            traceback.print_exc()
            code = 71
    finally:
        try:
            sys.stdout.flush()
            sys.stderr.flush()
        except BaseException:  # noqa: BLE001
            pass
        os._exit(code if isinstance(code, int) and 0 <= code < 256 else 1)


_BLOWUP_MARKS = ("MemoryError", "Unable to allocate", "Cannot allocate memory", "std::bad_alloc", "out of memory")


def classify(status: int | None, stderr: str) -> str:
    """Outcome of a finished child from its wait status (``None``: killed at the time cap) and its stderr."""
    if status is None or (os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGXCPU):
        return "hang"
    if any(m in stderr for m in _BLOWUP_MARKS):
        return "blowup"
    if os.WIFSIGNALED(status):
        return "crash"
    if "Traceback (most recent call last)" in stderr:
        return "traceback"
    return "ok" if os.waitstatus_to_exitcode(status) == 0 else "error"


def _detail(folder: Path) -> str:
    err = (folder / "stderr.txt").read_text(errors="replace") if (folder / "stderr.txt").exists() else ""
    lines = [ln for ln in err.splitlines() if ln.strip()]
    return lines[-1][:300] if lines else ""


def run_cases(seed: int, indices: list[int], corpus: dict[str, list[Seed]], work: Path, jobs: int, timeout: float,
              mem_mb: int, keep: bool = False, progress: bool = False) -> list[Case]:
    """Run every case in its own forked child, at most ``jobs`` at a time (each case's file is made just
    before it runs, so a long run holds one file per job in memory)."""
    pending = list(indices)
    running: dict[int, tuple[Case, float]] = {}
    done: list[Case] = []
    while pending or running:
        while pending and len(running) < jobs:
            case, s, data = make_case(seed, pending.pop(0), corpus)
            case.folder = work / f"case-{case.seed}-{case.index}"
            if case.folder.exists():
                shutil.rmtree(case.folder)
            argv = _prepare(case, s, data, case.folder)
            case.argv = argv
            del data
            sys.stdout.flush()
            sys.stderr.flush()
            pid = os.fork()
            if pid == 0:
                _child(argv, case.folder, mem_mb, timeout)
            running[pid] = (case, time.monotonic())
        pid, status, usage = os.wait4(-1, os.WNOHANG)
        now = time.monotonic()
        finished: list[tuple[int, int | None, float]] = []
        if pid:
            finished.append((pid, status, usage.ru_maxrss / 1024))
        for p, (case, t0) in list(running.items()):
            if p != pid and now - t0 > timeout * WALL_FACTOR:
                os.kill(p, signal.SIGKILL)
                _, _, usage = os.wait4(p, 0)
                finished.append((p, None, usage.ru_maxrss / 1024))
        for p, st, rss in finished:
            case, t0 = running.pop(p)
            case.seconds = now - t0
            case.max_rss_mb = rss
            err = (case.folder / "stderr.txt").read_text(errors="replace") if (case.folder / "stderr.txt").exists() else ""
            case.outcome = classify(st, err)
            case.detail = (f"killed after {timeout * WALL_FACTOR:.0f} s of wall time" if st is None else
                           f"past {timeout:.0f} s of CPU time" if case.outcome == "hang" else _detail(case.folder))
            if not keep:
                shutil.rmtree(case.folder, ignore_errors=True)
            done.append(case)
            if progress and len(done) % 100 == 0:
                bad = sum(c.outcome in FAILURES for c in done)
                print(f"{len(done)} of {len(indices)} cases, {bad} failing", file=sys.stderr, flush=True)
        if not finished:
            time.sleep(0.005)
    done.sort(key=lambda c: c.index)
    return done


# --- report ----------------------------------------------------------------------------------------


def counts(done: list[Case]) -> dict[str, dict[str, int]]:
    table = {r: {o: 0 for o in OUTCOMES} for r in READERS}
    for c in done:
        table[c.reader][c.outcome] += 1
    return {r: row for r, row in table.items() if sum(row.values())}


def report(done: list[Case], elapsed: float, seed: int) -> str:
    table = counts(done)
    lines = [f"{len(done)} cases, seed {seed}, {elapsed:.0f} s", "",
             f"{'reader':<10}{'cases':>7}" + "".join(f"{o:>11}" for o in OUTCOMES)]
    total = {o: 0 for o in OUTCOMES}
    for r, row in table.items():
        lines.append(f"{r:<10}{sum(row.values()):>7}" + "".join(f"{row[o]:>11}" for o in OUTCOMES))
        for o in OUTCOMES:
            total[o] += row[o]
    lines.append(f"{'all':<10}{len(done):>7}" + "".join(f"{total[o]:>11}" for o in OUTCOMES))
    bad = [c for c in done if c.outcome in FAILURES]
    if bad:
        lines += ["", f"{len(bad)} failing cases (re-run one with the command shown):"]
        for c in bad:
            lines.append(f"  [{c.outcome}] {c.reader} case {c.index}: {c.source.name} + {'+'.join(c.mutations)}: "
                         f"studyapp {' '.join(c.argv)}")
            lines.append(f"      {c.detail}")
            lines.append(f"      {c.reproducer()}")
    slow = max(done, key=lambda c: c.seconds, default=None)
    if slow is not None:
        lines.append(f"\nslowest case: {slow.index} ({slow.reader}, {slow.seconds:.1f} s); "
                     f"largest resident memory: {max(c.max_rss_mb for c in done):.0f} MB")
    return "\n".join(lines)


def _warm_up() -> None:
    """Import what the commands import, once, so that every forked child starts with it loaded."""
    import studyapp.audio.wav  # noqa: F401
    import studyapp.cli  # noqa: F401
    import studyapp.face.io  # noqa: F401
    import studyapp.motion.io  # noqa: F401
    import studyapp.render.avatar_report  # noqa: F401
    import studyapp.study.design  # noqa: F401
    import studyapp.study.storage  # noqa: F401
    import studyapp.study.stimuli  # noqa: F401
    import studyapp.study.export  # noqa: F401
    import studyapp.study.schedule  # noqa: F401
    import studyapp.render.scene  # noqa: F401
    import studyapp.render.pose  # noqa: F401
    import studyapp.motion.smpl  # noqa: F401
    import studyapp.face.smplx  # noqa: F401
    import pandas  # noqa: F401
    import scipy.signal  # noqa: F401


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tests.hardening.fuzz", description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", type=int, default=200, help="number of cases (default 200)")
    ap.add_argument("--start", type=int, default=0, help="index of the first case (default 0)")
    ap.add_argument("--seed", type=int, default=16, help="seed (default 16)")
    ap.add_argument("--case", type=int, action="append", help="run only this case index (repeatable), verbosely")
    ap.add_argument("--readers", default=None, help=f"comma-separated subset of {','.join(READERS)}")
    ap.add_argument("--jobs", type=int, default=2, help="cases run at once (default 2)")
    ap.add_argument("--timeout", type=float, default=30.0,
                    help=f"CPU seconds before a case counts as a hang (default 30; wall-clock cap {WALL_FACTOR}x that)")
    ap.add_argument("--mem-mb", type=int, default=1536, help="address-space cap of a case in MiB (default 1536)")
    ap.add_argument("--samples", type=Path, default=REPO / "tests/data/samples",
                    help="folder of real sample files (default tests/data/samples)")
    ap.add_argument("--work", type=Path, default=None, help="working folder (default: a temporary one)")
    ap.add_argument("--keep", action="store_true", help="keep every case's folder (input, output, stdout, stderr)")
    ap.add_argument("--json", type=Path, default=None, help="also write the outcome of every case to this JSON file")
    args = ap.parse_args(argv)

    readers = READERS if not args.readers else tuple(r.strip() for r in args.readers.split(","))
    unknown = set(readers) - set(READERS)
    if unknown:
        ap.error(f"unknown readers {sorted(unknown)}; choose from {','.join(READERS)}")
    work = args.work or Path(tempfile.mkdtemp(prefix="studyapp-fuzz-"))
    keep = args.keep or bool(args.case)
    t0 = time.monotonic()
    corpus = build_corpus(args.samples, work / "corpus")
    _warm_up()
    indices = args.case or [i for i in range(args.start, args.start + args.cases) if READERS[i % len(READERS)] in readers]
    done = run_cases(args.seed, indices, corpus, work, args.jobs, args.timeout, args.mem_mb, keep=keep,
                     progress=len(indices) >= 500)
    if args.case:
        for c in done:
            print(f"case {c.index} ({c.reader}): {c.source} + {' + '.join(c.mutations)}")
            print(f"  in {c.folder}: studyapp {' '.join(c.argv)}")
            print(f"  outcome {c.outcome} after {c.seconds:.1f} s, max RSS {c.max_rss_mb:.0f} MB")
            for stream in ("stdout.txt", "stderr.txt"):
                text = (c.folder / stream).read_text(errors="replace") if (c.folder / stream).exists() else ""
                tail = text[-3000:]
                print(f"  --- {stream} ({len(text)} chars){' (tail)' if len(text) > 3000 else ''}\n{tail}")
    print(report(done, time.monotonic() - t0, args.seed))
    if args.json:
        args.json.write_text(json.dumps({"seed": args.seed, "counts": counts(done), "cases": [
            {"index": c.index, "reader": c.reader, "source": c.source.name, "mutations": c.mutations, "argv": c.argv,
             "outcome": c.outcome, "detail": c.detail, "seconds": round(c.seconds, 3)} for c in done]}, indent=1))
    if not args.work and not keep:
        shutil.rmtree(work, ignore_errors=True)
    return 1 if any(c.outcome in FAILURES for c in done) else 0


if __name__ == "__main__":
    sys.exit(main())
