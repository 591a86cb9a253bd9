#!/usr/bin/env python3
"""The push the bullet delivers in the PIT phase, by road adhesion: over the full-size
scenes in a range, the mean contact normal force and the mean torque command of the control
steps that are in the PIT phase and in contact (negative torque brakes).

    .venv/bin/python scripts/push_by_mu.py --scenes 0:192 --config picopinn
"""
import argparse
import json
import sys

import numpy as np

import picopit

BANDS = [(0.0, 0.4, "low"), (0.4, 0.7, "mid"), (0.7, 10.0, "high")]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default="data/scenarios.jsonl")
    ap.add_argument("--models", default="models")
    ap.add_argument("--scenes", default="0:192", help="FIRST:END of the file's scenes")
    ap.add_argument("--config", default="picopinn", help="episode preset")
    args = ap.parse_args()
    try:
        first, end = (int(v) for v in args.scenes.split(":"))
        if not 0 <= first < end:
            raise ValueError
    except ValueError:
        print(f"push_by_mu: --scenes {args.scenes!r} is not FIRST:END", file=sys.stderr)
        return 2
    try:
        with open(args.data, encoding="utf-8") as f:
            lines = f.read().splitlines()[first:end]
    except OSError as e:
        print(f"push_by_mu: {e}", file=sys.stderr)
        return 1
    cols = {c: i for i, c in enumerate(picopit.trajectory_columns())}
    cfg = json.dumps({"preset": args.config, "clock": "simulated"})
    rows = []
    for n, line in enumerate(lines, first + 1):
        try:
            sc = json.loads(line)
            r = picopit.run_episode(line, cfg, 0, True, args.models)
        except (ValueError, picopit.EpisodeError, picopit.ScenarioError) as e:
            print(f"push_by_mu: {args.data} line {n}: {e}", file=sys.stderr)
            return 1
        if sc["params"] != "full_size":
            continue
        tr = np.asarray(r["trajectory"])
        pit = (tr[:, cols["phase"]] == 1) & (tr[:, cols["contact_fn"]] > 0)
        if pit.any():
            rows.append((sc["mu"], tr[pit, cols["contact_fn"]].mean(), tr[pit, cols["cmd_torque"]].mean()))
    print("| adhesion | episodes | mean μ | mean F_n in PIT contact (N) | mean torque command (N m) |")
    print("|---|---|---|---|---|")
    for lo, hi, name in BANDS:
        sel = np.array([r for r in rows if lo <= r[0] < hi]).reshape(-1, 3)
        if len(sel):
            print(f"| {name} | {len(sel)} | {sel[:, 0].mean():.2f} | {sel[:, 1].mean():.0f} | {sel[:, 2].mean():.0f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
