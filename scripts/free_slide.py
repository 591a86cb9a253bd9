#!/usr/bin/env python3
"""Each target model's free prediction (no contact force, the driver's input held) from one
recorded state of an episode: heading, yaw rate and speed every 0.5 s over 2 s
(docs/RESULTS.md, "Letting go").

Reads the state and the driver's input at time T from `trace_episode` (the `state` line
that `STATE_AT=T` prints) and the scene's μ and parameter set from the scenario file.

    cargo build --release -p picopit-sim --example trace_episode
    .venv/bin/python scripts/free_slide.py sc-00034 3.85 [--config JSON] [--seconds 2]
"""
import argparse
import os
import re
import subprocess
import sys

import numpy as np

from picopit import _core

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def recorded_state(scene: str, t: float, config: str):
    exe = os.path.join(ROOT, "target", "release", "examples", "trace_episode")
    if not os.path.isfile(exe):
        sys.exit(f"{exe} not found: cargo build --release -p picopit-sim --example trace_episode")
    run = subprocess.run([exe, scene, config], cwd=ROOT, env={**os.environ, "STATE_AT": str(t)},
                         capture_output=True, text=True)
    if run.returncode != 0:
        sys.exit(f"trace_episode {scene} failed: {(run.stderr.strip().splitlines() or ['?'])[-1]}")
    out = run.stdout
    m = re.search(r"^state t=(\S+) target \[([^\]]*)\] target_input \[([^\]]*)\]", out, re.M)
    if m is None:
        sys.exit(f"{scene}: no recorded state at {t} s (the episode ended before?)")
    vec = lambda s: np.array([float(v) for v in s.split(",")])  # noqa: E731
    return float(m.group(1)), vec(m.group(2)), vec(m.group(3))


def scene_of(scene: str, path: str) -> dict:
    """The scene from the scenario file, read and validated by the project's own loader."""
    try:
        scenes = _core.load_scenarios(path)
    except (OSError, _core.ScenarioError) as e:
        sys.exit(f"{path}: {e}")
    for sc in scenes:
        if sc.get("id") == scene:
            return sc
    sys.exit(f"{path}: no scene {scene}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene")
    ap.add_argument("time", type=float)
    ap.add_argument("--config", default='{"preset":"picopinn","clock":"simulated"}',
                    help="the episode's configuration, as for trace_episode")
    ap.add_argument("--seconds", type=float, default=2.0)
    ap.add_argument("--scenarios", default=os.path.join(ROOT, "data", "scenarios.jsonl"))
    args = ap.parse_args()
    sc = scene_of(args.scene, args.scenarios)
    t, x0, u = recorded_state(args.scene, args.time, args.config)
    mu, ps = float(sc["mu"]), sc["params"]
    models = {
        "4dof": _core.FourDofTarget(ps, mu=mu),
        "pinn": _core.SurrogateModel(os.path.join(ROOT, "models", ps, "pinn.safetensors"), mu=mu),
        "picopinn": _core.SurrogateModel(os.path.join(ROOT, "models", ps, "picopinn.safetensors"), mu=mu),
    }
    print(f"{args.scene} at {t:.2f} s, μ {mu:.3f}: heading {x0[2]:.3f} rad, yaw rate {x0[3]:.3f} rad/s, "
          f"speed {np.hypot(x0[0], x0[1]):.2f} m/s, slip {np.arctan2(x0[1], abs(x0[0])):.2f} rad; "
          f"driver input {u.tolist()}")
    dt = models["4dof"].dt
    steps = int(round(args.seconds / dt))
    every = max(1, int(round(0.5 / dt)))
    print("model      " + "  ".join(f"{(k + 1) * dt:>4.1f} s: ψ, r, v      " for k in range(every - 1, steps, every)))
    for name, m in models.items():
        if abs(m.dt - dt) > 1e-12:
            sys.exit(f"{name}: step {m.dt} s, the 4-DOF model's {dt} s")
        x, cells = x0.copy(), []
        for k in range(steps):
            x = m.step(x, u)
            if (k + 1) % every == 0:
                cells.append(f"{x[2]:6.2f} {x[3]:5.2f} {np.hypot(x[0], x[1]):5.2f}")
        print(f"{name:<10} " + "   ".join(cells))


if __name__ == "__main__":
    main()
