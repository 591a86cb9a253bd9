"""The shove map of one scene: every single rear-quarter shove of the oracle's grid (candidate
time from the bullet's earliest arrival × side × size), simulated to the benchmark's verdict
(``_core.shove_grid``), drawn as a success map per side, with where a controller's first
contact landed if a benchmark run is given.

It shows how much a push may be off and still save the scene: at full size, and most of all
for a fast target, the sizes that succeed at one moment are often a single step of the grid
(``docs/RESULTS.md``, the robust tiers).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional

import numpy as np

from . import _core

#: The most scenes ``picopit oracle --grid-plot`` draws in one call (each simulates its whole
#: grid: 5-15 s on the default grid, 2 000 simulated shoves).
MAX_SCENES = 20


@dataclass
class ShoveMap:
    """The grid of one scene: ``success[time, side, shove]``."""

    scene: str
    times: np.ndarray
    sides: List[float]
    shoves: List[float]
    success: np.ndarray
    t_reach: float

    @property
    def successes(self) -> int:
        return int(self.success.sum())

    def widest_band(self) -> int:
        """The most consecutive sizes of the grid that succeed at one time on one side (0 when
        none does): how far a push's size may be off."""
        return max((_band(list(row)) for row in self.success.reshape(-1, len(self.shoves))), default=0)

    def at(self, time: float, side: float) -> Optional[np.ndarray]:
        """The sizes' verdicts at the candidate time nearest ``time`` (within one step) on
        ``side``; None when the grid has no such time or side."""
        if side not in self.sides or len(self.times) == 0:
            return None
        i = int(np.argmin(np.abs(self.times - time)))
        step = float(self.times[1] - self.times[0]) if len(self.times) > 1 else 0.0
        if abs(self.times[i] - time) > max(step, 1e-9):
            return None
        return self.success[i, self.sides.index(side)]

    def line(self, mark: Optional[Mapping[str, Any]] = None) -> str:
        """One line: successes of the grid, the widest band of sizes, and with ``mark``
        (``time``, ``side``, ``stage``) which sizes would have saved the scene there."""
        text = (f"{self.scene}: {self.successes} of {self.success.size} shoves succeed "
                f"(earliest arrival {self.t_reach:.2f} s); widest band of sizes at one time: "
                f"{self.widest_band()} of {len(self.shoves)}")
        if mark is not None:
            side = "left" if mark["side"] > 0 else "right"
            ok = self.at(mark["time"], mark["side"])
            if ok is None:
                there = "outside the grid"
            else:
                sizes = [f"{v:g}" for v, s in zip(self.shoves, ok) if s]
                there = f"sizes that succeed there: {', '.join(sizes) or 'none'} m/s"
            text += (f"; the controller's first contact at {mark['time']:.2f} s on the {side} "
                     f"({mark['stage']}): {there}")
        return text


def shove_map(scene: Mapping[str, Any], settings: Mapping[str, Any], held: bool = False) -> ShoveMap:
    """Simulate the grid of ``settings`` (as :func:`picopit.oracle.resolve_settings` returns
    them) on ``scene``; raises ``_core.ScenarioError`` for a bad scene."""
    g = _core.shove_grid(json.dumps(dict(scene)), json.dumps(dict(settings)), held)
    times = np.asarray(g["times"], dtype=float)
    success = np.asarray(g["success"], dtype=bool).reshape(len(times), len(g["sides"]), len(g["shoves"]))
    return ShoveMap(scene=str(scene["id"]), times=times, sides=[float(s) for s in g["sides"]],
                    shoves=[float(v) for v in g["shoves"]], success=success, t_reach=float(g["t_reach"]))


def first_contacts(run: Path, config: str, option: str = "--grid-run") -> Dict[str, Dict[str, Any]]:
    """``{scene: {"time", "side", "stage"}}`` of the scenes configuration ``config`` of a
    benchmark run touched: its first contact's time, side (+1 the target's left) and where the
    episode ended (success, lost in the push, lost after reversal). Raises
    :class:`picopit.oracle.OracleError` as :func:`picopit.oracle.contact_rows` does."""
    from .oracle import contact_rows

    out: Dict[str, Dict[str, Any]] = {}
    for r, side in contact_rows(run, config, option, ("contact_at", "success", "reversed_at")):
        t = _number(r["contact_at"])
        if t is None:
            continue
        success = str(r["success"]).lower() in ("true", "1")
        stage = "success" if success else (
            "lost after reversal" if _number(r["reversed_at"]) is not None else "lost in the push")
        out[str(r["scenario"])] = {"time": t, "side": side, "stage": stage}
    return out


def _number(v: Any) -> Optional[float]:
    """A finite number from a run's cell; None for an empty or non-finite one."""
    try:
        x = float(v)
    except (TypeError, ValueError):
        return None
    return x if np.isfinite(x) else None


