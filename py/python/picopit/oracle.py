"""``picopit oracle``: the ideal-PIT bound, a physics ceiling for the benchmark.

For each scenario the target runs alone on the plant under its driver; at every candidate
contact time from the bullet's earliest arrival on, on either side, its rear quarter gets one
instantaneous lateral shove of each size of the grid (a velocity change ``dv`` of its c.g.),
and the plant runs on to ``T_max`` with the driver reacting. The scenario is *ideally
feasible* when one shove ends in success by the benchmark's own test (``sim::oracle``, the
Rust core; ``_core.ideal_pit``). A shove counts only from a side where a bullet fits beside
the target, inside the road and clear of the obstacles (setting ``bullet_beside``, default
true). The bound is optimistic
about the bullet (at its pose at once) and restrictive about the push (one impulse, no
sustained push).

With ``tiers`` the whole grid is simulated twice, with the driver's true law and with its
command held from the shove on, and eight choices are judged in the truth
(``_core.oracle_tier_names()``): ``ideal``; ``robust-t``/``-v``/``-tv`` (the shove succeeds
with its neighbours ±1 time step, ±1 size step, or both); ``ideal-exp`` (expected success
when the push lands anywhere in the 3 × 3 box of the best shove); ``held-first``,
``held-robust``, ``held-exp`` (the choice of a planner that sees only the driver's current
command). Each scene takes a few seconds (tiers: the whole grid twice, far longer).

With ``sides`` (``--sides-of RUN``) each scene that a benchmark run's controller pushed is
tried only on the side it pushed from (the sign of its first contact's ``impact_y``, the
target's body frame, y to the left): the bound of a controller that keeps its choice of side,
which says whether a scene it lost was lost to its side or to its push.

The scenes run on threads (the core releases the GIL), in scene order in the results.
"""

from __future__ import annotations

import json
import math
from collections import OrderedDict
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, Iterator, List, Mapping, Optional, Sequence, Tuple

from . import _core

#: The groups of the summary table: scenario field -> label.
GROUPS = (("category", "category"), ("adhesion", "adhesion"), ("driver", "driver"), ("params", "params"))
#: The grid of ``--tiers`` unless settings are given: ten sizes 0.4-3.15 m/s (steps of
#: ×1.25), a candidate time every 0.1 s.
TIER_SETTINGS = {"shoves": [0.4, 0.5, 0.63, 0.8, 1.0, 1.25, 1.6, 2.0, 2.5, 3.15], "time_step": 0.1}


class OracleError(ValueError):
    """Bad oracle input: settings, a scene selection or a scenario file."""


