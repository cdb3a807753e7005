"""``python -m studyapp.demo_content OUT_DIR``: (re)generate the demo study's stimuli."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from studyapp.demo_content import generate


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m studyapp.demo_content", description=__doc__)
    parser.add_argument("out_dir", type=Path, help="folder to write (the shipped copy is study_designs/demo)")
    args = parser.parse_args(argv)
    written = generate(args.out_dir)
    files = [p for group in ("audio", "face") for p in written[group].values()]
    files += [p for per_cond in written["motion"].values() for p in per_cond.values()] + [written["manifest"]]
    total = sum(p.stat().st_size for p in files)
    print(f"wrote {len(files)} files, {total / 1e6:.2f} MB, to {args.out_dir}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