def plot(m: ShoveMap, path: Path, mark: Optional[Mapping[str, Any]] = None) -> Path:
    """The map as a PNG: one panel per side, contact time across, shove size up, the shoves
    that succeed filled; the earliest arrival dashed and ``mark`` (a controller's first
    contact) as a line on its side."""
    from .plots import _pyplot

    plt = _pyplot()
    fig, axes = plt.subplots(1, len(m.sides), figsize=(5.2 * len(m.sides), 3.6), sharey=True, squeeze=False)
    step = float(m.times[1] - m.times[0]) if len(m.times) > 1 else 0.1
    for j, side in enumerate(m.sides):
        ax = axes[0][j]
        if len(m.times):
            grid = m.success[:, j, :].T.astype(float)
            ax.imshow(grid, origin="lower", aspect="auto", cmap="Greens", vmin=0.0, vmax=1.2,
                      extent=(m.times[0] - step / 2, m.times[-1] + step / 2, -0.5, len(m.shoves) - 0.5))
        ax.axvline(m.t_reach, color="0.4", ls="--", lw=0.9, label="earliest arrival")
        if mark is not None and mark["side"] == side:
            ax.axvline(mark["time"], color="tab:red", lw=1.4, label=f"controller's contact ({mark['stage']})")
        ax.set_yticks(range(len(m.shoves)))
        ax.set_yticklabels([f"{v:g}" for v in m.shoves])
        ax.set_xlabel("contact time (s)")
        ax.set_title(f"bullet on the target's {'left' if side > 0 else 'right'}", fontsize=10)
        ax.legend(loc="upper right", fontsize=7)
    axes[0][0].set_ylabel("shove size Δv (m/s)")
    fig.suptitle(f"{m.scene}: {m.successes} of {m.success.size} single shoves succeed", fontsize=11)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


@dataclass
class AtContact:
    """The grid's sizes at the moment and on the side a run's controller first touched each
    scene's target, by where its episode ended (``stage``)."""

    settings: Dict[str, Any]
    #: per scene: id, stage, contact time, side, candidate time (None before the earliest
    #: arrival), the sizes' verdicts there
    rows: List[Dict[str, Any]]

    STAGES = ("success", "lost in the push", "lost after reversal")

    def summary(self) -> List[Dict[str, Any]]:
        out = []
        for stage in self.STAGES:
            rows = [r for r in self.rows if r["stage"] == stage]
            on = [r for r in rows if r["time"] is not None]
            bands = sorted(_band(r["success"]) for r in on)
            out.append({"stage": stage, "scenes": len(rows), "on_grid": len(on),
                        "saving": sum(1 for r in on if any(r["success"])),
                        "band_2": sum(1 for b in bands if b >= 2),
                        "median_band": float(np.median(bands)) if bands else float("nan")})
        return out

    def markdown(self) -> str:
        lines = ["| ended | scenes | contact at a candidate time | some size saves | two or more adjacent sizes save | median band (sizes) |",
                 "|---|---|---|---|---|---|"]
        for s in self.summary():
            lines.append(f"| {s['stage']} | {s['scenes']} | {s['on_grid']} | {s['saving']} | {s['band_2']} | "
                         f"{s['median_band']:.1f} |")
        return "\n".join(lines) + "\n"


def _band(row: List[bool]) -> int:
    best = run = 0
    for ok in row:
        run = run + 1 if ok else 0
        best = max(best, run)
    return best


def at_contact(scenes: List[Mapping[str, Any]], marks: Mapping[str, Mapping[str, Any]],
               settings: Mapping[str, Any], workers: int = 1, progress: bool = True) -> AtContact:
    """For each scene in ``marks`` (:func:`first_contacts`), every size of the grid shoved at
    the candidate time nearest the first contact (within half a ``time_step``) from the side
    it came from: would one of them have saved the scene there?"""
    from concurrent.futures import ThreadPoolExecutor

    step = float(settings["time_step"])
    chosen = [sc for sc in scenes if sc["id"] in marks]

    def one(sc: Mapping[str, Any]) -> Dict[str, Any]:
        mk = marks[sc["id"]]
        t = float(mk["time"])
        own = dict(settings, window=[t - 0.5 * step, t + 0.5 * step], sides=[mk["side"]])
        m = shove_map(sc, own)
        row: Dict[str, Any] = {"id": sc["id"], "stage": mk["stage"], "contact_at": t, "side": mk["side"],
                               "time": None, "success": []}
        if len(m.times):
            i = int(np.argmin(np.abs(m.times - t)))
            row["time"] = float(m.times[i])
            row["success"] = [bool(v) for v in m.success[i, 0]]
        return row

    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(chosen), unit="scene", desc="oracle at contact")
    rows = []
    with ThreadPoolExecutor(max_workers=max(1, workers)) as pool:
        for row in pool.map(one, chosen):
            rows.append(row)
            if bar is not None:
                bar.update()
    if bar is not None:
        bar.close()
    return AtContact(settings=dict(settings), rows=rows)
