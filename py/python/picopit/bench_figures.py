"""The benchmark's figures (``picopit bench``), drawn with matplotlib (Agg):

* ``plot_panels``: ``panels.png`` -- A: success by road and adhesion, B: failure composition,
  C: runtimes, D: the funnel (``picopit.funnel``);
* ``plot_contacts``: ``contacts.png`` -- D: success by where the first contact landed along
  the target, E: by the relative speed at that contact, F: the share of its start speed a spun
  target kept at its first reversal;
* ``plot_case``: ``case_success.png``, ``case_failure.png`` -- one recorded episode on the
  road, its states and the bullet's inputs (also used by ``picopit trace --plot``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from . import _core, funnel
from .bench_summary import CAUSES, ERROR_CAUSE, _finite
from .cases_mcap import road_edges as _road_edges, station_span


def _pyplot():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


CAUSE_COLORS = {"decision_infeasible": "#8c6bb1", "no_termination": "#bdbdbd",
                "boundary_violation": "#e6550d", "secondary_collision": "#de2d26",
                "unsafe_rebound": "#3182bd", "error": "#000000"}


def plot_panels(summary: Mapping[str, Mapping[str, Any]], path: Path) -> None:
    plt = _pyplot()
    names = list(summary)
    fig, axes = plt.subplots(1, 4, figsize=(21, 4.8))
    # A: success by road and adhesion.
    ax = axes[0]
    groups = [("success_rate", "all"), ("success_straight", "straight"), ("success_curved", "curved"),
              ("success_low", "low μ"), ("success_mid", "mid μ"), ("success_high", "high μ")]
    w = 0.8 / max(1, len(names))
    x = np.arange(len(groups))
    for i, n in enumerate(names):
        vals = [summary[n].get(k) or 0.0 for k, _ in groups]
        ax.bar(x + (i - (len(names) - 1) / 2) * w, vals, w, label=n)
    ax.set_xticks(x, [g for _, g in groups])
    ax.set_ylabel("success (%)")
    ax.set_ylim(0, 100)
    ax.set_title("A  success by road and adhesion")
    ax.legend(fontsize=8)
    # B: failure composition.
    ax = axes[1]
    bottom = np.zeros(len(names))
    for c in CAUSES + (ERROR_CAUSE,):
        vals = np.array([summary[n].get(f"fail_{c}") or 0.0 for n in names])
        if c == ERROR_CAUSE and not vals.any():
            continue
        ax.bar(names, vals, bottom=bottom, color=CAUSE_COLORS[c], label=c.replace("_", " "))
        bottom += vals
    ax.set_ylabel("episodes (%)")
    ax.set_ylim(0, 100)
    ax.set_title("B  failure composition (first cause)")
    # Below the axes: inside, the legend hid the stacks it describes.
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=3, frameon=False)
    ax.tick_params(axis="x", labelrotation=15)
    # C: runtimes.
    ax = axes[2]
    x = np.arange(len(names))
    for j, (k, lab, hatch) in enumerate((("plan", "plan", ""), ("ctrl", "ctrl", "//"))):
        med = [summary[n].get(f"{k}_ms_median") or 0.0 for n in names]
        p99 = [summary[n].get(f"{k}_ms_p99") or 0.0 for n in names]
        pos = x + (j - 0.5) * 0.38
        ax.bar(pos, med, 0.36, label=f"{lab} median", color=f"C{j}")
        ax.scatter(pos, p99, marker="_", s=300, color="k", zorder=3, label="p99" if j == 0 else None)
    ax.axhline(50.0, color="#888", ls=":", lw=1)
    ax.text(x[-1] + 0.5 if len(x) else 0.5, 50.0, "control period 50 ms", ha="right", va="bottom",
            fontsize=7, color="#666")
    ax.set_xticks(x, names, rotation=15)
    ax.set_ylabel("ms per step")
    ax.set_yscale("log")
    from matplotlib.ticker import FormatStrFormatter

    ax.yaxis.set_major_formatter(FormatStrFormatter("%g"))
    ax.yaxis.set_minor_formatter(FormatStrFormatter(""))
    ax.set_title("C  planning and control times")
    shown = [v for n in names for k in ("plan", "ctrl") for v in
             (summary[n].get(f"{k}_ms_median"), summary[n].get(f"{k}_ms_p99")) if v]
    if shown:  # every bar from the same floor, and room for the legend above the 50 ms line
        ax.set_ylim(0.5 * min(shown), 4.0 * max(max(shown), 50.0))
    ax.legend(fontsize=8, loc="upper right", ncol=3)
    # D: the funnel.
    funnel.plot(axes[3], {n: summary[n]["funnel"] for n in names if "funnel" in summary[n]})
    fig.tight_layout()
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)


def plot_case(case: Mapping[str, Any], sc: Mapping[str, Any], path: Path, title: str) -> None:
    from matplotlib.patches import Polygon

    from . import load_params_dict

    plt = _pyplot()
    cols = list(_core.trajectory_columns())
    tr = np.asarray(case["trajectory"])
    c = {k: tr[:, i] for i, k in enumerate(cols)}
    p = load_params_dict(sc["params"])
    fig = plt.figure(figsize=(15, 8.5))
    gs = fig.add_gridspec(3, 3, height_ratios=[1.6, 1, 1])
    ax = fig.add_subplot(gs[0, :])
    # Road: edges, lane lines; stations spanned by the episode.
    edges = _road_edges(sc, *station_span(sc, c))
    for k, e in enumerate(edges):
        if k < 2:
            ax.plot(e[:, 0], e[:, 1], color="k", lw=1.5)
        elif k >= len(edges) - 2:
            ax.plot(e[:, 0], e[:, 1], color="#555", lw=0.8)
        else:
            ax.plot(e[:, 0], e[:, 1], color="#999", lw=0.8, ls=(0, (6, 6)))
    for ob in sc.get("obstacles", []):
        b = ob["body"]
        t_end = float(c["time"][-1])
        for tt, a in ((0.0, 0.5), (t_end, 1.0)):
            corners = _core.footprint([b["x"] + b["vx"] * tt, b["y"] + b["vy"] * tt, b["heading"]],
                                      b["length"], b["width"], 0.5 * b["length"])
            ax.add_patch(Polygon(corners, closed=True, facecolor="#555", alpha=0.3 * a, edgecolor="#333"))
    picks = np.unique(np.linspace(0, len(tr) - 1, 12).round().astype(int))
    for who, color, xk, yk, pk in (("bullet", "#1f5fbf", "bullet_x", "bullet_y", "bullet_psi"),
                                   ("target", "#d1402a", "target_x", "target_y", "target_psi")):
        geo = p[who]
        ax.plot(c[xk], c[yk], color=color, lw=1.2, label=who)
        for j, i in enumerate(picks):
            corners = _core.footprint([c[xk][i], c[yk][i], c[pk][i]], geo["length"], geo["width"],
                                      geo["cg_to_front"])
            a = 0.25 + 0.75 * j / max(1, len(picks) - 1)
            ax.add_patch(Polygon(corners, closed=True, facecolor=color, alpha=0.15 * a + 0.03,
                                 edgecolor=color, lw=0.8))
    contact = c["contact_fn"] > 0
    if contact.any():
        ax.scatter(c["target_x"][contact], c["target_y"][contact], s=6, color="#7a3fb0", zorder=5,
                   label="in contact")
    # Frame the vehicles' paths (obstacles far away would shrink them to nothing).
    xs = np.concatenate([c["target_x"], c["bullet_x"]])
    ys = np.concatenate([c["target_y"], c["bullet_y"]])
    pad = 8.0 * max(p["bullet"]["length"], p["target"]["length"]) / 4.5
    ax.set_xlim(xs.min() - pad, xs.max() + pad)
    ax.set_ylim(ys.min() - pad, ys.max() + pad)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("X (m)")
    ax.set_ylabel("Y (m)")
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title(title)
    t = c["time"]
    panels = [
        ("yaw ψ (deg)", [(np.degrees(c["target_psi"]), "target", "#d1402a"),
                                  (np.degrees(c["bullet_psi"]), "bullet", "#1f5fbf")]),
        ("speed (m/s)", [(np.hypot(c["target_vx"], c["target_vy"]), "target", "#d1402a"),
                         (np.hypot(c["bullet_vx"], c["bullet_vy"]), "bullet", "#1f5fbf")]),
        ("yaw rate (rad/s)", [(c["target_r"], "target", "#d1402a"), (c["bullet_r"], "bullet", "#1f5fbf")]),
        ("bullet steer δ_f (rad)", [(c["cmd_steer"], "command", "#1f5fbf")]),
        ("bullet torque T_r (N m)", [(c["cmd_torque"], "command", "#1f5fbf")]),
        ("contact force (kN)", [(c["contact_fn"] / 1e3, "F_n", "#7a3fb0"), (c["contact_ft"] / 1e3, "F_t", "#b07a3f")]),
    ]
    for k, (lab, series) in enumerate(panels):
        a = fig.add_subplot(gs[1 + k // 3, k % 3])
        for y, name, color in series:
            a.plot(t, y, color=color, lw=1.2, label=name)
        phase = c["phase"]
        for ph, shade in ((1.0, "#f2e6ff"), (2.0, "#e6f2e6")):
            on = phase == ph
            if on.any():
                a.fill_between(t, 0, 1, where=on, color=shade, transform=a.get_xaxis_transform(), zorder=0)
        a.set_ylabel(lab, fontsize=8)
        a.set_xlabel("t (s)", fontsize=8)
        a.grid(alpha=0.3)
        if len(series) > 1:
            a.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


# Bins of the contact figure (full-size scenes; the target's rear bumper is 2.39 m and its rear
# axle 1.42 m behind its c.g.).
IMPACT_X_EDGES = (-2.45, -2.2, -1.8, -1.4, -1.0, 0.0, 2.2)
IMPACT_V_EDGES = (0.0, 2.0, 3.0, 4.0, 5.0, 8.0)


def _binned_success(rows: Sequence[Mapping[str, Any]], key: str, edges: Sequence[float]):
    """Success % and counts per bin of ``key`` (episodes with that value only)."""
    n = np.zeros(len(edges) - 1)
    ok = np.zeros(len(edges) - 1)
    for r in rows:
        v = _finite(r.get(key))
        if v is None:
            continue
        j = int(np.searchsorted(edges, v, side="right")) - 1
        if 0 <= j < len(n):
            n[j] += 1
            ok[j] += bool(r.get("success"))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, 100.0 * ok / np.maximum(n, 1), np.nan), n


def plot_contacts(table: Sequence[Mapping[str, Any]], names: Sequence[str], path: Path) -> None:
    """D: success by the first contact's point along the target; E: by the relative speed
    at it (full-size episodes with a contact, per configuration); F: the share of its start
    speed a spun target kept at its first reversal, successes against failures."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(16, 4.6))
    full = [r for r in table if r.get("params") == "full_size"]
    focus = "picopinn" if "picopinn" in names else (names[0] if names else "")
    for ax, key, edges, label, title in (
            (axes[0], "impact_x", IMPACT_X_EDGES, "first contact along the target, body x (m)",
             "D  success by where the first contact landed"),
            (axes[1], "impact_speed", IMPACT_V_EDGES, "relative speed at the first contact (m/s)",
             "E  success by the speed of the first contact")):
        centres = 0.5 * (np.array(edges[:-1]) + np.array(edges[1:]))
        for i, name in enumerate(names):
            rate, n = _binned_success([r for r in full if r.get("config") == name], key, edges)
            ax.plot(centres, rate, "o-", color=f"C{i}", label=name)
            if name == focus:
                for c, k in zip(centres, n):
                    if k:
                        ax.annotate(f"{int(k)}", (c, 2), ha="center", fontsize=7, color="#666")
        ax.text(0.01, 0.99, f"grey: {focus} episodes per bin", transform=ax.transAxes, ha="left",
                va="top", fontsize=7, color="#666")
        for e in edges:
            ax.axvline(e, color="#ddd", lw=0.8, zorder=0)
        ax.set_xlabel(label)
        ax.set_ylabel("success (%)")
        ax.set_ylim(0, 100)
        ax.set_title(title)
        ax.legend(fontsize=8)
    axes[0].axvspan(-2.2, -1.4, color="#e5f5e0", zorder=0)
    axes[0].text(-1.8, 90, "rear quarter", ha="center", va="top", fontsize=8, color="#31a354")
    ax = axes[2]
    kept = {True: [], False: []}
    for r in table:
        vr, v0 = _finite(r.get("reversed_speed")), _finite(r.get("target_speed"))
        if r.get("config") == focus and vr is not None and v0 and int(r.get("contacts") or 0) > 0:
            kept[bool(r.get("success"))].append(vr / v0)
    bins = np.linspace(0.0, 1.0, 21)
    for ok, color, lab in ((True, "#31a354", "success"), (False, "#e6550d", "failure")):
        if kept[ok]:
            ax.hist(kept[ok], bins=bins, alpha=0.6, color=color,
                    label=f"{lab} (n={len(kept[ok])}, median {np.median(kept[ok]):.2f})")
    ax.set_xlabel("speed at the first reversal / start speed")
    ax.set_ylabel("spun targets")
    ax.set_title(f"F  speed a spun target kept ({focus})")
    if kept[True] or kept[False]:
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
