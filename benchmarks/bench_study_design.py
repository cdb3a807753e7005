"""Study engine part 1 on the demo design: design loading, trial media (cold vs replay), schedules, careful scores.

Prints one table; ratios compare figures measured in this same run, so they are meaningful on a busy machine.
"""
from __future__ import annotations

import time

from studyapp.bots.careful import careful_scores
from studyapp.resources import demo_design
from studyapp.study import stimuli
from studyapp.study.design import load_design
from studyapp.study.design.files import _HASH_CACHE
from studyapp.study.schedule import full_schedule, participant_schedule


def best(fn, repeat: int = 5) -> float:
    """Best of ``repeat`` wall-clock runs, in seconds (the least disturbed by other processes)."""
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> None:
    load_design(demo_design())  # imports and first touch of the files

    def cold_load():
        stimuli.clear_cache()
        _HASH_CACHE.clear()
        load_design(demo_design())

    t_cold = best(cold_load, 3)
    t_warm = best(lambda: load_design(demo_design()))
    design = load_design(demo_design())
    plan = participant_schedule(design, "P01", row=0)[1]

    def cold_media():
        stimuli.clear_cache()
        stimuli.load_trial_media(design, plan)

    t_media_cold = best(cold_media, 3)
    stimuli.load_trial_media(design, plan)
    t_media_replay = best(lambda: stimuli.load_trial_media(design, plan), 50)
    media = stimuli.load_trial_media(design, plan)
    t_careful = best(lambda: careful_scores(media), 3)
    t_sched_1 = best(lambda: participant_schedule(design, "P01", row=3), 20)
    t_sched_1200 = best(lambda: full_schedule(design, 1200), 3)

    rows = [
        ("load_design, files re-read (validate + hash)", t_cold, ""),
        ("load_design, files cached", t_warm, f"{t_cold / t_warm:.0f}x faster than re-reading"),
        ("load_trial_media, first show", t_media_cold, ""),
        ("load_trial_media, replay", t_media_replay, f"{t_media_cold / t_media_replay:.0f}x faster than first show"),
        ("careful_scores, one trial (3 x 10 s motion)", t_careful, ""),
        ("participant_schedule, one participant", t_sched_1, ""),
        ("full_schedule, 1200 participants", t_sched_1200, f"{t_sched_1200 / 1200 * 1e6:.0f} us per participant"),
    ]
    print(f"{'what':48s} {'time':>12s}  note")
    for name, t, note in rows:
        shown = f"{t * 1e3:9.3f} ms" if t >= 1e-3 else f"{t * 1e6:9.1f} us"
        print(f"{name:48s} {shown:>12s}  {note}")


if __name__ == "__main__":
    main()
