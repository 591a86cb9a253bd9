#!/usr/bin/env python3
"""Split two closed-loop runs' difference into reaching the reversal and what follows it.

Reads the lines of two `examples/episodes` runs over the same scenes (A and B, e.g. two
configurations) and prints, for each: the scenes brought into contact, the mean first
impact (point x on the target, closing speed), the targets reversed among the scenes both
bring into contact (both / only this one), and the successes among the scenes both reverse.
With `--traces DIR_A DIR_B` (the output of `examples/trace_episode` for each of those
scenes, one `<scene>.txt` per scene) it adds the state at the let-go (the first
`Stabilising` line: turn, yaw rate, push length) and the mean peak force of the PIT plans
made in contact.

    cargo build --release -p picopit-sim --example episodes --example trace_episode
    for r in "0 192" "512 256" "1024 256"; do
        ./target/release/examples/episodes '{"preset":"4dof","clock":"simulated"}' $r
    done > a.txt                                   # likewise "picopinn" > b.txt
    python3 scripts/reversal_split.py a.txt b.txt
    for s in $(python3 scripts/reversal_split.py a.txt b.txt --both-contacted); do
        ./target/release/examples/trace_episode $s '{"preset":"4dof","clock":"simulated"}' > ta/$s.txt
    done                                           # likewise "picopinn" into tb/
    python3 scripts/reversal_split.py a.txt b.txt --traces ta tb
"""
from __future__ import annotations

import argparse
import re
import statistics
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Tuple

IMPACT = re.compile(r"\| impact x (\S+) y (\S+) v (\S+)")
REVERSED = re.compile(r"\| reversed (?:t (\S+) v (\S+)|-)")
TRACE = re.compile(r"^t=\s*(\S+) (\S+) .*?ψ-h=\s*(\S+)° .* Fn=\s*(\S+)\s*$")
PLAN = re.compile(r"^plan t=\s*(\S+) (\S+) push .*?peak (\S+) N")


@dataclass
class Episode:
    success: bool
    impact: Optional[Tuple[float, float]]  # (point x on the target, closing speed)
    reversed: bool


@dataclass
class LetGo:
    turn: float  # deg, |heading − road heading| at the first Stabilising line
    rate: float  # deg/s, its change from the line before
    push: float  # s, from the first contact force to the let-go
    peak: float  # N, mean peak force of the PIT plans made from the first contact on


def parse_episodes(path: Path) -> Dict[str, Episode]:
    """The `episodes` lines of a file by scene; a malformed line raises naming it."""
    out: Dict[str, Episode] = {}
    for i, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        if not line.startswith("sc-"):
            continue
        words = line.split()
        imp, rev = IMPACT.search(line), REVERSED.search(line)
        if len(words) < 4 or rev is None or ("| impact -" not in line and imp is None):
            raise ValueError(f"{path}:{i}: not an episodes line: {line[:80]}")
        impact = (float(imp.group(1)), float(imp.group(3))) if imp else None
        out[words[0]] = Episode(words[3] == "success", impact, rev.group(1) is not None)
    if not out:
        raise ValueError(f"{path}: no episode lines (sc-…)")
    return out


def parse_trace(path: Path) -> Optional[LetGo]:
    """The let-go of one `trace_episode` output, None if the bullet never pushed or never
    let go."""
    rows: List[Tuple[float, str, float, float]] = []
    plans: List[Tuple[float, str, float]] = []
    for line in path.read_text(encoding="utf-8").splitlines():
        m = TRACE.match(line)
        if m:
            rows.append((float(m.group(1)), m.group(2), abs(float(m.group(3))), float(m.group(4))))
            continue
        m = PLAN.match(line)
        if m:
            plans.append((float(m.group(1)), m.group(2), float(m.group(3))))
    touch = [r[0] for r in rows if r[3] > 0.0]
    stab = [i for i, r in enumerate(rows) if r[1] == "Stabilising"]
    if not touch or not stab or stab[0] == 0:
        return None
    i, t0 = stab[0], touch[0]
    (ta, _, ha, _), (tb, _, hb, _) = rows[i - 1], rows[i]
    peaks = [p for t, mode, p in plans if t >= t0 - 1e-6 and mode == "Pit"]
    return LetGo(hb, (hb - ha) / (tb - ta), tb - t0, statistics.fmean(peaks) if peaks else 0.0)


