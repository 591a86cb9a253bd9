"""The ``picopit simulate`` figure, with matplotlib's non-interactive Agg backend. It reads
``simulate``'s results; ``simulate`` does not import it (the command line draws)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Mapping, Optional, Sequence, Tuple

import numpy as np

from . import _core
from .simulate import LANE_COUNT, LANE_WIDTH, SimulateResult, Vehicle

BULLET_COLOR = "#1f5fbf"
TARGET_COLOR = "#d1402a"
CONTACT_COLOR = "#7a3fb0"


def _pyplot():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def footprints_over_time(
    x: np.ndarray, y: np.ndarray, yaw: np.ndarray, vehicle: Vehicle
) -> np.ndarray:
    """Corners (n, 4, 2) of a vehicle's footprint along a c.g. trajectory (rigid body,
    without the small roll/pitch shift the plant adds at bumper height)."""
    return np.stack([
        _core.footprint([xi, yi, wi], vehicle.length, vehicle.width, vehicle.cg_to_front)
        for xi, yi, wi in zip(x, y, yaw)
    ]) if len(x) else np.zeros((0, 4, 2))


def _draw_road(ax, x_lo: float, x_hi: float, lanes: int, lane_width: float) -> None:
    half = 0.5 * lanes * lane_width
    ax.axhspan(-half, half, color="#e9e9e9", zorder=0)
    ax.axhline(half, color="k", lw=1.4, zorder=1)
    ax.axhline(-half, color="k", lw=1.4, zorder=1)
    for k in range(1, lanes):
        ax.axhline(-half + k * lane_width, color="#8a8a8a", lw=0.9, ls=(0, (6, 6)), zorder=1)
    ax.set_xlim(x_lo, x_hi)


def _draw_boxes(ax, corners: np.ndarray, color: str, alphas: Sequence[float], lw: float = 0.9) -> None:
    from matplotlib.patches import Polygon

    for c, a in zip(corners, alphas):
        ax.add_patch(Polygon(c, closed=True, facecolor=color, alpha=0.18 * a + 0.04,
                             edgecolor=color, lw=lw, zorder=3))
        # The front edge (corners 3 -> 0) drawn thick, so heading is visible.
        ax.plot([c[3, 0], c[0, 0]], [c[3, 1], c[0, 1]], color=color, lw=2.0 * lw, alpha=0.35 + 0.65 * a, zorder=4)


def _time_picks(t: np.ndarray, every: float, t_lo: float = -math.inf, t_hi: float = math.inf) -> np.ndarray:
    """Indices of samples every `every` seconds within [t_lo, t_hi], last sample included."""
    sel = np.flatnonzero((t >= t_lo - 1e-9) & (t <= t_hi + 1e-9))
    if sel.size == 0:
        return sel
    picks, next_t = [], t[sel[0]]
    for i in sel:
        if t[i] >= next_t - 1e-9:
            picks.append(i)
            next_t = t[i] + every
    if picks[-1] != sel[-1]:
        picks.append(sel[-1])
    return np.array(picks)


def _motion_picks(
    t: np.ndarray, x: np.ndarray, y: np.ndarray, yaw: np.ndarray, every: float,
    t_lo: float, t_hi: float, min_move: float = 0.8, min_turn: float = math.radians(12.0),
) -> np.ndarray:
    """Like :func:`_time_picks`, but skip samples where the vehicle has hardly moved or
    turned since the last pick, so a vehicle at rest is drawn once."""
    picks = []
    for i in _time_picks(t, every, t_lo, t_hi):
        if picks:
            j = picks[-1]
            if math.hypot(x[i] - x[j], y[i] - y[j]) < min_move and abs(yaw[i] - yaw[j]) < min_turn:
                continue
        picks.append(i)
    return np.array(picks, dtype=int)


def _contact_spans(t: np.ndarray, fn: np.ndarray) -> Sequence[Tuple[float, float]]:
    on = fn > 0
    spans, start = [], None
    for i, flag in enumerate(on):
        if flag and start is None:
            start = t[max(i - 1, 0)]
        if not flag and start is not None:
            spans.append((start, t[i - 1] if i > 0 else t[i]))
            start = None
    if start is not None:
        spans.append((start, t[-1]))
    return spans


def plot_simulation(result: SimulateResult, path: Path, title: Optional[str] = None) -> None:
    """The ``picopit simulate`` figure: the road from above with both footprints over time
    (overview and a close-up of the contact), yaw angles, speeds and the contact force."""
    plt = _pyplot()
    d: Mapping[str, np.ndarray] = result.data
    cfg = result.config
    t = d["t"]
    fn, ft = d["contact_Fn"], d["contact_Ft"]
    spans = _contact_spans(t, fn)

    b_corners = footprints_over_time(d["bullet_X"], d["bullet_Y"], d["bullet_yaw"], result.bullet)
    t_corners = footprints_over_time(d["target_X"], d["target_Y"], d["target_yaw"], result.target)

    fig = plt.figure(figsize=(15, 11.5), constrained_layout=True)
    gs = fig.add_gridspec(3, 3, height_ratios=[1.0, 2.1, 1.6])
    ax_all = fig.add_subplot(gs[0, :])
    ax_zoom = fig.add_subplot(gs[1, :])
    ax_yaw = fig.add_subplot(gs[2, 0])
    ax_v = fig.add_subplot(gs[2, 1])
    ax_f = fig.add_subplot(gs[2, 2])

    x_all = np.concatenate([b_corners[..., 0].ravel(), t_corners[..., 0].ravel()])
    half = 0.5 * LANE_COUNT * LANE_WIDTH
    s = result.summary

    # Overview: every 0.5 s.
    lo, hi = float(x_all.min()) - 3.0, float(x_all.max()) + 3.0
    _draw_road(ax_all, lo, hi, LANE_COUNT, LANE_WIDTH)
    picks = _time_picks(t, 0.5)
    alphas = np.linspace(0.25, 1.0, len(picks))
    _draw_boxes(ax_all, b_corners[picks], BULLET_COLOR, alphas, lw=0.7)
    _draw_boxes(ax_all, t_corners[picks], TARGET_COLOR, alphas, lw=0.7)
    ax_all.plot(d["bullet_X"], d["bullet_Y"], color=BULLET_COLOR, lw=0.8, zorder=2)
    ax_all.plot(d["target_X"], d["target_Y"], color=TARGET_COLOR, lw=0.8, zorder=2)
    ax_all.set_aspect("equal")
    ax_all.set_ylim(-half - 2.0, half + 2.0)
    ax_all.set_ylabel("Y (m)")
    ax_all.set_title(f"Whole run, footprints every 0.5 s over {t[-1]:.1f} s (X along the road; "
                     f"{LANE_COUNT} lanes of {LANE_WIDTH} m)", fontsize=10, loc="left")

    # Close-up around the contact: from 1 s before the first contact until both settle.
    if spans:
        t0 = max(t[0], spans[0][0] - 1.0)
    else:
        t0 = t[0]
    moving = (np.hypot(d["target_vx"], d["target_vy"]) > 0.2) | (np.hypot(d["bullet_vx"], d["bullet_vy"]) > 0.2)
    t1 = float(t[np.flatnonzero(moving)[-1]]) if moving.any() else float(t[-1])
    t1 = max(t1, t0 + 1.0)
    window = (t >= t0 - 1e-9) & (t <= t1 + 1e-9)
    xz = np.concatenate([b_corners[window][..., 0].ravel(), t_corners[window][..., 0].ravel()])
    yz = np.concatenate([b_corners[window][..., 1].ravel(), t_corners[window][..., 1].ravel()])
    _draw_road(ax_zoom, float(xz.min()) - 2.0, float(xz.max()) + 2.0, LANE_COUNT, LANE_WIDTH)
    for corners, prefix, color in ((b_corners, "bullet", BULLET_COLOR), (t_corners, "target", TARGET_COLOR)):
        picks = _motion_picks(t, d[f"{prefix}_X"], d[f"{prefix}_Y"], d[f"{prefix}_yaw"], 0.2, t0, t1)
        _draw_boxes(ax_zoom, corners[picks], color, np.linspace(0.2, 1.0, len(picks)))
        ax_zoom.plot(d[f"{prefix}_X"][window], d[f"{prefix}_Y"][window], color=color, lw=1.0, zorder=2)
        if prefix == "target":
            # Time stamps on the target's c.g. every 0.6 s.
            for i in _time_picks(t, 0.6, t0, t1)[:-1]:
                ax_zoom.annotate(
                    f"{t[i]:.1f} s", (d["target_X"][i], d["target_Y"][i]), fontsize=7, color=color,
                    ha="center", va="center", zorder=7,
                    bbox=dict(boxstyle="round,pad=0.15", fc="white", ec="none", alpha=0.8),
                )
    touching = fn > 0
    if touching.any():
        ax_zoom.scatter(d["contact_X"][touching], d["contact_Y"][touching], s=5, color=CONTACT_COLOR,
                        zorder=6, label="contact point")
    ax_zoom.set_aspect("equal")
    ax_zoom.set_ylim(min(-half, float(yz.min())) - 1.0, max(half, float(yz.max())) + 1.0)
    ax_zoom.set_xlabel("X (m)")
    ax_zoom.set_ylabel("Y (m)")
    ax_zoom.set_title(f"Close-up {t0:.1f}-{t1:.1f} s, footprints every 0.2 s (faint = earlier, "
                      "thick edge = front)", fontsize=10, loc="left")
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles = [Patch(facecolor=BULLET_COLOR, alpha=0.5, label="bullet"),
               Patch(facecolor=TARGET_COLOR, alpha=0.5, label="target")]
    if touching.any():
        handles.append(Line2D([], [], marker="o", ls="", color=CONTACT_COLOR, label="contact point"))
    ax_zoom.legend(handles=handles, loc="upper left", fontsize=9, framealpha=0.9)

    def shade(ax) -> None:
        for a, b in spans:
            ax.axvspan(a, b, color=CONTACT_COLOR, alpha=0.12, lw=0)

    # Yaw angles (unwrapped, relative to the road).
    ax_yaw.plot(t, np.degrees(d["bullet_yaw"]), color=BULLET_COLOR, label="bullet")
    ax_yaw.plot(t, np.degrees(d["target_yaw"]), color=TARGET_COLOR, label="target")
    for ref in (-180, -90, 90, 180):
        ax_yaw.axhline(ref, color="#999", lw=0.6, ls=":")
    shade(ax_yaw)
    ax_yaw.set_xlabel("t (s)")
    ax_yaw.set_ylabel("yaw (deg)")
    ax_yaw.set_title(f"Yaw angle (target change {s['target_yaw_change_deg']:+.0f} deg)", fontsize=10)
    ax_yaw.legend(fontsize=8)

    # Speeds.
    ax_v.plot(t, np.hypot(d["bullet_vx"], d["bullet_vy"]), color=BULLET_COLOR, label="bullet")
    ax_v.plot(t, np.hypot(d["target_vx"], d["target_vy"]), color=TARGET_COLOR, label="target")
    ax_v.plot(t, d["target_vx"], color=TARGET_COLOR, lw=0.8, ls="--", label="target $v_x$ (body)")
    shade(ax_v)
    ax_v.set_xlabel("t (s)")
    ax_v.set_ylabel("speed (m/s)")
    ax_v.set_title("Speed over ground", fontsize=10)
    ax_v.legend(fontsize=8)

    # Contact force.
    ax_f.plot(t, fn / 1e3, color=CONTACT_COLOR, label="$F_n$ (normal)")
    ax_f.plot(t, ft / 1e3, color="#e08a00", lw=0.9, label="$F_t$ (tangential)")
    shade(ax_f)
    ax_f.set_xlabel("t (s)")
    ax_f.set_ylabel("force on target (kN)")
    ax_f.set_title(f"Contact force (peak {s['peak_contact_force_N'] / 1e3:.1f} kN, "
                   f"{len(t) and round(1 / (t[1] - t[0]))} Hz averages)", fontsize=10)
    ax_f.legend(fontsize=8)

    for ax in (ax_yaw, ax_v, ax_f):
        ax.grid(alpha=0.3)
        ax.set_xlim(t[0], t[-1])

    fig.suptitle(
        title or (
            f"picopit simulate: rear-quarter PIT, {cfg.params}, mu={cfg.mu:g}, target "
            f"{cfg.target_speed:g} m/s, bullet +{cfg.speed_diff:g} m/s, seed {cfg.seed}  "
            f"(shaded: vehicles in contact)"
        ),
        fontsize=12,
    )
    fig.savefig(path, dpi=110)
    plt.close(fig)
