#!/usr/bin/env python3
"""How much of a one-step heading error is the timing of the contact within the step?

The surrogates (and the 4-DOF model) see the contact of a step as its impulse average: force,
normal and point averaged over the 0.05 s step. Two contacts with the same average give the
same yaw-rate change, but not the same heading change: a push early in the step turns the car
for longer than the same push late in it, Δψ ≈ r·dt + Δr·dt·(1 − τ) with τ the impulse
centroid as a fraction of the step. This script regenerates a datagen dataset with τ recorded
(``datagen.generate(..., impulse_timing=True)``: the same episodes, seed and split as
``picopit datagen``), then measures on its test split

* two analytic oracles that know the true next yaw rate r⁺ (information no surrogate has):
  the trapezoid Δψ = dt·(r + r⁺)/2, and the timed one Δψ = dt·r + dt·(r⁺ − r)·(1 − τ);
* two networks of the teacher's width trained on the same training split for the heading
  increment alone: on the model's 11 features, and on the features plus τ;
* how much of τ itself a network of that width predicts from the 11 features (R² on the
  contact steps of the test split).

The first network is what the model inputs allow for the heading alone, the second how much
of the rest is the timing, and the R² whether the inputs could tell the timing. Run from the
repository root with the venv:

    .venv/bin/python scripts/contact_timing.py --params full_size --json runs/contact_timing_full.json

(about 4 min on 2 cores). Results and the reading of them: docs/surrogates.md.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
import torch

from picopit import datagen, load_params_dict
from picopit.eval_surrogates import wrap_angles
from picopit.physics import FourDof
from picopit.surrogate_nn import features, increments, physics_base

DT = datagen.DT
PSI = 5  # Δψ in the increment order


def rmse(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(e * e))) if e.size else float("nan")


def split_errors(e: np.ndarray, contact: np.ndarray) -> dict:
    """Heading RMSE (mrad) over all samples, contact steps and free steps."""
    return {"all_mrad": 1e3 * rmse(e), "contact_mrad": 1e3 * rmse(e[contact]),
            "free_mrad": 1e3 * rmse(e[~contact])}


def fit_mlp(inputs: np.ndarray, target: np.ndarray, train: np.ndarray, epochs: int, seed: int,
            width: int = 64) -> np.ndarray:
    """A tanh MLP (3 hidden layers of ``width``) fitted to ``target`` on the ``train`` rows by
    Adam with cosine decay; returns its predictions on every row."""
    g = torch.Generator().manual_seed(seed)
    torch.manual_seed(seed)
    x = torch.from_numpy(inputs)
    y = torch.from_numpy(target)
    mx, sx = x[train].mean(0), x[train].std(0).clamp(min=1e-12)
    my, sy = y[train].mean(), y[train].std().clamp(min=1e-12)
    xn, yn = (x - mx) / sx, (y - my) / sy
    n_in = x.shape[1]
    net = torch.nn.Sequential(
        torch.nn.Linear(n_in, width), torch.nn.Tanh(), torch.nn.Linear(width, width), torch.nn.Tanh(),
        torch.nn.Linear(width, width), torch.nn.Tanh(), torch.nn.Linear(width, 1)).double()
    opt = torch.optim.Adam(net.parameters(), lr=3e-3)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=epochs, eta_min=1e-4)
    rows = torch.from_numpy(np.flatnonzero(train))
    for _ in range(epochs):
        for b in rows[torch.randperm(len(rows), generator=g)].split(1024):
            opt.zero_grad()
            loss = ((net(xn[b]).squeeze(1) - yn[b]) ** 2).mean()
            loss.backward()
            opt.step()
        sched.step()
    with torch.no_grad():
        return (net(xn).squeeze(1) * sy + my).numpy()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--params", default="full_size", help="parameter set (default full_size)")
    ap.add_argument("--episodes", type=int, default=2500, help="episodes (default 2500, as models/regenerate.sh)")
    ap.add_argument("--seed", type=int, default=0, help="datagen seed (default 0, as models/regenerate.sh)")
    ap.add_argument("--epochs", type=int, default=60, help="epochs per network (default 60)")
    ap.add_argument("--json", type=Path, help="write the results here")
    ap.add_argument("--plot", type=Path, help="write a figure of the heading error against τ here")
    args = ap.parse_args(argv)
    if args.episodes < 10 or args.epochs < 1:
        ap.error("--episodes must be >= 10 and --epochs >= 1")
    try:
        p = load_params_dict(args.params)
    except (ValueError, OSError) as e:  # ParamError is a ValueError naming the field
        ap.error(f"--params {args.params!r}: {e}")
    torch.set_num_threads(1)

    t0 = time.time()
    cfg = datagen.DatagenConfig.for_params(args.params, episodes=args.episodes, seed=args.seed)
    a, manifest = datagen.generate(cfg, progress=sys.stderr.isatty(), impulse_timing=True)
    t_gen = time.time() - t0
    m4 = FourDof.from_params(p["target"], dt=DT)
    T = {k: torch.from_numpy(np.ascontiguousarray(a[k], dtype=np.float64))
         for k in ("x", "u", "fc", "gamma", "point", "x_next", "mu")}
    z = features(T["x"], T["u"], T["fc"], T["gamma"], T["point"], T["mu"]).numpy()
    o = increments(T["x"], T["x_next"]).numpy()
    o[:, PSI] = wrap_angles(o[:, PSI])
    r, r_next = a["x"][:, 3], a["x_next"][:, 3]
    contact = a["fc"][:, 0] > 0
    tau = a["tau"]
    train, test = a["split"] == 0, a["split"] == 2
    c_test = contact[test]

    # Analytic oracles (they know r⁺).
    dpsi = o[:, PSI]
    trapezoid = dpsi - DT * 0.5 * (r + r_next)
    timed = dpsi - (DT * r + DT * (r_next - r) * (1.0 - np.where(contact, tau, 0.5)))
    results = {
        "params": args.params, "episodes": args.episodes, "seed": args.seed, "data_hash": manifest["data_hash"],
        "test_samples": int(test.sum()), "test_contact_samples": int(c_test.sum()),
        "tau_contact": {"mean": float(np.mean(tau[contact])), "std": float(np.std(tau[contact]))},
        "oracle_trapezoid": split_errors(trapezoid[test], c_test),
        "oracle_timed": split_errors(timed[test], c_test),
    }

    # Networks for Δψ − r·dt − M_z·dt²/(2 I_z) (the impulse base's heading part).
    target = dpsi - z @ physics_base(DT, m4.mass, m4.iz)[PSI]
    tau_in = np.where(contact, tau, 0.5)[:, None]
    inputs = {
        "net_features": z,
        "net_features_tau": np.hstack([z, tau_in]),
    }
    preds = {}
    for i, (name, x) in enumerate(inputs.items()):
        t1 = time.time()
        preds[name] = fit_mlp(x, target, train, args.epochs, args.seed + i)
        e = (target - preds[name])[test]
        results[name] = split_errors(e, c_test)
        print(f"contact_timing: {name}: {results[name]['all_mrad']:.3f} mrad ({time.time() - t1:.0f} s)",
              file=sys.stderr)
    # Is τ predictable from the features? (contact steps only)
    ct = np.flatnonzero(contact)
    tau_hat = fit_mlp(z[ct], tau[ct], train[ct], args.epochs, args.seed + len(inputs))
    tt = test[ct]
    results["tau_r2_from_features"] = float(1.0 - np.mean((tau[ct][tt] - tau_hat[tt]) ** 2) / np.var(tau[ct][tt]))
    results["seconds"] = {"datagen": t_gen, "total": time.time() - t0}

    rows = [("trapezoid with the true r⁺ (oracle)", "oracle_trapezoid"),
            ("r⁺ and the impulse timing τ (oracle)", "oracle_timed"),
            ("network on the 11 features", "net_features"),
            ("network on the 11 features and τ", "net_features_tau")]
    print(f"\n{args.params}: {args.episodes} episodes (seed {args.seed}), test split "
          f"{results['test_samples']} samples, {results['test_contact_samples']} in contact; "
          f"τ on contact steps: mean {results['tau_contact']['mean']:.2f}, std {results['tau_contact']['std']:.2f}\n")
    print("| one-step heading RMSE (mrad) | all | in contact | free |")
    print("|---|---|---|---|")
    for label, key in rows:
        v = results[key]
        print(f"| {label} | {v['all_mrad']:.2f} | {v['contact_mrad']:.2f} | {v['free_mrad']:.2f} |")
    print(f"\nτ predicted from the 11 features: R² = {results['tau_r2_from_features']:.2f} on the test contact steps")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(results, indent=2) + "\n")
        print(f"\ncontact_timing: wrote {args.json}")
    if args.plot:
        errors = {k: (target - preds[k])[test][c_test] for k in preds}
        errors["oracle_timed"] = timed[test][c_test]
        errors["oracle_trapezoid"] = trapezoid[test][c_test]
        plot(args.plot, tau[test][c_test], errors, args.params)
        print(f"contact_timing: wrote {args.plot}")
    return 0


def plot(path: Path, tau: np.ndarray, errors: dict, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    edges = np.linspace(0.0, 1.0, 11)
    mid = 0.5 * (edges[1:] + edges[:-1])
    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    labels = {"net_features": "network on the features", "net_features_tau": "… and τ",
              "oracle_trapezoid": "trapezoid, true r⁺", "oracle_timed": "true r⁺ and τ"}
    for k, e in errors.items():
        y = [1e3 * rmse(e[(tau >= lo) & (tau < hi)]) for lo, hi in zip(edges[:-1], edges[1:])]
        ax.plot(mid, y, marker="o", label=labels.get(k, k))
    ax.set_xlabel("impulse centroid τ within the step")
    ax.set_ylabel("heading RMSE on contact steps (mrad)")
    ax.set_title(f"{title}: one-step heading error vs contact timing")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