@dataclass
class OracleRun:
    """One oracle run: per scene its labels and the core's result (``ideal_pit`` or
    ``oracle_tiers``), or ``error``."""

    tiers: bool
    settings: Dict[str, Any]
    scenes: List[Dict[str, Any]] = field(default_factory=list)

    @property
    def names(self) -> List[str]:
        """The columns of the summary: ``feasible``, or the tier names."""
        return list(_core.oracle_tier_names()) if self.tiers else ["feasible"]

    def values(self, scene: Mapping[str, Any]) -> List[float]:
        """The scene's chance of success per column (0 or 1; a share for the ``-exp`` tiers)."""
        r = scene["result"]
        if self.tiers:
            return [float(r["tiers"][n]) for n in self.names]
        return [1.0 if r["feasible"] else 0.0]

    def summary(self) -> "OrderedDict[str, Dict[str, Any]]":
        """Per group (``all``, then each category, adhesion band, driver and parameter set): the
        number of scenes and the share (%) per column; scenes that errored are left out."""
        groups: "OrderedDict[str, Dict[str, Any]]" = OrderedDict()
        ok = [s for s in self.scenes if s.get("error") is None]
        keys = [("all", lambda s: "all")]
        keys += [(label, lambda s, k=k, label=label: f"{label} {s[k]}") for k, label in GROUPS]
        for _, key in keys:
            for s in sorted(ok, key=key):
                g = groups.setdefault(key(s), {"n": 0, "sum": [0.0] * len(self.names)})
                g["n"] += 1
                g["sum"] = [a + b for a, b in zip(g["sum"], self.values(s))]
        for g in groups.values():
            g["share"] = {n: 100.0 * v / g["n"] for n, v in zip(self.names, g.pop("sum"))}
        return groups

    def markdown(self) -> str:
        names = self.names
        head = "| group | scenes | " + " | ".join(names) + " |\n|---|---:|" + "---:|" * len(names) + "\n"
        rows = [f"| {k} | {g['n']} | " + " | ".join(f"{g['share'][n]:.1f} %" for n in names) + " |"
                for k, g in self.summary().items()]
        return head + "\n".join(rows) + "\n"

    def line(self, scene: Mapping[str, Any]) -> str:
        """One line on a scene's result."""
        if scene.get("error") is not None:
            return f"{scene['id']}: error: {scene['error']}"
        r = scene["result"]
        if self.tiers:
            return (f"{scene['id']} true share {r['true_share']:.3f}, held share {r['held_share']:.3f} | "
                    + " ".join(f"{n}={r['tiers'][n]:.2f}" for n in self.names))
        if r["feasible"]:
            f = r["shove"]
            side = "left" if f["side"] > 0 else "right"
            return (f"{scene['id']} feasible: shove at {f['time']:.2f} s on the {side}, "
                    f"dv {f['dv']:.2f} m/s -> success at {f['decided_at']:.2f} s "
                    f"({'at rest' if f['at_rest'] else 'settled'}) | reach {r['t_reach']:.2f} s, tried {r['tried']}")
        alone = r["alone_fails_at"]
        return (f"{scene['id']} infeasible | reach {r['t_reach']:.2f} s, tried {r['tried']}, alone "
                + (f"fails at {alone:.2f} s" if alone is not None else "does not fail"))

    def to_json(self) -> Dict[str, Any]:
        return {"tiers": self.tiers, "settings": self.settings, "columns": self.names,
                "summary": self.summary(), "scenes": self.scenes}


def resolve_settings(text: Optional[str], tiers: bool) -> Dict[str, Any]:
    """The settings (JSON text over the defaults; ``--tiers`` starts from ``TIER_SETTINGS``),
    validated by the core; raises :class:`OracleError` naming the field."""
    base: Dict[str, Any] = dict(TIER_SETTINGS) if tiers else {}
    if text:
        try:
            over = json.loads(text)
        except ValueError as e:
            raise OracleError(f"--settings: not JSON: {e}") from None
        if not isinstance(over, dict):
            raise OracleError("--settings: expected a JSON object, e.g. '{\"shoves\": [1, 2]}'")
        base.update(over)
    try:
        return dict(_core.oracle_settings(json.dumps(base)))
    except _core.ScenarioError as e:
        raise OracleError(f"--settings: {e}") from None


def select(scenarios: Sequence[Mapping[str, Any]], first: int = 0, n: Optional[int] = None,
           ids: Optional[Sequence[str]] = None, subset: Optional[int] = None) -> List[Mapping[str, Any]]:
    """Scenes ``first .. first + n`` of the file, those named by ``ids`` (in the given order), or
    the benchmark's stratified ``subset`` of that many scenes (``bench.stratified_subset``, as
    ``picopit bench`` picks them); raises :class:`OracleError` for an unknown id, a bad size or
    an empty selection."""
    if subset is not None:
        if subset < 1:
            raise OracleError(f"--subset {subset}: need at least 1 scene")
        from .bench import stratified_subset

        return [scenarios[i] for i in stratified_subset(scenarios, subset)]
    if ids:
        by_id = {s["id"]: s for s in scenarios}
        missing = [i for i in ids if i not in by_id]
        if missing:
            raise OracleError(f"--ids: not in the scenario file: {', '.join(missing)}")
        return [by_id[i] for i in ids]
    if first < 0 or (n is not None and n < 1):
        raise OracleError(f"--first {first}, --n {n}: need --first >= 0 and --n >= 1")
    chosen = list(scenarios[first:] if n is None else scenarios[first:first + n])
    if not chosen:
        raise OracleError(f"--first {first}: the file has {len(scenarios)} scenes")
    return chosen


