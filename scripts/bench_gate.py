#!/usr/bin/env python3
"""Gate criterion medians against benches/thresholds.toml, as ratios to a reference.

Every bench binary measures `reference/<binary>` (crates/bench_ref: a fixed workload) before
its own benches and `reference/<binary>_end` after them. A gate judges a bench by the ratio
of its median to the slower of the two, measured in the same run, so that a slower or busier
machine cancels out: the ratio must stay within `margin` (1.5) times the ratio recorded in the file.
A bench whose time is not CPU work (the IPC wake-up) is gated on an absolute median instead.

Reads target/criterion/<group>/<bench>/new/{estimates,sample}.json (written by
`cargo bench`), prints every bench found (median, p99 over criterion's samples, its ratio to
its reference, the limit) and exits 1 if a gated bench exceeds its limit or has no result.
`--record` prints the measured ratios as the file's [gates] table instead of gating, for
after an intended change of performance. `--failing` prints, per bench binary, a criterion
filter for the benches that fail and their references: scripts/bench.sh re-runs those once
before it fails (on a shared machine a neighbour's burst can slow one bench and neither
reference), so a gate fails only when it fails twice. Standard library only (plus tomli before 3.11).
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from dataclasses import dataclass
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


@dataclass(frozen=True)
class Result:
    median: float
    p99: float


def read(criterion: Path, bench: str) -> Result | None:
    path = criterion / bench / "new" / "estimates.json"
    if not path.is_file():
        return None
    median = json.loads(path.read_text())["median"]["point_estimate"]
    sample = json.loads(path.with_name("sample.json").read_text())
    per_iter = sorted(t / n for t, n in zip(sample["times"], sample["iters"]))
    k = min(len(per_iter) - 1, round(0.99 * (len(per_iter) - 1)))
    return Result(median, per_iter[k])


class SpecError(ValueError):
    """benches/thresholds.toml is malformed: the message names the gate and field."""


@dataclass(frozen=True)
class Gate:
    reference: str | None
    ratio: float | None
    absolute_ns: float | None

    @staticmethod
    def parse(name: str, raw: object) -> "Gate":
        if not isinstance(raw, dict):
            raise SpecError(f"gates.{name!r}: must be a table")
        unknown = set(raw) - {"reference", "ratio", "absolute_ns"}
        if unknown:
            raise SpecError(f"gates.{name!r}: unknown field {sorted(unknown)[0]!r}")
        for field in ("ratio", "absolute_ns"):
            v = raw.get(field)
            if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float)) or not v > 0):
                raise SpecError(f"gates.{name!r}.{field} = {v!r}: must be a positive number")
        if ("ratio" in raw) == ("absolute_ns" in raw):
            raise SpecError(f"gates.{name!r}: give exactly one of `ratio` (with `reference`) or `absolute_ns`")
        if "ratio" in raw and not isinstance(raw.get("reference"), str):
            raise SpecError(f"gates.{name!r}.reference: a ratio needs the reference bench it is measured against")
        return Gate(raw.get("reference"), raw.get("ratio"), raw.get("absolute_ns"))


def load_spec(path: Path) -> tuple[float, dict[str, Gate]]:
    spec = tomllib.loads(path.read_text())
    margin = spec.get("margin")
    if isinstance(margin, bool) or not isinstance(margin, (int, float)) or not margin >= 1:
        raise SpecError(f"margin = {margin!r}: must be a number ≥ 1")
    gates = spec.get("gates")
    if not isinstance(gates, dict) or not gates:
        raise SpecError("gates: missing or empty")
    return float(margin), {name: Gate.parse(name, raw) for name, raw in gates.items()}


def reference(criterion: Path, name: str) -> Result | None:
    """The reference measured before a binary's benches and, if present, after them
    (`<name>_end`): the slower of the two, so that load over the binary's run is counted."""
    start, end = read(criterion, name), read(criterion, name + "_end")
    if start is None or end is None:
        return start or end
    return max(start, end, key=lambda r: r.median)


def found_benches(criterion: Path) -> list[str]:
    if not criterion.is_dir():
        return []
    return sorted(
        str(p.parent.parent.relative_to(criterion))
        for p in criterion.glob("**/new/estimates.json")
        if "report" not in p.parts
    )


