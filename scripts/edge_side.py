#!/usr/bin/env python3
"""Which road edge do spun targets cross, and how much road was there on the bullet's side?
(docs/planner.md, "What the contact and the spin leave behind").

Re-runs every episode with a contact through `trace_episode` (same configuration) and reads,
at the first step with a contact force, the target's and the bullet's lateral offsets d from
the road's reference line (left positive) and, at the last step, the target's. The bullet's
side is where its c.g. is relative to the target's; the room on that side is the road's half
width minus the target's offset toward it.

    cargo build --release -p picopit-sim --example trace_episode
    python3 scripts/edge_side.py EPISODES.txt [...] [--config JSON] [--scenarios FILE]
"""
import argparse
import collections
import os
import re
import subprocess
from concurrent.futures import ThreadPoolExecutor

from failure_map import load_episodes, load_scenarios

TRACE = "./target/release/examples/trace_episode"
STEP = re.compile(r"T: d=\s*([-\d.]+).*B: d=\s*([-\d.]+).*Fn=\s*([-\d]+)")


def trace(sid, config):
    out = subprocess.run([TRACE, sid, config], capture_output=True, text=True, check=True).stdout
    steps = [tuple(float(g) for g in STEP.search(l).groups()) for l in out.splitlines() if l.startswith("t=")]
    half = float(re.search(r"half width ([\d.]+)", out).group(1))
    first = next((s for s in steps if s[2] > 0), None)
    if first is None:
        return None
    side = 1.0 if first[1] > first[0] else -1.0
    return {"side": side, "room": half - side * first[0], "edge": 1.0 if steps[-1][0] > 0 else -1.0}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("episodes", nargs="+")
    ap.add_argument("--config", default='{"preset":"picopinn","clock":"simulated"}')
    ap.add_argument("--scenarios", default="data/scenarios.jsonl")
    a = ap.parse_args()
    if not os.path.exists(TRACE):
        raise SystemExit(f"{TRACE} is missing: cargo build --release -p picopit-sim --example trace_episode")
    params = {k: v["params"] for k, v in load_scenarios(a.scenarios).items()}
    rows = [r for r in load_episodes(a.episodes) if r["impact"] is not None]
    for r in rows:
        r["spun"] = r["reversed"] is not None
    with ThreadPoolExecutor(2) as ex:
        traced = list(ex.map(lambda r: trace(r["id"], a.config), rows))
    for r, t in zip(rows, traced):
        r.update(t or {})
    rows = [r for r in rows if "side" in r]
    over = [r for r in rows if r["spun"] and r["cause"] == "boundary_violation" and r["vehicle"] == "Target"]
    same = sum(r["edge"] == r["side"] for r in over)
    print(f"spun targets over an edge: {len(over)}; on the bullet's side {same}, on the far side {len(over) - same}")
    print("\nfull-size episodes with a contact, by the road on the bullet's side at the first contact")
    print("| room (m) | episodes | successes | target over an edge |\n|---|---|---|---|")
    groups = collections.defaultdict(list)
    for r in rows:
        if params[r["id"]] == "full_size":
            groups[next(k for k in ((0, 5), (5, 8), (8, 1e9)) if k[0] <= r["room"] < k[1])].append(r)
    for (lo, hi), g in sorted(groups.items()):
        label = f"≥ {lo}" if hi > 1e8 else f"{lo}–{hi}"
        print(f"| {label} | {len(g)} | {sum(r['cause'] == 'success' for r in g)} | "
              f"{sum(r['cause'] == 'boundary_violation' and r['vehicle'] == 'Target' for r in g)} |")


if __name__ == "__main__":
    main()
