"""``picopit trace SCENE``: one closed-loop episode of the benchmark, step by step.

The episode runs as in ``picopit bench`` (``_core.run_episode`` with the trajectory recorded),
by default on the simulated clock so that a trace repeats to the step. Each row of the table
is one control step: the time, the controller's phase, whether the vehicles touch, the
bullet's lead along the road over the target (``ds``), each vehicle's lateral offset from the
road's reference line (``d``, m, left positive), its heading relative to the road (deg) and
its speed, the bullet's command (front steer, rear torque) and the contact force on the
target (normal and tangential, N). Every ``every``-th step is shown, and every step in
contact or where the phase changes. The episode's metrics follow.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional

import numpy as np

from . import _core

PHASES = ("chasing", "pit", "stabilising", "done", "aborted")
#: The target state's columns in the recorded trajectory, in the models' order.
TARGET_STATE = ("target_vx", "target_vy", "target_psi", "target_r", "target_p", "target_phi", "target_x",
                "target_y")
#: The opening of a push counted as its impact (s).
IMPACT_TIME = 0.15
#: The table's columns: name, width, format.
COLUMNS = (("t", 6, "{:6.2f}"), ("phase", 11, "{:>11}"), ("contact", 7, "{:>7}"), ("ds", 7, "{:7.2f}"),
           ("T.d", 6, "{:6.2f}"), ("T.psi", 7, "{:7.1f}"), ("T.v", 6, "{:6.2f}"), ("B.d", 6, "{:6.2f}"),
           ("B.psi", 7, "{:7.1f}"), ("B.v", 6, "{:6.2f}"), ("steer", 7, "{:7.3f}"), ("torque", 8, "{:8.1f}"),
           ("Fn", 7, "{:7.0f}"), ("Ft", 7, "{:7.0f}"))
#: The metrics printed after the table, in this order.
METRICS = ("success", "cause", "failed_vehicle", "decided_at", "at_rest", "contacts", "contact_at",
           "impact_speed", "impact_angle", "reversed_at", "terminal_heading_error", "min_margin",
           "final_phase", "abort", "mpc_failures")


class TraceError(ValueError):
    """Bad trace input: an unknown scene, a bad configuration or settings file."""


@dataclass
class Trace:
    """A traced episode: the scene, the core's result and the trajectory's columns, with the
    road-frame columns added (``target_s``, ``target_d``, ``target_dpsi``, the same for
    ``bullet_``; heading relative to the road in rad)."""

    scene: Dict[str, Any]
    config: str
    result: Dict[str, Any]
    #: the recorded trajectory as the core returns it (``_core.trajectory_columns()``)
    trajectory: np.ndarray
    columns: Dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def contact_steps(self) -> np.ndarray:
        """Indices of the steps with a contact force."""
        return np.flatnonzero(self.columns["contact_fn"] > 0)

    def rows(self, every: int = 2) -> List[Dict[str, Any]]:
        """The table's rows: every ``every``-th step, every step in contact and every step
        where the phase changes (the first and last steps too)."""
        c = self.columns
        n = len(c["time"])
        phase = c["phase"]
        keep = set(range(0, n, max(1, every))) | {n - 1} | set(self.contact_steps.tolist())
        keep |= {i for i in range(1, n) if phase[i] != phase[i - 1]}
        rows = []
        for i in sorted(keep):
            rows.append({
                "t": c["time"][i], "phase": PHASES[int(phase[i])] if 0 <= int(phase[i]) < len(PHASES) else "?",
                "contact": "yes" if c["contact_fn"][i] > 0 else "",
                "ds": c["bullet_s"][i] - c["target_s"][i],
                "T.d": c["target_d"][i], "T.psi": math.degrees(c["target_dpsi"][i]),
                "T.v": math.hypot(c["target_vx"][i], c["target_vy"][i]),
                "B.d": c["bullet_d"][i], "B.psi": math.degrees(c["bullet_dpsi"][i]),
                "B.v": math.hypot(c["bullet_vx"][i], c["bullet_vy"][i]),
                "steer": c["cmd_steer"][i], "torque": c["cmd_torque"][i],
                "Fn": c["contact_fn"][i], "Ft": c["contact_ft"][i],
            })
        return rows

    def table(self, every: int = 2) -> str:
        head = " ".join(f"{name:>{w}}" for name, w, _ in COLUMNS)
        lines = [head]
        for r in self.rows(every):
            lines.append(" ".join(fmt.format(r[name]) for name, _, fmt in COLUMNS))
        return "\n".join(lines)

    def header(self) -> str:
        s = self.scene
        return (f"scene {s['id']}: {s.get('category')}, adhesion {s.get('adhesion')} (mu {s.get('mu')}), "
                f"driver {(s.get('driver') or {}).get('kind')}, {s.get('params')}; config {self.config}, "
                f"seed {self.result.get('seed')}, {len(self.columns['time'])} steps")

    def prediction_error(self, plan: Mapping[str, Any]) -> Optional[Dict[str, float]]:
        """How far the target went from the plan's prediction: at the last predicted step the
        episode reached, the distance (m) between the predicted and the recorded target
        positions and the predicted minus the recorded heading (rad, wrapped); None for a
        plan without a prediction, or none of whose later steps the recording holds."""
        times = np.asarray(plan.get("predicted_time", ()))
        states = np.asarray(plan.get("predicted_target", ()))
        t = self.columns["time"]
        if times.size == 0 or t.size == 0:
            return None
        k = int(np.searchsorted(times, t[-1] + 1e-9)) - 1
        if k < 1:  # nothing predicted beyond the plan's own time is recorded
            return None
        i = int(np.argmin(np.abs(t - times[k])))
        if abs(t[i] - times[k]) > 1e-6:  # plan steps fall on control steps
            return None
        x = states[k]
        return {
            "time": float(times[k]),
            "distance": math.hypot(x[6] - self.columns["target_x"][i], x[7] - self.columns["target_y"][i]),
            "heading": _core.wrap_angle(float(x[2] - self.columns["target_psi"][i])),
        }

    def plan_lines(self) -> List[str]:
        """One line per plan of the upper layer: when, the mode (for an abort, why), the side,
        the planned push's window, peak normal force and impulse, the predicted heading error
        at the end of the look-ahead, and how far the target then was from the prediction
        (:meth:`prediction_error`)."""
        out = []
        for p in self.result.get("plans") or []:
            window = ("none" if p["push_from"] is None
                      else f"{p['push_from']:.2f}-{p['push_to']:.2f} s, peak {p['push_peak']:.0f} N, "
                           f"{p['push_impulse'] / 1000:.1f} kN s")
            why = f" ({p['reason']})" if p.get("reason") else ""
            held = ", held back behind the target" if p.get("hold_back") else ""
            err = self.prediction_error(p)
            truth = ("" if err is None else
                     f"; at {err['time']:.2f} s the target was {err['distance']:.2f} m and "
                     f"{math.degrees(err['heading']):+.0f} deg off the prediction")
            out.append(f"plan at {p['time']:5.2f} s: {p['mode']}{why}, {p.get('side', '?')} side{held}, "
                       f"push {window}, predicted heading error "
                       f"{p['predicted_heading_error']:.3f} rad{truth}")
        return out

    def first_push(self, gap: float = 0.5) -> Optional[range]:
        """The control steps of the first push: from the first step in contact to the last
        one before the vehicles stay apart for more than ``gap`` seconds; None without a
        contact."""
        steps = self.contact_steps
        if steps.size == 0:
            return None
        t = self.columns["time"]
        last = int(steps[0])
        for k in steps[1:]:
            if t[k] - t[last] > gap + 1e-9:
                break
            last = int(k)
        return range(int(steps[0]), last + 1)

    def push_models(self, models: Path = Path("models"), after: float = 2.0) -> Optional[Dict[str, Any]]:
        """The target models stepped through the first push as it happened: from the recorded
        state before the first contact, with the recorded driver commands and the recorded
        contact of every step (its impulse average, point and normal: what a model takes),
        to ``after`` seconds past the push's last contact. Beside them, the plan made last
        before the contact (its prediction at the same times, if its look-ahead reaches
        them). So a prediction error can be told apart: the models' own, given the push
        that was delivered, or the planned push's, which the bullet did not deliver.

        Returns ``None`` without a contact; else a dict: ``start``, ``end`` (the push's first
        step start and last step end, s), ``impulse`` (∫F_n dt, N s), ``point_x`` (the
        contact point's body x, impulse-weighted, m), ``plan`` (the plan's time, or None),
        ``impact`` (∫F_n dt over the push's first 0.15 s, N s), ``peak`` (largest step force, N),
        ``sustained`` (the median step force after that, N; None for a shorter push),
        ``rows``: per checkpoint (the push's end, then ``after`` past it or the recording's
        end), ``time`` and per source (``truth``, ``4dof``, ``pinn``, ``picopinn``, ``plan``,
        ``free``: the PicoPINN, or the 4-DOF model without a PicoPINN file, without the
        contact) the heading turned since the start (rad,
        unwrapped) and the yaw rate (rad/s), None where a source has no value."""
        push = self.first_push()
        if push is None:
            return None
        c = self.columns
        k0, k1 = push.start, push.stop - 1
        if k0 == 0:
            return None  # no recorded state before the first contact
        t = c["time"]
        dt = float(t[1] - t[0]) if t.size > 1 else 0.05
        k_end = min(len(t) - 1, k1 + int(round(after / dt)))
        mu, params = float(self.scene["mu"]), str(self.scene.get("params", "full_size"))
        sources: Dict[str, Any] = {"4dof": _core.FourDofTarget(params, mu=mu)}
        for name in ("pinn", "picopinn"):
            path = Path(models) / params / f"{name}.safetensors"
            if path.is_file():
                try:
                    sources[name] = _core.SurrogateModel(str(path), mu=mu)
                except _core.ModelError as e:  # e.g. the scene's mu outside the model's range
                    raise TraceError(f"{path}: {e}") from None
        checkpoints = sorted({k1, k_end})
        psi0 = float(c["target_psi"][k0 - 1])
        # Per source and checkpoint: (heading turned since the start, unwrapped step by step; r).
        got: Dict[str, Dict[int, tuple]] = {n: {} for n in list(sources) + ["free"]}
        for name, model in list(sources.items()) + [("free", sources.get("picopinn", sources["4dof"]))]:
            x, turned = np.array([c[n][k0 - 1] for n in TARGET_STATE]), 0.0
            for k in range(k0, k_end + 1):
                u = [c["target_steer"][k], c["target_brake"][k]]
                if name != "free" and c["contact_fn"][k] > 0:
                    nx = model.step(x, u, [c["contact_fn"][k], c["contact_ft"][k]], float(c["contact_gamma"][k]),
                                    [c["contact_px"][k], c["contact_py"][k]])
                else:
                    nx = model.step(x, u)
                turned += _core.wrap_angle(float(nx[2] - x[2]))
                x = nx
                if k in checkpoints:
                    got[name][k] = (turned, float(x[3]))
        plan = None
        for p in self.result.get("plans") or []:
            if p["time"] <= t[k0 - 1] + 1e-9 and p["push_from"] is not None:
                plan = p
        truth_turn = np.unwrap(c["target_psi"][k0 - 1:k_end + 1]) - psi0
        rows = []
        for k in checkpoints:
            row: Dict[str, Any] = {"time": float(t[k]), "truth": (float(truth_turn[k - k0 + 1]), float(c["target_r"][k]))}
            row.update({name: g[k] for name, g in got.items()})
            row["plan"] = None
            if plan is not None:
                times, states = np.asarray(plan["predicted_time"]), np.asarray(plan["predicted_target"])
                j = int(np.argmin(np.abs(times - t[k])))
                if abs(times[j] - t[k]) < 1e-6:
                    # The plan's turn from its own start, plus where its start stood against psi0.
                    own = float(np.unwrap(states[: j + 1, 2])[-1] - states[0, 2])
                    row["plan"] = (own + _core.wrap_angle(float(states[0, 2]) - psi0), float(states[j, 3]))
            rows.append(row)
        fn = c["contact_fn"][k0:k1 + 1]
        impulse = float(fn.sum() * dt)
        point_x = float((fn * c["contact_px"][k0:k1 + 1]).sum() / max(fn.sum(), 1e-12))
        head = max(1, int(round(IMPACT_TIME / dt)))
        return {"start": float(t[k0 - 1]), "end": float(t[k1]), "impulse": impulse, "point_x": point_x,
                "impact": float(fn[:head].sum() * dt), "peak": float(fn.max()),
                "sustained": float(np.median(fn[head:])) if fn.size > head else None,
                "plan": None if plan is None else float(plan["time"]), "rows": rows}

    def push_model_lines(self, models: Path = Path("models")) -> List[str]:
        """:meth:`push_models` as text: the push, then one line per checkpoint and source
        with the heading turned since the push began (deg) and the yaw rate (deg/s)."""
        pm = self.push_models(models)
        if pm is None:
            return ["push models: no contact recorded (after the first step)"]
        plan = "no plan with a push before the contact" if pm["plan"] is None else f"plan at {pm['plan']:.2f} s"
        out = [f"push {pm['start']:.2f}-{pm['end']:.2f} s: {pm['impulse'] / 1000:.2f} kN s, contact point "
               f"{pm['point_x']:+.2f} m from the c.g. along the target; the models given the recorded push "
               f"and driver commands, the PicoPINN without the contact (free), the {plan}:"]
        names = ("truth", "4dof", "pinn", "picopinn", "free", "plan")
        out.append(f"{'at':>8} " + " ".join(f"{n:>16}" for n in names) + "   (turned deg / yaw rate deg/s)")
        for row in pm["rows"]:
            cells = []
            for n in names:
                v = row.get(n)
                cells.append(f"{'-':>16}" if v is None else f"{math.degrees(v[0]):7.1f} /{math.degrees(v[1]):7.1f}")
            out.append(f"{row['time']:7.2f}s " + " ".join(cells))
        return out

    def metrics(self) -> str:
        parts = []
        for k in METRICS:
            v = self.result.get(k)
            if isinstance(v, float):
                v = f"{v:.3f}"
            parts.append(f"{k} {v}")
        return "metrics: " + ", ".join(parts)

    def write_csv(self, path: Path) -> Path:
        path = Path(path)
        names = list(self.columns)
        data = np.column_stack([self.columns[k] for k in names])
        np.savetxt(path, data, delimiter=",", header=",".join(names), comments="", fmt="%.9g")
        return path


def config_text(config: str, clock: str = "simulated", controller_toml: Optional[Path] = None) -> str:
    """The configuration the core parses: a preset name or a JSON object, on ``clock`` unless
    it names one, with the controller settings of a TOML file in place of its own (for
    full-size and half-scale scenes alike)."""
    text = config.strip()
    if text.startswith("{"):
        try:
            doc = json.loads(text)
        except ValueError as e:
            raise TraceError(f"--config: not JSON: {e}") from None
        if not isinstance(doc, dict):
            raise TraceError("--config: expected a preset name or a JSON object")
    else:
        doc = {"preset": text}
    doc.setdefault("clock", clock)
    if controller_toml is not None:
        from .bench import BenchError, load_controller_config

        try:
            # The scene's settings whatever its parameter set (full size or half scale).
            doc["controller"] = doc["controller_half_scale"] = load_controller_config(
                str(controller_toml), "--controller-config")
        except BenchError as e:
            raise TraceError(str(e)) from None
    return json.dumps(doc)


def find_scene(path: Path, scene_id: str) -> Dict[str, Any]:
    """The scene ``scene_id`` of a scenario file (an integer is its 0-based position);
    raises :class:`TraceError` when there is none."""
    scenes = _core.load_scenarios(str(path))
    for s in scenes:
        if s["id"] == scene_id:
            return dict(s)
    if scene_id.isdigit() and int(scene_id) < len(scenes):
        return dict(scenes[int(scene_id)])
    near = [s["id"] for s in scenes[:3]]
    raise TraceError(f"{scene_id}: no such scene in {path} ({len(scenes)} scenes, e.g. {', '.join(near)})")


def trace(scene: Mapping[str, Any], config: str = "picopinn", seed: int = 0, models: Path = Path("models"),
          clock: str = "simulated", controller_toml: Optional[Path] = None) -> Trace:
    """Run the episode of ``scene`` with the trajectory recorded and add the road frame."""
    text = config_text(config, clock, controller_toml)
    try:
        r = _core.run_episode(json.dumps(dict(scene)), text, seed, record=True, models_dir=str(models))
    except (_core.EpisodeError, _core.ScenarioError) as e:
        raise TraceError(str(e)) from None
    tr = np.asarray(r.pop("trajectory"))
    cols = {k: tr[:, i] for i, k in enumerate(_core.trajectory_columns())}
    road = json.dumps(scene["road"])
    for who, x, y, psi in (("target", "target_x", "target_y", "target_psi"),
                           ("bullet", "bullet_x", "bullet_y", "bullet_psi")):
        f = np.asarray(_core.road_project(road, cols[x].tolist(), cols[y].tolist()))
        cols[f"{who}_s"] = f[:, 0]
        cols[f"{who}_d"] = f[:, 1]
        cols[f"{who}_dpsi"] = np.array([_core.wrap_angle(a) for a in cols[psi] - f[:, 2]])
    return Trace(scene=dict(scene), config=config, result=r, trajectory=tr, columns=cols)
