#!/usr/bin/env python3
"""Is the PicoPINN limited by its optimiser or by its size? (docs/surrogates.md, "What the
numbers say").

Prints the normalised one-step MSE of the teacher and the PicoPINN on the train and val
splits (a student that underfits has a higher train MSE than the teacher; one that
overfits, a val MSE above its train MSE), then fine-tunes the PicoPINN's θ_free and biases
with full-batch L-BFGS (strong Wolfe line search) on the retraining loss (one-step data +
0.3 · 4-step rollout on 20 000 windows + 0.05 · physics), printing the loss and the
validation numbers every 20 iterations. The model files are not changed.

    .venv/bin/python scripts/lbfgs_probe.py --data runs/surrogates/full_size/data \
        --models models/full_size --rounds 6
"""
import argparse
import time
from pathlib import Path

import torch

from picopit import datagen, load_params_dict
from picopit.physics import FourDof
from picopit.surrogate_nn import load_model
from picopit.train import (evaluate, increment_scale, one_step_loss, output_scale, physics_targets, prepare,
                           rollout_loss)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--models", required=True, help="folder with pinn.safetensors and picopinn.safetensors")
    ap.add_argument("--rounds", type=int, default=6, help="rounds of 20 L-BFGS iterations (default 6)")
    args = ap.parse_args()
    torch.set_num_threads(1)
    ds = datagen.load(Path(args.data))
    tr, va = prepare(ds, 4)
    teacher, _ = load_model(Path(args.models) / "pinn.safetensors")
    pico, _ = load_model(Path(args.models) / "picopinn.safetensors")
    for name, m in (("teacher", teacher), ("picopinn", pico)):
        t, v = evaluate(m, tr, 4), evaluate(m, va, 4)
        print(f"{name:8s} one-step MSE train {t['mse']:.4f} val {v['mse']:.4f} | val heading "
              f"{v['heading_rmse_rad'] * 1e3:.3f} mrad, 4-step {v['rollout_heading_rmse_rad'] * 1e3:.3f} mrad")
    model4 = FourDof.from_params(load_params_dict(ds.param_set)["target"], dt=float(ds.manifest["dt"]))
    phys = physics_targets(tr, model4, 0.5, 0)
    scale, oscale = increment_scale(tr), output_scale(pico, tr, "geometric")
    g = torch.Generator().manual_seed(1)
    wins = tr.win[torch.randperm(len(tr.win), generator=g)[:20000]]
    params = [p for p in pico.parameters() if p.requires_grad]
    opt = torch.optim.LBFGS(params, lr=1.0, max_iter=20, history_size=50, line_search_fn="strong_wolfe",
                            tolerance_grad=1e-12, tolerance_change=1e-15)

    def closure():
        opt.zero_grad()
        loss = (one_step_loss(pico, tr.z, tr.o, oscale) + 0.3 * rollout_loss(pico, tr, wins, 4, scale)
                + 0.05 * one_step_loss(pico, phys.z, phys.o, oscale))
        loss.backward()
        return loss

    print(f"   0 loss {float(closure().detach()):.6g}")
    t0 = time.time()
    for i in range(args.rounds):
        opt.step(closure)
        loss = float(closure().detach())
        v = evaluate(pico, va, 4)
        print(f"{(i + 1) * 20:4d} loss {loss:.6g} | val MSE {v['mse']:.4f}, heading {v['heading_rmse_rad'] * 1e3:.3f} mrad, "
              f"4-step {v['rollout_heading_rmse_rad'] * 1e3:.3f} mrad | {time.time() - t0:.0f} s")


if __name__ == "__main__":
    from picopit import ModelError
    from picopit.datagen import DatasetError
    from picopit.surrogate_nn import ModelFileError

    try:
        main()
    except (DatasetError, ModelError, ModelFileError, OSError) as e:
        raise SystemExit(f"{Path(__file__).name}: {e}")
