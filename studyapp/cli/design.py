"""``studyapp validate`` and ``studyapp schedule``: check a design, print the plan it produces."""
from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    v = sub.add_parser(
        "validate",
        help="check a study design: every problem in one run, each with file, key and fix",
        description="Check a study design file and every file it references. Exit status 0 only when the "
                    "design can run; otherwise one line per problem (file:line: key: problem -- fix: ...).",
    )
    v.add_argument("design", type=Path, help="the design .toml")
    v.add_argument("--json", action="store_true", help="print a JSON list of {file, key, line, message, fix}")
    v.add_argument("--quick", action="store_true",
                   help="do not open stimulus files (skips duration and skeleton checks; missing files are still reported)")
    v.set_defaults(func=_cmd_validate)

    s = sub.add_parser(
        "schedule",
        help="print the full trial plan of a design and its balance counts",
        description="The plan for N participants arriving in order (participant k gets design row k mod "
                    "n_rows): one row per participant x trial, then how often each clip comes at each "
                    "position and each condition sits in each slot.",
    )
    s.add_argument("design", type=Path, help="the design .toml")
    s.add_argument("--participants", "-n", type=int, required=True, help="number of participants")
    s.add_argument("--csv", type=Path, help="write the plan to this CSV file instead of printing it")
    s.set_defaults(func=_cmd_schedule)


def _cmd_validate(args: argparse.Namespace) -> int:
    from studyapp.study.design import problems_to_json, validate_design

    # Readers warn about what they can work around (a blendshape missing from a face file is set to 0,
    # a BVH header's frame count disagrees with its data): the experimenter should see those as notes,
    # not as Python warnings, and they do not stop the design from running.
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        problems = validate_design(args.design, check_files=not args.quick)
    notes = list(dict.fromkeys(str(w.message) for w in caught))
    if args.json:
        print(problems_to_json(problems))
        for n in notes:  # stdout stays one JSON document; the notes still reach the experimenter
            print(f"note: {n}", file=sys.stderr)
    else:
        for p in problems:
            print(p)
        for n in notes:
            print(f"note: {n}")
        if problems:
            n = len(problems)
            print("1 problem: the design cannot run until it is fixed." if n == 1 else
                  f"{n} problems: the design cannot run until they are fixed.", file=sys.stderr)
        else:
            print(f"{args.design}: OK, the design can run.")
    if not problems and not args.quick:
        _warm_gl(args.design)
    return 1 if problems else 0


def _warm_gl(path: Path) -> None:
    """Compile the programs of a participant's trial frame into this machine's GL driver cache
    (:mod:`studyapp.render.warmup`, in a child process): in a lab, the experimenter validates on the
    participants' PC, whose first participant would otherwise wait for the compile. Best effort and silent:
    it changes no verdict."""
    import logging

    from studyapp.errors import StudyappError
    from studyapp.render.warmup import warm_in_child
    from studyapp.study.design import load_design

    try:
        design = load_design(path, reuse_check=True)  # just checked and recorded: the cheap parse only
    except (StudyappError, OSError, ValueError):
        return
    specs = sorted({design.avatar_for(s) for s in design.stimuli})
    outcome = warm_in_child([None if s == "builtin" else s for s in specs], dict(design.avatar_bone_map))
    logging.getLogger(__name__).debug("GL shader cache: %s", outcome)


def _cmd_schedule(args: argparse.Namespace) -> int:
    from studyapp.errors import StudyappError
    from studyapp.study.design import load_design
    from studyapp.study.schedule import balance_counts, full_schedule, n_rows

    if args.participants < 1:
        raise StudyappError("--participants must be at least 1")
    design = load_design(args.design, check_files=False)
    df = full_schedule(design, args.participants)
    if args.csv:
        args.csv.parent.mkdir(parents=True, exist_ok=True)
        df.to_csv(args.csv, index=False)
        print(f"Wrote {len(df)} trials of {args.participants} participants to {args.csv}")
    else:
        import pandas as pd  # only `schedule` prints a table; `--help` must not pay for pandas

        with pd.option_context("display.max_rows", None, "display.width", 200):
            print(df.to_string(index=False))
    rows = n_rows(design)
    print(f"\nOrdering {design.ordering}, slot assignment {design.slot_assignment}: {rows} design rows; "
          f"full balance needs a multiple of {rows} participants"
          + ("" if args.participants % rows == 0 else f" ({args.participants} is not)") + ".")
    counts = balance_counts(df)
    blocked = "paradigm" in df.columns
    if not blocked or (df["paradigm"] == "rank").any():
        print("\nRated trials per position (rows) x stimulus (columns)" + (", rank blocks:" if blocked else ":"))
        print(counts["position_x_stimulus"].to_string())
        print("\nConditions (rows) x slots (columns)" + (", rank blocks:" if blocked else ":"))
        print(counts["slot_x_condition"].to_string())
    if blocked:
        from studyapp.study.schedule import block_counts

        per_block = block_counts(df)
        print("\nEvery block: conditions (rows) x slot positions (columns), 0 = left:")
        print(per_block["figure_x_slot"].to_string())
        if "matched_side" in per_block:
            print("\nMismatch blocks: the figure playing its own motion, left or right, per condition x stimulus:")
            print(per_block["matched_side"].to_string())
    if any(c.samples > 1 for c in design.conditions):
        print("\nSamples shown (columns) per condition x stimulus (rows), rated trials:")
        print(counts["sample_x_condition_stimulus"].to_string())
    return 0
