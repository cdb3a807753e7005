"""Study engine part 1 on the demo design: design loading, trial media, schedules, careful scores.

Prints one table of medians with min-max over the same number of runs for every row. Cold rows (files
re-read, caches cleared) and cached rows (a dictionary lookup after the first load) run interleaved, cold then
cached in each round, so both see the same machine load; they are shown side by side but never divided: a
cache hit is not a faster load, and a ratio between them says nothing about either.
"""
from __future__ import annotations

import os
import statistics
import time

from studyapp.bots.careful import careful_scores
from studyapp.resources import demo_design
from studyapp.study import stimuli
from studyapp.study.design import load_design
from studyapp.study.design.files import _HASH_CACHE
from studyapp.study.schedule import full_schedule, participant_schedule

RUNS = 7


def timed(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def interleaved(*fns, runs: int = RUNS) -> list[list[float]]:
    """Wall-clock seconds of each function, ``runs`` rounds, the functions alternating within a round."""
    out: list[list[float]] = [[] for _ in fns]
    for _ in range(runs):
        for i, fn in enumerate(fns):
            out[i].append(timed(fn))
    return out


def _fmt(t: float) -> str:
    return f"{t * 1e3:9.3f} ms" if t >= 1e-3 else f"{t * 1e6:9.1f} us"


def main() -> None:
    load_design(demo_design())  # imports and first touch of the files

    def cold_load():
        stimuli.clear_cache()
        _HASH_CACHE.clear()
        load_design(demo_design())

    t_cold, t_warm = interleaved(cold_load, lambda: load_design(demo_design()))
    design = load_design(demo_design())
    plan = participant_schedule(design, "P01", row=0)[1]

    def cold_media():
        stimuli.clear_cache()
        stimuli.load_trial_media(design, plan)

    t_media_cold, t_media_replay = interleaved(cold_media, lambda: stimuli.load_trial_media(design, plan))
    media = stimuli.load_trial_media(design, plan)
    (t_careful,) = interleaved(lambda: careful_scores(media))
    (t_sched_1,) = interleaved(lambda: participant_schedule(design, "P01", row=3))
    (t_sched_1200,) = interleaved(lambda: full_schedule(design, 1200))

    rows = [
        ("load_design, files re-read (validate + hash)", t_cold, "what `validate` and a session start pay"),
        ("load_design, file hashes cached", t_warm, "the design is still parsed and validated"),
        ("load_trial_media, first show", t_media_cold, "what a participant waits for"),
        ("load_trial_media, replay", t_media_replay, "cache hit (dictionary lookup), not a load"),
        ("careful_scores, one trial (3 x 10 s motion)", t_careful, ""),
        ("participant_schedule, one participant", t_sched_1, ""),
        ("full_schedule, 1200 participants", t_sched_1200,
         f"{statistics.median(t_sched_1200) / 1200 * 1e6:.0f} us per participant"),
    ]
    print(f"{RUNS} runs per row, cold and cached rows interleaved; load average {os.getloadavg()[0]:.2f} "
          f"({os.cpu_count()} cores)")
    print(f"{'what':48s} {'median':>12s} {'min':>12s} {'max':>12s}  note")
    for name, t, note in rows:
        print(f"{name:48s} {_fmt(statistics.median(t)):>12s} {_fmt(min(t)):>12s} {_fmt(max(t)):>12s}  {note}")

if __name__ == "__main__":
    main()
