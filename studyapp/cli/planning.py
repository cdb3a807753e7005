"""``studyapp metrics`` and ``studyapp plan``: objective metrics of a design's motion, and its power before recruiting."""
from __future__ import annotations

import argparse
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    m = sub.add_parser(
        "metrics",
        help="objective metrics per condition and stimulus (beat alignment, L1 diversity, jerk, frozen frames)",
        description="Compute, from the motion as it plays on the avatar (60 fps, metres) and the clip's audio, "
                    "per condition x stimulus: the Beat Align Score (motion beats = minima of joint speed vs audio "
                    "onsets, sigma 0.3 s), L1 diversity (1 s segments), mean acceleration and jerk, and the share "
                    "of frozen frames (every joint under 5 mm/s). Writes a CSV that `results-analysis --metrics` "
                    "sets beside the subjective ranks. FGD only with an encoder you provide (--fgd-encoder).",
    )
    m.add_argument("design", type=Path, help="the design .toml")
    m.add_argument("--out", type=Path, help="write the table to this CSV file (default: print it)")
    m.add_argument("--fgd-encoder", type=Path, metavar="MODEL.onnx",
                   help="a trained motion encoder (ONNX, input [batch, frames, 3 x avatar joints]); adds the "
                        "Frechet Gesture Distance column 'fgd'")
    m.add_argument("--fgd-reference", metavar="CONDITION",
                   help="the condition FGD measures against (real motion; default: the first condition)")
    m.add_argument("--segment-s", type=float, default=1.0, help="L1-diversity segment length in seconds (default 1)")
    m.set_defaults(func=_cmd_metrics)

    p = sub.add_parser(
        "plan",
        help="power of the headline test for N participants, simulated on the design's own schedule",
        description="Simulate the design's schedule (participants on rows in order of arrival) with a "
                    "Plackett-Luce model of the given strengths, run the analysis's headline test "
                    "(participant-level Friedman) on each simulated study, and report the power at N, the N for "
                    "the target power, the balance achieved and the expected session length. Seeded.",
    )
    p.add_argument("design", type=Path, help="the design .toml")
    p.add_argument("--participants", "-n", type=int, required=True, help="number of participants")
    p.add_argument("--strengths", required=True, metavar="A,B,C",
                   help="Plackett-Luce strengths, one per condition in design order (e.g. 2,1.5,1)")
    p.add_argument("--simulations", type=int, default=1000, help="simulated studies per N (default 1000)")
    p.add_argument("--alpha", type=float, default=0.05, help="significance level (default 0.05)")
    p.add_argument("--target", type=float, default=0.8, help="power to find N for (default 0.8)")
    p.add_argument("--max-n", type=int, default=500, help="largest N searched (default 500)")
    p.add_argument("--answer-s", type=float, default=15.0,
                   help="assumed seconds to answer one trial, added to its playing time (default 15)")
    p.add_argument("--seed", type=int, default=0, help="simulation seed (default 0)")
    p.set_defaults(func=_cmd_plan)


def _cmd_metrics(args: argparse.Namespace) -> int:
    from studyapp.errors import InputError
    from studyapp.study.design import load_design
    from studyapp.study.metrics import design_metrics

    if not args.segment_s > 0:
        raise InputError(None, "--segment-s", f"{args.segment_s}: must be a positive number of seconds")
    design = load_design(args.design)
    encoder = None
    if args.fgd_encoder is not None:
        from studyapp.models.encoder import MotionEncoder

        encoder = MotionEncoder(args.fgd_encoder)
    elif args.fgd_reference is not None:
        raise InputError(None, "--fgd-reference", "needs --fgd-encoder (FGD is computed only with your encoder)")
    table = design_metrics(design, encoder=encoder, fgd_reference=args.fgd_reference, segment_s=args.segment_s)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        table.to_csv(args.out, index=False, float_format="%.6g")
        print(f"Wrote {len(table)} rows (condition x stimulus x sample) to {args.out}")
    else:
        import pandas as pd

        with pd.option_context("display.max_rows", None, "display.width", 200, "display.max_columns", None):
            print(table.to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    cols = [c for c in table.columns if c not in ("stimulus", "sample", "duration_s", "fps")]
    means = table[cols].groupby("condition", sort=False).mean()
    print("\nMean per condition:")
    print(means.to_string(float_format=lambda v: f"{v:.4g}"))
    return 0


def _cmd_plan(args: argparse.Namespace) -> int:
    from studyapp.errors import InputError
    from studyapp.study.design import load_design
    from studyapp.study.plan import parse_strengths, plan_study

    if args.participants < 2:
        raise InputError(None, "--participants", f"{args.participants}: the headline test needs at least 2")
    if args.answer_s < 0:
        raise InputError(None, "--answer-s", f"{args.answer_s}: must not be negative")
    design = load_design(args.design)
    r = plan_study(design, args.participants, parse_strengths(args.strengths, design), n_sim=args.simulations,
                   alpha=args.alpha, target=args.target, max_n=args.max_n, answer_s=args.answer_s, seed=args.seed)
    strengths = ", ".join(f"{c} {v:g}" for c, v in r.strengths.items())
    print(f"Plackett-Luce strengths: {strengths}; {r.rated_trials} rated trials per participant; "
          f"{r.n_sim} simulated studies per N, seed {r.seed}.")
    print(f"Headline test: participant-level Friedman (each participant's mean within-trial rank), alpha = {r.alpha:g}.")
    print(f"Power with {r.n_participants} participants: {r.power:.1%} (Monte-Carlo SE {r.power_se:.1%}).")
    if r.n_for_target is None:
        print(f"{r.target:.0%} power is not reached with up to {r.max_n} participants (--max-n).")
    else:
        print(f"Participants needed for {r.target:.0%} power: {r.n_for_target}"
              + (f" (a multiple of {r.n_rows} for full balance: "
                 f"{-(-r.n_for_target // r.n_rows) * r.n_rows})" if r.n_for_target % r.n_rows else "") + ".")
    print("Power by N: " + ", ".join(f"{n}: {p:.0%}" for n, p in r.curve.items()))
    minutes = r.session_seconds / 60
    print(f"Session length: {r.n_trials} trials, {r.trial_seconds / 60:.1f} min of clips + {r.answer_s:g} s to answer "
          f"each = about {minutes:.1f} min per participant (replays not counted).")
    print(f"\nBalance for {r.n_participants} participants ({r.n_rows} design rows):")
    print("Rated trials per position (rows) x stimulus (columns):")
    print(r.balance["position_x_stimulus"].to_string())
    print("Conditions (rows) x slots (columns):")
    print(r.balance["slot_x_condition"].to_string())
    for note in r.notes:
        print(f"note: {note}")
    return 0
