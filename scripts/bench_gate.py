#!/usr/bin/env python3
"""Compare criterion medians against the thresholds in benches/thresholds.toml.

Reads target/criterion/<group>/<bench>/new/{estimates,sample}.json (written by
`cargo bench`), prints a table (median, p99 over criterion's samples, threshold, ratio) of
every bench found and exits 1 if a gated median exceeds its threshold or a gated bench has
no result. Standard library only.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

try:
    import tomllib
except ModuleNotFoundError:  # Python < 3.11
    import tomli as tomllib  # type: ignore[no-redef]

ROOT = Path(__file__).resolve().parent.parent


def fmt_ns(ns: float) -> str:
    for unit, scale in (("s", 1e9), ("ms", 1e6), ("µs", 1e3)):
        if ns >= scale:
            return f"{ns / scale:.3g} {unit}"
    return f"{ns:.3g} ns"


def p99(sample_file: Path) -> float:
    """99th percentile of criterion's per-sample mean iteration times (ns)."""
    sample = json.loads(sample_file.read_text())
    per_iter = sorted(t / n for t, n in zip(sample["times"], sample["iters"]))
    k = min(len(per_iter) - 1, round(0.99 * (len(per_iter) - 1)))
    return per_iter[k]


def main() -> int:
    spec = tomllib.loads((ROOT / "benches" / "thresholds.toml").read_text())
    thresholds: dict[str, float] = spec["thresholds"]
    criterion = ROOT / "target" / "criterion"
    found = sorted(
        str(p.parent.parent.relative_to(criterion))
        for p in criterion.glob("**/new/estimates.json")
        if "report" not in p.parts
    ) if criterion.is_dir() else []
    failed = False
    print(f"{'bench':<46} {'median':>10} {'p99':>10} {'threshold':>10} {'ratio':>6}")
    for bench in sorted(set(found) | set(thresholds)):
        threshold = thresholds.get(bench)
        shown = fmt_ns(threshold) if threshold else "-"
        path = criterion / bench / "new" / "estimates.json"
        if not path.is_file():
            print(f"{bench:<46} {'missing':>10} {'':>10} {shown:>10}        FAIL (no result)")
            failed = True
            continue
        median = json.loads(path.read_text())["median"]["point_estimate"]
        tail = p99(path.with_name("sample.json"))
        if threshold is None:
            print(f"{bench:<46} {fmt_ns(median):>10} {fmt_ns(tail):>10} {shown:>10}")
            continue
        ratio = median / threshold
        verdict = "ok" if median <= threshold else "FAIL"
        failed |= median > threshold
        print(f"{bench:<46} {fmt_ns(median):>10} {fmt_ns(tail):>10} {shown:>10} {ratio:6.2f} {verdict}")
    if failed:
        print("bench gate: FAILED (a median exceeds its threshold in benches/thresholds.toml)")
        return 1
    print("bench gate: all medians within their thresholds")
    return 0


if __name__ == "__main__":
    sys.exit(main())
