#!/usr/bin/env python3
"""Join the ideal-PIT tiers (`oracle_tiers` example) with a benchmark run's episodes: how
often each configuration saved the scenes, by how forgiving the scene's best shove is
(docs/RESULTS.md, "How much of the bound a controller can reach").

Input: the lines printed by `./target/release/examples/oracle_tiers FIRST COUNT` (any number
of files) and a run folder's `episodes.parquet` (needs pyarrow: the project's .venv).

    .venv/bin/python scripts/oracle_tiers.py TIERS.txt [...] --episodes runs/bench-full-9/episodes.parquet
"""
import argparse
import collections

TIERS = ["ideal", "robust-t", "robust-v", "robust-tv", "ideal-exp", "held-first", "held-robust", "held-exp"]


def parse(line):
    """One `scene` line as a dict (ValueError if it is not one)."""
    if not line.startswith("scene ") or " | " not in line:
        raise ValueError("not a `scene` line of the oracle_tiers example")
    head, tail = line.split(" | ", 1)
    f = head.split()
    row = {"id": f[1], "category": f[2], "driver": f[3], "params": f[4]}
    row.update({k: float(v) for k, v in (kv.split("=") for kv in tail.split())})
    missing = [t for t in TIERS if t not in row]
    if missing:
        raise ValueError(f"tiers {missing} missing (output of an older oracle_tiers?)")
    return row


def bucket(p):
    """The box-score band of an `ideal-exp` share (printed to 2 decimals: ninths)."""
    k = round(9 * p)
    if k == 0:
        return "0 (no shove)"
    if k <= 3:
        return "1–3 of 9"
    if k <= 6:
        return "4–6 of 9"
    return "7–9 of 9"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("tiers", nargs="+")
    ap.add_argument("--episodes", required=True, help="a run folder's episodes.parquet")
    a = ap.parse_args()
    scenes = {}
    for path in a.tiers:
        with open(path) as fh:
            for line in fh:
                if line.startswith("scene "):
                    r = parse(line.rstrip("\n"))
                    scenes[r["id"]] = r
    if not scenes:
        raise SystemExit("no `scene` lines in " + ", ".join(a.tiers))
    import pyarrow.parquet as pq

    eps = pq.read_table(a.episodes, columns=["config", "scenario", "success"]).to_pylist()
    configs = sorted({e["config"] for e in eps})
    won = collections.defaultdict(dict)
    for e in eps:
        if e["scenario"] in scenes:
            won[e["config"]][e["scenario"]] = bool(e["success"])
    n = len(scenes)
    print(f"{n} scenes")
    print("| tier | share of scenes |")
    print("|---|---|")
    for t in TIERS:
        print(f"| {t} | {100 * sum(s[t] for s in scenes.values()) / n:.1f} % |")
    for c in configs:
        if len(won[c]) != n:
            print(f"(the run has {len(won[c])} of these scenes for {c})")
    print()
    print("Controller success by the scene's best box: successes among the 9 shoves around its most forgiving shove (ideal-exp):")
    print()
    print("| best box | scenes | " + " | ".join(configs) + " |")
    print("|---|---|" + "---|" * len(configs))
    order = ["0 (no shove)", "1–3 of 9", "4–6 of 9", "7–9 of 9"]
    groups = collections.defaultdict(list)
    for s in scenes.values():
        groups[bucket(s["ideal-exp"] if s["ideal"] else 0.0)].append(s["id"])
    for b in order:
        ids = groups.get(b, [])
        cells = []
        for c in configs:
            got = [won[c][i] for i in ids if i in won[c]]
            cells.append(f"{sum(got)} ({100 * sum(got) / max(len(got), 1):.0f} %)")
        print(f"| {b} | {len(ids)} | " + " | ".join(cells) + " |")
    print()
    print("Saved by the controller although no single shove saves the scene (ideal = 0):")
    for c in configs:
        ids = sorted(i for i in groups.get("0 (no shove)", []) if won[c].get(i))
        print(f"  {c}: {len(ids)} {' '.join(ids)}")


if __name__ == "__main__":
    main()
