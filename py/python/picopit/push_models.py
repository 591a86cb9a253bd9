"""``picopit push-models RUN``: how well the target models, and the plans, predicted the pushes
a benchmark run delivered.

For a seeded random sample of the run's episodes of one configuration that touched the target,
the episode is traced again (``picopit trace``, simulated clock) and its first push checked as
:meth:`picopit.trace.Trace.push_models` does: the 4-DOF model, the PINN and the PicoPINN
stepped through the push as it happened (the recorded contact of every step and the recorded
driver commands, from the state before the contact), and the plan made before the contact.
For the pushes that turned the target more than ``min_turn``, the turn each predicts at the
push's end is divided by the truth's; the report gives the median and the 10 and 90 %
quantiles of that ratio per source, and how often the plan was off by more than half the
turn either way; and what the bullet delivered (the impact in the push's first 0.15 s, the
median force after it, the peak, the contact point along the target). A model near 1 with the plan far from it says the plans' errors are the
planned push's, not the model's (``docs/planner.md``, Limits).
"""

from __future__ import annotations

import math
import random
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any, Dict, List, Optional

import numpy as np

from . import _core
from .compare import CompareError, episodes_file, read_rows
from .trace import TraceError, trace

#: The sources set against the truth, in report order.
SOURCES = ("picopinn", "pinn", "4dof", "plan")


def _has_contact(v: object) -> bool:
    if v is None:
        return False
    if isinstance(v, str):
        return bool(v.strip())
    return not (isinstance(v, float) and math.isnan(v))


def sample_scenes(run: Path, config: str, params: str, n: int, seed: int) -> List[str]:
    """Up to ``n`` scene ids, drawn with ``seed``, of the run's episodes of ``config`` and
    ``params`` with a contact (sorted draw: the same run, n and seed give the same scenes)."""
    try:
        rows = read_rows(episodes_file(Path(run)), ("config", "scenario", "params", "contact_at"))
    except CompareError as e:
        raise TraceError(str(e)) from None
    ids = sorted({str(r["scenario"]) for r in rows if str(r["config"]) == config
                  and str(r["params"]) == params and _has_contact(r["contact_at"]) and not r.get("error")})
    if not ids:
        raise TraceError(f"{run}: no episode of configuration {config} ({params}) touched the target")
    return sorted(random.Random(seed).sample(ids, min(n, len(ids))))


def survey(run: Path, scenarios: Path, config: str = "picopinn", params: str = "full_size", n: int = 300,
           seed: int = 1, models: Path = Path("models"), workers: int = 2, min_turn: float = math.radians(10.0),
           progress: bool = True) -> Dict[str, Any]:
    """Trace the sampled episodes and summarise their first pushes (module docstring).

    Returns ``scenes`` (traced), ``turned`` (pushes that turned the target more than
    ``min_turn``), ``sources``: per source ``n`` (ratios), ``median``, ``p10``, ``p90`` of
    the predicted turn over the truth's at the push's end, and for the plan ``over`` and
    ``under`` (ratio above 1.5, below 0.5); ``delivered``: median, 10 and 90 % over the
    pushes of ``impact``, ``sustained``, ``peak`` (N s, N) and ``point_x`` (m);
    ``pushes``: one dict per traced push."""
    if n < 1:
        raise TraceError(f"--n {n}: need at least 1")
    if workers < 1:
        raise TraceError(f"--workers {workers}: need at least 1")
    ids = sample_scenes(run, config, params, n, seed)
    try:
        scenes = {s["id"]: dict(s) for s in _core.load_scenarios(str(scenarios))}
    except _core.ScenarioError as e:
        raise TraceError(f"{scenarios}: {e}") from None
    missing = [i for i in ids if i not in scenes]
    if missing:
        raise TraceError(f"{scenarios}: no scene {missing[0]} of the run (the run's scenario file?)")

    def one(sid: str) -> Optional[Dict[str, Any]]:
        pm = trace(scenes[sid], config, models=models).push_models(models)
        if pm is None:
            return None
        end = pm["rows"][0]
        return {"scene": sid, "truth": end["truth"][0], "impulse": pm["impulse"], "point_x": pm["point_x"],
                "impact": pm["impact"], "sustained": pm["sustained"], "peak": pm["peak"],
                **{k: (None if end.get(k) is None else end[k][0]) for k in SOURCES}}

    from tqdm import tqdm

    bar = tqdm(total=len(ids), desc="push-models", unit="episode", leave=False, dynamic_ncols=True,
               disable=None) if progress else None
    pushes: List[Dict[str, Any]] = []
    # The core releases the GIL while an episode runs: threads run episodes side by side.
    with ThreadPoolExecutor(max_workers=workers) as pool:
        for got in pool.map(one, ids):
            if got is not None:
                pushes.append(got)
            if bar is not None:
                bar.update(1)
    if bar is not None:
        bar.close()
    turned = [p for p in pushes if abs(p["truth"]) > min_turn]
    sources: Dict[str, Dict[str, Any]] = {}
    for k in SOURCES:
        r = np.array([p[k] / p["truth"] for p in turned if p[k] is not None])
        s: Dict[str, Any] = {"n": int(r.size), **(_quantiles(r) or {})}
        if k == "plan":
            s.update(over=int((r > 1.5).sum()), under=int((r < 0.5).sum()))
        sources[k] = s
    delivered = {k: _quantiles(np.array([p[k] for p in pushes if p[k] is not None]))
                 for k in ("impact", "sustained", "peak", "point_x")}
    return {"run": str(run), "config": config, "params": params, "n": n, "seed": seed,
            "scenes": len(ids), "pushes": pushes, "turned": len(turned), "sources": sources,
            "delivered": delivered}


def lines(result: Dict[str, Any]) -> List[str]:
    """The survey as text."""
    out = [f"{result['config']} ({result['params']}): {result['scenes']} episodes with a contact sampled "
           f"(seed {result['seed']}), {result['turned']} first pushes turned the target more than 10 deg",
           "turn at the push's end as a multiple of the truth's (the models given the delivered push; "
           "the plan made before the contact, given its own):",
           f"{'source':>9} {'pushes':>6} {'median':>7} {'10 %':>6} {'90 %':>6}"]
    for k in SOURCES:
        s = result["sources"][k]
        if not s["n"]:
            out.append(f"{k:>9} {0:6d} {'-':>7} {'-':>6} {'-':>6}")
            continue
        extra = f"   off by more than half: {s['over']} over, {s['under']} under" if k == "plan" else ""
        out.append(f"{k:>9} {s['n']:6d} {s['median']:7.2f} {s['p10']:6.2f} {s['p90']:6.2f}{extra}")
    d = result["delivered"]

    def q(k: str, scale: float, unit: str) -> str:
        v = d.get(k)
        if v is None:
            return "-"
        return f"{v['median'] / scale:.2f} {unit} (10-90 %: {v['p10'] / scale:.2f}-{v['p90'] / scale:.2f})"

    out.append(f"delivered (median over the pushes): impact in the first 0.15 s {q('impact', 1e3, 'kN s')}, "
               f"then {q('sustained', 1e3, 'kN')}, peak {q('peak', 1e3, 'kN')}, contact point "
               f"{q('point_x', 1.0, 'm')} from the c.g.")
    return out



def _quantiles(v: np.ndarray) -> Optional[Dict[str, float]]:
    """Median, 10 and 90 % of ``v``; None when empty."""
    if v.size == 0:
        return None
    return {"median": float(np.median(v)), "p10": float(np.percentile(v, 10)), "p90": float(np.percentile(v, 90))}
