#!/usr/bin/env python3
"""How well does each target model predict the free spin after the bullet lets go?
(docs/RESULTS.md, "Which layer does the surrogate matter in?").

On the test episodes of a datagen folder, every window of 2 s that starts at the first step
without contact after a contact (and stays free of contact) is rolled out by the 4-DOF
model, the PINN and the PicoPINN with the recorded driver inputs. Printed per model: the
RMSE of the projected heading ψ + τ·r at the window's end (τ = 0.4 s, the planner's
`yaw_decay`, what its terminal set and its `stabilise` decision use), its mean along the
direction of rotation (positive: predicts more spin), the share of windows off by more
than 0.3 rad, the final position RMSE and the mean final speed error.

    .venv/bin/python scripts/release_probe.py --data runs/surrogates/full_size/data \
        --models models/full_size
"""
import argparse
from pathlib import Path

import numpy as np

from picopit import datagen
from picopit.eval_surrogates import _fourdof, _learned, wrap_angles


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", required=True, help="datagen folder")
    ap.add_argument("--models", required=True, help="folder with pinn.safetensors and picopinn.safetensors")
    ap.add_argument("--horizon", type=int, default=40, help="steps of 0.05 s (default 40)")
    ap.add_argument("--tau", type=float, default=0.4, help="projection time of the yaw rate, s (default 0.4)")
    args = ap.parse_args()
    ds = datagen.load(Path(args.data))
    a = ds.subset("test")
    h = args.horizon
    contact = np.linalg.norm(a["fc"], axis=1) > 0
    ok = set(datagen.windows(a, h).tolist())
    rel = np.array([k for k in range(1, len(contact))
                    if contact[k - 1] and not contact[k] and a["step"][k] == a["step"][k - 1] + 1
                    and k in ok and not contact[k:k + h].any()], dtype=int)
    print(f"{ds.param_set}: {len(rel)} windows of {h} steps starting as the bullet lets go")
    if len(rel) == 0:
        return
    folder = Path(args.models)
    models = [_fourdof(ds.param_set), _learned("pinn", folder / "pinn.safetensors"),
              _learned("picopinn", folder / "picopinn.safetensors")]
    end = a["x_next"][rel + h - 1]
    proj_true = end[:, 2] + args.tau * end[:, 3]
    spin = np.sign(a["x"][rel, 3])
    for m in models:
        x = a["x"][rel].copy()
        for j in range(h):
            k = rel + j
            x = m.step(x, a["u"][k], a["fc"][k], a["gamma"][k], a["point"][k], a["mu"][k])
        e = wrap_angles(x[:, 2] + args.tau * x[:, 3] - proj_true)
        pos = np.hypot(x[:, 6] - end[:, 6], x[:, 7] - end[:, 7])
        dv = np.hypot(x[:, 0], x[:, 1]) - np.hypot(end[:, 0], end[:, 1])
        print(f"{m.name:9s} projected heading RMSE {np.sqrt(np.mean(e ** 2)):.3f} rad, "
              f"mean along the spin {np.mean(e * spin):+.3f} rad, off by > 0.3 rad {np.mean(np.abs(e) > 0.3):.2f}, "
              f"final position RMSE {np.sqrt(np.mean(pos ** 2)):.2f} m, mean speed error {dv.mean():+.2f} m/s")


if __name__ == "__main__":
    from picopit import ModelError
    from picopit.datagen import DatasetError
    from picopit.surrogate_nn import ModelFileError

    try:
        main()
    except (DatasetError, ModelError, ModelFileError, OSError) as e:
        raise SystemExit(f"{Path(__file__).name}: {e}")
