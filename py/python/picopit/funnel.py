"""Where the benchmark loses its scenes: scenes → first contact → target reversed → success.

For each configuration the funnel counts the scenes that reach each stage and the episodes
lost between stages, by first failure cause and by who failed:

* **before contact**: the bullet never touched the target (the race was lost, or the
  controller gave up: decision infeasible);
* **in the push**: the vehicles touched, but the target failed before it first turned to
  within ε_ψ of the reversed heading (or never did);
* **after reversal**: the target reversed, then failed (left the road, hit something, was
  hit again, or kept spinning at ``T_max``).

Who failed: ``target`` or ``bullet`` (or ``both``) for a boundary violation or a secondary
collision (which vehicle crossed the edge or touched the obstacle), ``each_other`` for an
unsafe rebound, ``controller`` for decision infeasible, ``none`` for no termination and
``error`` for an episode that could not run.
"""

from __future__ import annotations

from typing import Any, Dict, Mapping, Optional, Sequence

STAGES = ("scenes", "first_contact", "reversed", "success")
LOSSES = ("before_contact", "in_push", "after_reversal")


def who(row: Mapping[str, Any]) -> str:
    """Who failed in an episode that failed."""
    cause = row.get("cause")
    if cause == "error" or row.get("error") is not None:
        return "error"
    if cause in ("boundary_violation", "secondary_collision"):
        return str(row.get("failed_vehicle") or "target")
    return {"unsafe_rebound": "each_other", "decision_infeasible": "controller"}.get(str(cause), "none")


def stage_lost(row: Mapping[str, Any]) -> Optional[str]:
    """The stage a failed episode was lost in (``None`` for a success)."""
    if row.get("success"):
        return None
    if row.get("error") is not None or not row.get("contacts"):
        return "before_contact"
    reversed_at = row.get("reversed_at")
    if reversed_at is None:
        return "in_push"
    decided = row.get("decided_at")
    if decided is not None and decided < reversed_at:
        return "in_push"
    return "after_reversal"


def funnel(rows: Sequence[Mapping[str, Any]]) -> Dict[str, Any]:
    """The funnel of one configuration's episodes: ``{"scenes", "first_contact",
    "reversed", "success", "lost": {stage: {cause: {who: count}}}}``. A target counts as
    reversed when it turned to within ε_ψ of the reversed heading before its episode's
    failure was decided."""
    out: Dict[str, Any] = {s: 0 for s in STAGES}
    lost: Dict[str, Dict[str, Dict[str, int]]] = {s: {} for s in LOSSES}
    for r in rows:
        out["scenes"] += 1
        stage = stage_lost(r)
        if stage != "before_contact":
            out["first_contact"] += 1
        if stage in (None, "after_reversal"):
            out["reversed"] += 1
        if stage is None:
            out["success"] += 1
            continue
        cause = "error" if r.get("error") is not None else str(r.get("cause"))
        by_who = lost[stage].setdefault(cause, {})
        by_who[who(r)] = by_who.get(who(r), 0) + 1
    out["lost"] = lost
    return out


def lost_total(f: Mapping[str, Any], stage: str) -> int:
    return sum(n for by_who in f["lost"][stage].values() for n in by_who.values())


def markdown(funnels: Mapping[str, Mapping[str, Any]]) -> str:
    """Two tables: the stages per configuration, and the losses by stage, cause and who."""
    lines = [
        "| config | scenes | first contact | reversed | success | lost before contact | lost in the push | lost after reversal |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, f in funnels.items():
        lines.append(
            f"| {name} | {f['scenes']} | {f['first_contact']} | {f['reversed']} | {f['success']} | "
            + " | ".join(str(lost_total(f, s)) for s in LOSSES) + " |"
        )
    lines += ["", "| config | stage | cause | who | episodes |", "|---|---|---|---|---|"]
    for name, f in funnels.items():
        for stage in LOSSES:
            for cause, by_who in sorted(f["lost"][stage].items()):
                for w, n in sorted(by_who.items()):
                    lines.append(f"| {name} | {stage.replace('_', ' ')} | {cause.replace('_', ' ')} | {w.replace('_', ' ')} | {n} |")
    return "\n".join(lines)


def plot(ax, funnels: Mapping[str, Mapping[str, Any]]) -> None:
    """Panel D: the share of scenes at each stage, one line per configuration."""
    x = range(len(STAGES))
    for i, (name, f) in enumerate(funnels.items()):
        n = max(1, f["scenes"])
        ys = [100.0 * f[s] / n for s in STAGES]
        ax.plot(list(x), ys, marker="o", label=name, color=f"C{i}")
        for xi, y, s in zip(x, ys, STAGES):
            # Stacked labels: configurations often land on the same point.
            ax.annotate(str(f[s]), (xi, y), textcoords="offset points", xytext=(5, 2 - 9 * i),
                        fontsize=7, color=f"C{i}")
    ax.set_xticks(list(x), ["scenes", "first contact", "reversed", "success"])
    ax.set_ylim(0, 105)
    ax.set_ylabel("scenes (%)")
    ax.set_title("D  funnel: where scenes are lost")
    ax.legend(fontsize=8, loc="lower left")