def _p(a: int, b: int) -> float:
    """Exact two-sided McNemar p for a scenes only one side has, b only the other."""
    from math import comb

    n = a + b
    return 1.0 if n == 0 else min(1.0, 2 * sum(comb(n, k) for k in range(min(a, b) + 1)) / 2 ** n)


def report(a: Dict[str, Episode], b: Dict[str, Episode], names: Tuple[str, str],
           traces: Optional[Tuple[Path, Path]] = None) -> str:
    common = sorted(set(a) & set(b))
    if not common:
        raise ValueError("the two runs have no scene in common")
    both = [s for s in common if a[s].impact and b[s].impact]
    rev_both = [s for s in both if a[s].reversed and b[s].reversed]
    rows = [("scenes", [str(len(common))] * 2)]
    touched = [[r[s].impact for s in common if r[s].impact] for r in (a, b)]
    rows.append(("scenes brought into contact", [str(len(t)) for t in touched]))
    rows.append(("first impact: point x on the target, closing speed (mean)",
                 [f"{statistics.fmean(x for x, _ in t):+.2f} m, {statistics.fmean(v for _, v in t):.2f} m/s"
                  if t else "–" for t in touched]))
    only = [sum(1 for s in both if r[s].reversed and not o[s].reversed) for r, o in ((a, b), (b, a))]
    rows.append((f"targets reversed of the {len(both)} both touch (both / only this one; p = {_p(*only):.2g})",
                 [f"{sum(1 for s in both if r[s].reversed)} ({len(rev_both)} / {k})" for r, k in zip((a, b), only)]))
    rows.append((f"successes among the {len(rev_both)} both reverse",
                 [str(sum(1 for s in rev_both if r[s].success)) for r in (a, b)]))
    rows.append(("successes", [str(sum(1 for s in common if r[s].success)) for r in (a, b)]))
    if traces is not None:
        lets = []
        for d in traces:
            got = {}
            for s in both:
                f = d / f"{s}.txt"
                if not f.is_file():
                    raise ValueError(f"{f}: missing (a trace per scene both bring into contact)")
                got[s] = parse_trace(f)
            lets.append(got)
        keys = [s for s in both if all(g[s] is not None for g in lets)]
        med = lambda g, k: statistics.median(getattr(g[s], k) for s in keys) if keys else float("nan")  # noqa: E731
        rows.append((f"at the let-go, medians over the {len(keys)} scenes both let go: turn, yaw rate, push length",
                     [f"{med(g, 'turn'):.1f}°, {med(g, 'rate'):.0f}°/s, {med(g, 'push'):.2f} s" for g in lets]))
        rows.append(("mean peak force of the PIT plans made in contact",
                     [f"{statistics.fmean(g[s].peak for s in keys):.0f} N" if keys else "–" for g in lets]))
    out = [f"| | {names[0]} | {names[1]} |", "|---|---|---|"]
    out += [f"| {label} | {c[0]} | {c[1]} |" for label, c in rows]
    return "\n".join(out) + "\n"


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("a", type=Path, help="examples/episodes output of run A")
    ap.add_argument("b", type=Path, help="examples/episodes output of run B")
    ap.add_argument("--traces", nargs=2, type=Path, metavar=("DIR_A", "DIR_B"),
                    help="trace_episode outputs (<scene>.txt) of the scenes both bring into contact")
    ap.add_argument("--both-contacted", action="store_true",
                    help="only list the scenes both runs bring into contact, one per line")
    args = ap.parse_args(argv)
    try:
        a, b = parse_episodes(args.a), parse_episodes(args.b)
        if args.both_contacted:
            print("\n".join(s for s in sorted(set(a) & set(b)) if a[s].impact and b[s].impact))
            return 0
        print(report(a, b, (args.a.stem, args.b.stem), tuple(args.traces) if args.traces else None), end="")
    except (OSError, ValueError) as e:
        print(f"reversal_split: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
