#!/usr/bin/env python3
"""Tabulate closed-loop episodes by where the first contact landed, how fast it was, and what
the target did once spun round (docs/planner.md, "What happens after the spin").

Input: the lines printed by `./target/release/examples/episodes CONFIG FIRST COUNT` (any
number of files), and the scenario file for the target driver, road and speed.

    python3 scripts/failure_map.py EPISODES.txt [...] [--scenarios data/scenarios.jsonl]
"""
import argparse
import collections
import json
import statistics


def parse(line):
    """One line of the `episodes` example as a dict (ValueError if it is not one)."""
    if "| impact " not in line or "| reversed " not in line:
        raise ValueError("no '| impact' and '| reversed' fields (output of an older `episodes` example?)")
    f = line.split()
    row = {"id": f[0], "category": f[1], "adhesion": f[2], "cause": f[3]}
    row["vehicle"] = f[4] if f[4] in ("Target", "Bullet") else ""
    row["contacts"] = int(f[f.index("contacts") + 1])
    row["herr"] = float(f[f.index("herr") + 1])
    row["at"] = float(f[f.index("at") + 1])
    imp = line.split("| impact ")[1].split(" |")[0].split()
    row["impact"] = None if imp == ["-"] else (float(imp[1]), float(imp[3]), float(imp[5]))
    rev = line.split("| reversed ")[1].split()
    row["reversed"] = None if rev == ["-"] else (float(rev[1]), float(rev[3]))
    return row


def bucket(v, edges):
    for e in edges:
        if v < e:
            return f"< {e}"
    return f">= {edges[-1]}"


def table(title, rows, key, order=None):
    groups = collections.defaultdict(list)
    for r in rows:
        k = key(r)
        if k is not None:
            groups[k].append(r["cause"] == "success")
    keys = order or sorted(groups)
    print(f"\n{title}\n| group | episodes | success % |\n|---|---|---|")
    for k in keys:
        if k in groups:
            g = groups[k]
            print(f"| {k} | {len(g)} | {100.0 * sum(g) / len(g):.0f} |")


def load_scenarios(path):
    """Scenario id -> scenario of a dataset file."""
    with open(path) as f:
        return {j["id"]: j for j in map(json.loads, f)}


def load_episodes(paths):
    """The episode lines (`sc-...`) of the files, parsed; a line that does not parse stops the
    script with its file and line number."""
    rows = []
    for path in paths:
        with open(path) as f:
            for n, line in enumerate(f, 1):
                if line.startswith("sc-"):
                    try:
                        rows.append(parse(line))
                    except (ValueError, IndexError) as e:
                        raise SystemExit(f"{path}:{n}: not an `episodes` line: {e}")
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("episodes", nargs="+")
    ap.add_argument("--scenarios", default="data/scenarios.jsonl")
    a = ap.parse_args()
    sc = load_scenarios(a.scenarios)
    rows = load_episodes(a.episodes)
    for r in rows:
        s = sc[r["id"]]
        r["driver"] = s["driver"]["kind"]
        r["v0"] = (s["target"]["vx"] ** 2 + s["target"]["vy"] ** 2) ** 0.5
        r["params"] = s["params"]
    ok = sum(r["cause"] == "success" for r in rows)
    print(f"{len(rows)} episodes, {ok} successes ({100.0 * ok / len(rows):.1f} %)")
    hit = [r for r in rows if r["impact"] is not None]
    print(f"{len(hit)} with a contact, {sum(r['cause'] == 'success' for r in hit)} of them successes")
    edges_x = [-2.2, -2.0, -1.8, -1.6, -1.4, -1.0]
    table("First contact point along the target (body x, m; the rear bumper is at -2.39, the rear axle at -1.42)",
          hit, lambda r: bucket(r["impact"][0], edges_x),
          [f"< {e}" for e in edges_x] + [f">= {edges_x[-1]}"])
    edges_v = [1, 2, 3, 4, 5]
    table("Relative speed at the first contact (m/s)", hit, lambda r: bucket(r["impact"][2], edges_v),
          [f"< {e}" for e in edges_v] + [f">= {edges_v[-1]}"])
    edges_t = [8, 12, 16, 20, 25]
    table("Target speed at the start (m/s), episodes with a contact", hit,
          lambda r: bucket(r["v0"], edges_t), [f"< {e}" for e in edges_t] + [f">= {edges_t[-1]}"])
    table("Target driver, episodes with a contact", hit, lambda r: r["driver"])

    # After the spin: episodes whose target reached the reversed heading after a contact.
    spun = [r for r in hit if r["reversed"] is not None]
    print(f"\nTargets spun round (within eps_psi of the reversed heading after a contact): {len(spun)}")
    print("| outcome | episodes | speed kept at reversal, median (quartiles) | s from reversal to the decision, median |")
    print("|---|---|---|---|")
    out = collections.defaultdict(list)
    for r in spun:
        name = r["cause"] if r["cause"] != "success" else "success"
        if r["cause"] in ("boundary_violation", "secondary_collision"):
            name += f" ({r['vehicle'].lower()})"
        out[name].append(r)
    for name, g in sorted(out.items(), key=lambda kv: -len(kv[1])):
        kept = sorted(r["reversed"][1] / r["v0"] for r in g if r["v0"] > 0)
        q = statistics.quantiles(kept, n=4) if len(kept) >= 2 else [kept[0]] * 3
        dt = statistics.median(r["at"] - r["reversed"][0] for r in g)
        print(f"| {name} | {len(g)} | {statistics.median(kept):.2f} ({q[0]:.2f}–{q[2]:.2f}) | {dt:.1f} |")
    table("Spun targets by road", spun, lambda r: r["category"])
    table("Spun targets by driver", spun, lambda r: r["driver"])


if __name__ == "__main__":
    main()
