#!/usr/bin/env python3
"""Count closed-loop failures by stage: before any contact, in or after contact with the
target never reversed, and after the target had been reversed.

Reads the lines of `examples/episodes` (one per scene), e.g.

    cargo build --release -p picopit-sim --example episodes
    for r in "0 192" "512 256" "1024 256"; do
        ./target/release/examples/episodes '{"preset":"picopinn","clock":"simulated"}' $r
    done > episodes.txt
    python3 scripts/failure_stage.py episodes.txt

and prints a Markdown table of (outcome, failing vehicle, stage) counts.
"""
import argparse
import collections
import sys


def parse(line: str, number: int) -> tuple[str, str, str]:
    """(outcome, vehicle, stage) of one `episodes` line."""
    words = line.split()
    try:
        outcome = words[3]
        if outcome == "success":
            return ("success", "-", "-")
        vehicle = words[4] if words[4] in ("Target", "Bullet") else "-"
        at = float(words[words.index("at") + 1])
        contacts = int(line.split("contacts")[1].split()[0])
        rev = line.split("| reversed")[1].split()
        reversed_at = None if rev[0] == "-" else float(rev[1])
    except (IndexError, ValueError) as e:
        raise ValueError(f"line {number}: not an episodes line ({e}): {line.strip()[:80]}")
    if contacts == 0:
        stage = "before any contact"
    elif reversed_at is not None and reversed_at <= at + 1e-9:
        stage = "after the target was reversed"
    else:
        stage = "in or after contact, never reversed"
    return (outcome, vehicle, stage)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("log", help="output of examples/episodes")
    args = ap.parse_args()
    try:
        with open(args.log, encoding="utf-8") as f:
            lines = [(i, l) for i, l in enumerate(f, 1) if l.startswith("sc-")]
    except OSError as e:
        print(f"failure_stage: {e}", file=sys.stderr)
        return 1
    if not lines:
        print(f"failure_stage: {args.log}: no episode lines (sc-…)", file=sys.stderr)
        return 1
    try:
        counts = collections.Counter(parse(l, i) for i, l in lines)
    except ValueError as e:
        print(f"failure_stage: {args.log}: {e}", file=sys.stderr)
        return 1
    print(f"{len(lines)} episodes")
    print("| stage | outcome | vehicle | episodes |\n|---|---|---|---|")
    for (outcome, vehicle, stage), n in sorted(counts.items(), key=lambda kv: (kv[0][2], -kv[1])):
        print(f"| {stage} | {outcome} | {vehicle} | {n} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