def contact_rows(run: Path, config: str, option: str,
                 extra: Sequence[str] = ()) -> Iterator[Tuple[Dict[str, Any], float]]:
    """The rows of configuration ``config`` in a benchmark run (its folder or episodes file)
    whose first contact had a side, with that side (+1 where ``impact_y`` > 0, the target's
    left; -1 on its right); rows without a contact are skipped. Reads the columns ``config``,
    ``scenario``, ``impact_y`` and ``extra``. Raises :class:`OracleError` naming ``option``
    for a run without the columns, without ``config``, or with a malformed ``impact_y``
    (naming the row)."""
    from .compare import CompareError, episodes_file, read_rows

    try:
        path = episodes_file(Path(run))
        rows = read_rows(path, ("config", "scenario", "impact_y", *extra))
    except CompareError as e:
        raise OracleError(f"{option}: {e}") from None
    found = False
    for i, r in enumerate(rows, start=1):
        if str(r["config"]) != config:
            continue
        found = True
        y = r["impact_y"]
        if y is None or y == "":
            continue
        try:
            y = float(y)  # type: ignore[arg-type]
        except (TypeError, ValueError):
            raise OracleError(f"{option}: {path}: row {i}: impact_y {y!r} is not a number") from None
        if math.isfinite(y) and y != 0.0:
            yield r, (1.0 if y > 0.0 else -1.0)
    if not found:
        configs = sorted({str(r["config"]) for r in rows})
        raise OracleError(f"--config {config}: not in {path} (it has {', '.join(configs) or 'no rows'})")


def sides_of(run: Path, config: str) -> Dict[str, float]:
    """``{scene: side}`` of the scenes that configuration ``config`` of a benchmark run (its
    folder or episodes file) pushed, by their first contact (:func:`contact_rows`)."""
    return {str(r["scenario"]): side for r, side in contact_rows(run, config, "--sides-of")}


def run(scenes: Sequence[Mapping[str, Any]], settings: Mapping[str, Any], tiers: bool = False,
        workers: int = 1, progress: bool = True, sides: Optional[Mapping[str, float]] = None) -> OracleRun:
    """The oracle (``tiers``: its tiers) on each scene, ``workers`` scenes at a time; a scene
    in ``sides`` (:func:`sides_of`) is tried on that side only, and its row says so
    (``"sides"``)."""
    text = json.dumps(dict(settings))
    fn = _core.oracle_tiers if tiers else _core.ideal_pit
    out = OracleRun(tiers=tiers, settings=dict(settings))

    def one(sc: Mapping[str, Any]) -> Dict[str, Any]:
        row = {"id": sc["id"], "category": sc.get("category"), "adhesion": sc.get("adhesion"),
               "driver": (sc.get("driver") or {}).get("kind"), "params": sc.get("params"),
               "result": None, "error": None}
        own = text
        if sides is not None and sc["id"] in sides:
            row["sides"] = [sides[sc["id"]]]
            own = json.dumps({**dict(settings), "sides": row["sides"]})
        try:
            row["result"] = dict(fn(json.dumps(dict(sc)), own))
        except (_core.ScenarioError, ValueError) as e:
            row["error"] = str(e)
        return row

    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(scenes), unit="scene", desc="oracle" + (" tiers" if tiers else ""))
    with ThreadPoolExecutor(max_workers=max(1, workers)) as pool:
        for row in pool.map(one, scenes):
            out.scenes.append(row)
            if bar is not None:
                feasible = sum(1 for s in out.scenes if s["result"] and out.values(s)[0] > 0)
                bar.set_postfix_str(f"ideal {feasible}/{len(out.scenes)}")
                bar.update()
    if bar is not None:
        bar.close()
    return out


def write_json(res: OracleRun, path: Path) -> Path:
    path = Path(path)
    path.write_text(json.dumps(res.to_json(), indent=1) + "\n")
    return path
