#!/usr/bin/env python3
"""Tabulate `examples/oracle_surrogate`: which shove the upper layer's model would choose,
judged in the truth, by adhesion band and driver, and set against the closed loop.

    cargo build --release -p picopit-sim --examples
    for r in "0 192" "512 256" "1024 256"; do
        ./target/release/examples/oracle_surrogate $r 2 4dof,pinn,picopinn 3 '{}' runs/truth-grids
    done > surrogate.txt
    for r in "0 192" "512 256" "1024 256"; do
        ./target/release/examples/episodes '{"preset":"picopinn","clock":"simulated"}' $r
    done > episodes.txt
    python3 scripts/oracle_surrogate.py surrogate.txt --episodes episodes.txt --model picopinn

prints Markdown: per model, the share of scenes its earliest feasible shove (`first`) and
its most forgiving one (`robust`) save, and the expected success over that shove's box
(`exp`); by group; the precision and recall of its verdict on single shoves; its optimum
against its average feasible shove (`best`, `mean`, when the log has them); what it holds
against the succeeding shoves it rejects (`miss_*`, when the log has them); and, for
`--model`, the closed loop's successes among the scenes whose `first` shove works and
among those where it does not.
"""
import argparse
import collections
import sys


def parse_scene(line: str, number: int) -> tuple[str, dict[str, str], dict[str, dict[str, float]]]:
    """(scene id, {group: value}, {model: {field: value}}) of one `scene` line."""
    parts = [p.strip() for p in line.split("|")]
    head = parts[0].split()
    try:
        scene = head[1]
        groups = {"category": head[2], "driver": head[3], "adhesion": head[4]}
        ideal = float(head[5].split("=")[1])
        models = {}
        for p in parts[1:]:
            w = p.split()
            models[w[0]] = {k: float(v) for k, v in (f.split("=") for f in w[1:])}
        for m in models.values():
            m["ideal"] = ideal
    except (IndexError, ValueError) as e:
        raise ValueError(f"line {number}: not an oracle_surrogate scene line ({e}): {line[:80]}")
    return scene, groups, models


def closed_loop(path: str) -> dict[str, bool]:
    """Scene id → success, from an `examples/episodes` log."""
    out = {}
    with open(path, encoding="utf-8") as f:
        for line in f:
            if line.startswith("sc-"):
                w = line.split()
                out[w[0]] = w[3] == "success"
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("log", help="output of examples/oracle_surrogate")
    ap.add_argument("--episodes", help="output of examples/episodes on the same scenes")
    ap.add_argument("--model", default="picopinn", help="model to set against the closed loop")
    args = ap.parse_args()
    try:
        with open(args.log, encoding="utf-8") as f:
            rows = [parse_scene(l, i) for i, l in enumerate(f, 1) if l.startswith("scene ")]
        episodes = closed_loop(args.episodes) if args.episodes else None
    except (OSError, ValueError) as e:
        print(f"oracle_surrogate: {e}", file=sys.stderr)
        return 1
    if not rows:
        print(f"oracle_surrogate: {args.log}: no scene lines", file=sys.stderr)
        return 1
    models = list(rows[0][2])
    fields = ("first", "robust", "exp")
    print(f"{len(rows)} scenes\n")
    print("| group | n | ideal | " + " | ".join(f"{m} {f}" for m in models for f in fields) + " |")
    print("|---|---|---|" + "---|" * (len(models) * len(fields)))
    keys = [("all", "all")] + sorted(
        {(g, v) for _, groups, _ in rows for g, v in groups.items() if g != "category"}
    )
    for g, v in keys:
        sel = [r for r in rows if g == "all" or r[1][g] == v]
        n = len(sel)
        ideal = 100 * sum(r[2][models[0]]["ideal"] for r in sel) / n
        cells = [
            f"{100 * sum(r[2][m][f] for r in sel) / n:.1f} %" for m in models for f in fields
        ]
        label = "**all**" if g == "all" else f"{g} {v}"
        print(f"| {label} | {n} | {ideal:.1f} % | " + " | ".join(cells) + " |")
    print("\nverdict on single shoves (precision: called feasible and succeeds / called feasible; "
          "recall: called feasible and succeeds / succeeds):\n")
    print("| group | " + " | ".join(f"{m} precision | {m} recall" for m in models) + " |")
    print("|---|" + "---|---|" * len(models))
    for g, v in keys:
        sel = [r for r in rows if g == "all" or r[1][g] == v]
        cells = []
        for m in models:
            both = sum(r[2][m]["both"] for r in sel)
            called = both + sum(r[2][m]["model_only"] for r in sel)
            works = both + sum(r[2][m]["truth_only"] for r in sel)
            cells += [f"{100 * both / max(called, 1):.1f} %", f"{100 * both / max(works, 1):.1f} %"]
        label = "**all**" if g == "all" else f"{g} {v}"
        print(f"| {label} | " + " | ".join(cells) + " |")
    if all("best" in r[2][m] and "mean" in r[2][m] for r in rows for m in models):
        print("\nthe model's optimum (`best`: the feasible shove it puts nearest the reversed "
              "heading) against a feasible shove at random (`mean`), at the earliest time it "
              "calls one feasible:\n")
        print("| group | " + " | ".join(f"{m} scenes | {m} best | {m} mean | {m} best − mean"
                                        for m in models) + " |")
        print("|---|" + "---|---|---|---|" * len(models))
        for g, v in keys:
            sel = [r for r in rows if g == "all" or r[1][g] == v]
            cells = []
            for m in models:
                # The model calls a shove feasible somewhere iff it has an earliest one.
                called = [r[2][m] for r in sel if r[2][m]["both"] + r[2][m]["model_only"] > 0]
                n = max(len(called), 1)
                best = 100 * sum(c["best"] for c in called) / n
                mean = 100 * sum(c["mean"] for c in called) / n
                cells += [str(len(called)), f"{best:.1f} %", f"{mean:.1f} %",
                          f"{best - mean:+.1f} points"]
            label = "**all**" if g == "all" else f"{g} {v}"
            print(f"| {label} | " + " | ".join(cells) + " |")
    miss = ("miss_heading", "miss_road", "miss_stop", "miss_obstacle")
    if all(f in r[2][m] for r in rows for m in models for f in miss):
        print("\nwhat the model holds against the succeeding shoves it rejects (share of them; "
              "a shove can fail several criteria):\n")
        print("| model | rejected successes | terminal heading | road edge | stopping point "
              "| obstacle |")
        print("|---|---|---|---|---|---|")
        for m in models:
            n = sum(r[2][m]["truth_only"] for r in rows)
            cells = [f"{100 * sum(r[2][m][f] for r in rows) / max(n, 1):.1f} %" for f in miss]
            print(f"| {m} | {n:.0f} | " + " | ".join(cells) + " |")
    if episodes is not None:
        m = args.model
        if m not in models:
            print(f"oracle_surrogate: no model {m!r} in {args.log}", file=sys.stderr)
            return 1
        table = collections.Counter()
        for scene, _, ms in rows:
            if scene in episodes:
                table[(ms[m]["first"] > 0.5, episodes[scene])] += 1
        print(f"\nclosed loop against {m}'s first shove, executed exactly:\n")
        print("| first shove | scenes | closed-loop successes |")
        print("|---|---|---|")
        for works in (True, False):
            n = table[(works, True)] + table[(works, False)]
            print(f"| {'works' if works else 'fails or none'} | {n} | {table[(works, True)]} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