def judge(criterion: Path, margin: float, gates: dict[str, Gate], verbose: bool = True) -> list[str]:
    """Print the table (if `verbose`) and return the gated benches over their limit or
    without a result."""
    failing: list[str] = []
    say = print if verbose else (lambda *a, **k: None)
    say(f"{'bench':<44} {'median':>9} {'p99':>9} {'ratio':>8} {'limit':>9}  verdict")
    for bench in sorted(set(found_benches(criterion)) | set(gates)):
        g = gates.get(bench)
        r = read(criterion, bench)
        if r is None:
            say(f"{bench:<44} {'missing':>9}{'':>30}  FAIL (no result)")
            failing.append(bench)
            continue
        if g is None:
            say(f"{bench:<44} {fmt_ns(r.median):>9} {fmt_ns(r.p99):>9}")
            continue
        if g.absolute_ns is not None:
            ok = r.median <= g.absolute_ns
            say(f"{bench:<44} {fmt_ns(r.median):>9} {fmt_ns(r.p99):>9} {'':>8} "
                f"{fmt_ns(g.absolute_ns):>9}  {'ok' if ok else 'FAIL'}")
        else:
            ref = reference(criterion, g.reference)
            if ref is None:
                say(f"{bench:<44} {fmt_ns(r.median):>9} {fmt_ns(r.p99):>9}{'':>20}  "
                    f"FAIL (no result for its reference {g.reference})")
                failing.append(bench)
                continue
            ratio = r.median / ref.median
            limit = margin * g.ratio
            ok = ratio <= limit
            say(f"{bench:<44} {fmt_ns(r.median):>9} {fmt_ns(r.p99):>9} {ratio:>8.4g} "
                f"{limit:>9.4g}  {'ok' if ok else 'FAIL'}")
        if not ok:
            failing.append(bench)
    return failing


def gate(criterion: Path, margin: float, gates: dict[str, Gate]) -> int:
    if judge(criterion, margin, gates):
        print("bench gate: FAILED (see the rows marked FAIL; benches/thresholds.toml says how the limits are set)")
        return 1
    print("bench gate: every gated bench within its limit")
    return 0


def binary_of(bench: str, g: Gate) -> str:
    """The bench binary that measures a gated bench: its reference's (`reference/<binary>`),
    or for an absolute gate its group's name."""
    if g.reference is not None:
        return g.reference.removeprefix("reference/")
    return bench.split("/", 1)[0]


def failing(criterion: Path, margin: float, gates: dict[str, Gate]) -> int:
    """Print one line per bench binary with a failing gate: the binary and a criterion filter
    (a regex) for those benches and the binary's two references, for a re-run."""
    by_binary: dict[str, list[str]] = {}
    for bench in judge(criterion, margin, gates, verbose=False):
        binary = binary_of(bench, gates[bench])
        by_binary.setdefault(binary, []).append(bench)
    for binary, benches in sorted(by_binary.items()):
        names = benches + [f"reference/{binary}", f"reference/{binary}_end"]
        print(binary, "^(" + "|".join(re.escape(n) for n in names) + ")$")
    return 0


def record(criterion: Path, gates: dict[str, Gate]) -> int:
    """Print the measured ratios as a [gates] table (absolute gates kept as they are)."""
    missing = 0
    for bench, g in sorted(gates.items()):
        if g.absolute_ns is not None:
            print(f'[gates."{bench}"]\nabsolute_ns = {g.absolute_ns:.0f}\n')
            continue
        r, ref = read(criterion, bench), reference(criterion, g.reference)
        if r is None or ref is None:
            print(f"# {bench}: no result for it or its reference {g.reference}", file=sys.stderr)
            missing += 1
            continue
        print(f'[gates."{bench}"]\nreference = "{g.reference}"\nratio = {r.median / ref.median:.4g}'
              f"  # median {fmt_ns(r.median)}, reference {fmt_ns(ref.median)}\n")
    return 1 if missing else 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spec", type=Path, default=ROOT / "benches" / "thresholds.toml")
    ap.add_argument("--criterion", type=Path, default=ROOT / "target" / "criterion",
                    help="criterion's output folder (default target/criterion)")
    ap.add_argument("--record", action="store_true",
                    help="print the measured ratios as a [gates] table instead of gating")
    ap.add_argument("--failing", action="store_true",
                    help="print, per bench binary with a failing gate, the binary and a criterion "
                         "filter for a re-run of those benches and its references")
    args = ap.parse_args(argv)
    try:
        margin, gates = load_spec(args.spec)
    except (OSError, tomllib.TOMLDecodeError, SpecError) as e:
        print(f"bench gate: {args.spec}: {e}", file=sys.stderr)
        return 2
    if args.record:
        return record(args.criterion, gates)
    if args.failing:
        return failing(args.criterion, margin, gates)
    return gate(args.criterion, margin, gates)


if __name__ == "__main__":
    sys.exit(main())
