"""The surrogate pipeline's subcommands of the ``picopit`` command line: ``datagen``,
``train``, ``compress`` and ``eval-surrogates`` (they need the ``train`` extra: torch), and
the parameter-set name check ``simulate`` shares. Same conventions as ``cli``; the command
line as typed comes in ``args.command_line``."""

from __future__ import annotations

import argparse
import datetime as _dt
from pathlib import Path
from typing import Any, Dict, Optional, Tuple

from .outputs import check_dir, check_file


def check_params_name(name: str) -> None:
    """A friendlier message than the core's for a name that is neither built in nor a file."""
    from . import builtin_param_sets
    from .simulate import ConfigError

    if name not in builtin_param_sets() and not Path(name).exists():
        raise ConfigError(
            f"params = {name!r}: not a built-in parameter set ({', '.join(builtin_param_sets())}) "
            "nor an existing TOML file"
        )


def datagen_parser(sub) -> None:
    p = sub.add_parser(
        "datagen",
        help="collision data for the learned surrogates, from the plant (npz + manifest)",
        description=(
            "Run the plant over sampled PIT-like contacts (target speed, speed difference, "
            "contact angle and station, side, road mu, target driver) and record the target at "
            "the MPC step (0.05 s): x_k, u_k, the averaged contact and x_{k+1}. Episodes are "
            "split into train/val/test with the seed. Writes dataset.npz and manifest.json."
        ),
    )
    p.add_argument("--params", default="full_size", help="built-in parameter set or TOML (default full_size)")
    p.add_argument("--episodes", type=int, default=1200, metavar="N", help="episodes (default 1200)")
    p.add_argument("--seed", type=int, default=0, metavar="S", help="random seed (default 0)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_datagen)


def train_parser(sub) -> None:
    from .train import TrainConfig

    d = TrainConfig()
    p = sub.add_parser(
        "train",
        help="train the teacher PINN (data + rollout + 4-DOF physics loss)",
        description=(
            "Train the teacher PINN (tanh MLP, float64) on a datagen folder: one-step data loss, "
            "a multi-step rollout loss on the model's own predictions, and the residual of the "
            "4-DOF Newton-Euler equations with the contact force and moment. Writes the model "
            "file (docs/model-format.md), checkpoints, the history and the curve figure."
        ),
    )
    p.add_argument("--data", required=True, metavar="DIR", help="datagen output folder")
    p.add_argument("--out", required=True, metavar="DIR", help="folder for checkpoints, curves, history")
    p.add_argument("--model", metavar="PATH", help="model file to write (default OUT/pinn.safetensors)")
    p.add_argument("--layers", default=",".join(map(str, d.layers)), help=f"widths (default {','.join(map(str, d.layers))})")
    p.add_argument("--epochs", type=int, default=d.epochs, help=f"epochs (default {d.epochs})")
    p.add_argument("--batch", type=int, default=d.batch, help=f"batch size (default {d.batch})")
    p.add_argument("--lr", type=float, default=d.lr, help=f"initial learning rate (default {d.lr})")
    p.add_argument("--w-data", type=float, default=d.w_data, help=f"one-step data weight (default {d.w_data})")
    p.add_argument("--w-rollout", type=float, default=d.w_rollout, help=f"rollout weight (default {d.w_rollout})")
    p.add_argument("--w-physics", type=float, default=d.w_physics, help=f"physics weight (default {d.w_physics})")
    p.add_argument("--no-physics", action="store_true", help="ablation: physics weight 0")
    p.add_argument("--base", default=d.base, help=(
        f"fixed linear base of the increments: impulse (kinematics and the contact's rigid-body "
        f"impulse) or kinematic (ablation) (default {d.base})"))
    p.add_argument("--horizon", type=int, default=d.horizon, help=f"rollout steps (default {d.horizon})")
    p.add_argument("--seed", type=int, default=d.seed, help=f"random seed (default {d.seed})")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_train)


def compress_parser(sub) -> None:
    from .compress import CompressConfig

    d = CompressConfig()
    p = sub.add_parser(
        "compress",
        help="PicoPINN from a teacher: distil, Ward-cluster, retrain (Psi-NN)",
        description=(
            "Distil a student from the teacher (teacher outputs + 1e-3 sum ||W||_2), cluster each "
            "weight tensor's |w| (Ward) to the free-parameter budget, tie w = sign * centre "
            "(w = R theta_free), retrain theta_free with data + physics. Writes the model file, "
            "the threshold-vs-parameters figure and the curves."
        ),
    )
    p.add_argument("--teacher", required=True, metavar="PATH", help="teacher model file")
    p.add_argument("--data", required=True, metavar="DIR", help="datagen output folder")
    p.add_argument("--out", required=True, metavar="DIR", help="folder for figures and history")
    p.add_argument("--model", metavar="PATH", help="model file to write (default OUT/picopinn.safetensors)")
    p.add_argument("--student", default=",".join(map(str, d.student)), help=f"student widths (default {','.join(map(str, d.student))})")
    p.add_argument("--budget", type=int, default=d.budget, help=f"free-parameter budget (default {d.budget})")
    p.add_argument("--distil-epochs", type=int, default=d.distil_epochs, help=f"(default {d.distil_epochs})")
    p.add_argument("--retrain-epochs", type=int, default=d.retrain_epochs, help=f"(default {d.retrain_epochs})")
    p.add_argument("--w-physics", type=float, default=d.w_physics, help=f"physics weight in retraining (default {d.w_physics})")
    p.add_argument("--no-physics", action="store_true", help="ablation: physics weight 0 in retraining")
    p.add_argument("--w-rollout", type=float, default=d.w_rollout, help=f"rollout weight in retraining (default {d.w_rollout})")
    p.add_argument("--horizon", type=int, default=d.horizon, help=f"rollout steps in retraining (default {d.horizon})")
    p.add_argument("--output-weights", metavar="W1,...,W8",
                   help="per-output loss weights (dvx,dvy,dr,dp,dphi,dpsi,dx,dy; default all 1)")
    p.add_argument("--seed", type=int, default=d.seed, help=f"random seed (default {d.seed})")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_compress)


def eval_parser(sub) -> None:
    p = sub.add_parser(
        "eval-surrogates",
        help="4-DOF vs PINN vs PicoPINN on held-out episodes: one-step and 2 s rollout errors",
        description=(
            "Evaluate the 4-DOF model (Rust), the teacher PINN and PicoPINN on the test episodes "
            "of a datagen folder: one-step errors and open-loop rollouts with the recorded inputs "
            "and contacts. Prints a Markdown table; writes eval.md, eval.json and eval.png to OUT."
        ),
    )
    p.add_argument("--data", required=True, metavar="DIR", help="datagen output folder")
    p.add_argument("--pinn", required=True, metavar="PATH", help="teacher model file")
    p.add_argument("--picopinn", required=True, metavar="PATH", help="PicoPINN model file")
    p.add_argument("--out", metavar="DIR", help="folder for eval.md, eval.json, eval.png")
    p.add_argument("--json", metavar="PATH", help="also write the results JSON here")
    p.add_argument("--horizon", type=int, default=40, help="rollout steps (default 40 = 2 s)")
    p.add_argument("--stride", type=int, default=10, help="a rollout starts every STRIDE steps (default 10)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_eval)


def _cmd_datagen(args: argparse.Namespace) -> int:
    from . import datagen

    check_params_name(args.params)
    cfg = datagen.DatagenConfig.for_params(args.params, episodes=args.episodes, seed=args.seed)
    check_dir(args.out, "--out")
    arrays, manifest = datagen.generate(cfg, progress=not args.no_progress)
    manifest["command"] = args.command_line
    manifest["created"] = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    from .surrogate_nn import git_commit

    manifest["git_commit"] = git_commit()
    paths = datagen.write(arrays, manifest, Path(args.out))
    c = manifest["counts"]
    print(f"datagen: {c['episodes']} episodes ({c['episodes_with_contact']} with contact), {c['samples']} samples "
          f"({c['contact_samples']} in contact); train/val/test episodes {c['train_episodes']}/"
          f"{c['val_episodes']}/{c['test_episodes']} (seed {cfg.seed})")
    print(f"datagen: wrote {paths['npz']} and {paths['manifest']} ({manifest['data_hash']})")
    return 0


def _provenance(ds, seed: int, config: Dict[str, Any], command: str) -> Dict[str, Any]:
    from .surrogate_nn import git_commit

    import torch

    return {"data_hash": ds.data_hash, "seed": str(seed), "git_commit": git_commit(),
            "command": command, "train_config": config,
            "torch_threads": str(torch.get_num_threads())}


def _mu_range(ds) -> tuple:
    """The road-μ span the model was trained on: the sampling range of the data (or, for a
    dataset without one, the span of its μ values)."""
    mu = ds.manifest.get("sampling", {}).get("mu")
    if mu is None:
        return float(ds.arrays["mu"].min()), float(ds.arrays["mu"].max())
    return float(mu[0]), float(mu[1])


def _cmd_train(args: argparse.Namespace) -> int:
    from . import datagen
    from .surrogate_nn import save_model
    from .train import TrainConfig, parse_layers, train_teacher

    cfg = TrainConfig(
        layers=parse_layers(args.layers), epochs=args.epochs, batch=args.batch, lr=args.lr,
        w_data=args.w_data, w_rollout=args.w_rollout,
        w_physics=0.0 if args.no_physics else args.w_physics, horizon=args.horizon, seed=args.seed,
        base=args.base,
    ).validate()
    ds = datagen.load(Path(args.data))
    out = check_dir(args.out, "--out")
    path = check_file(Path(args.model) if args.model else out / "pinn.safetensors", "--model")
    model, info = train_teacher(ds, cfg, out, progress=not args.no_progress)
    save_model(model, path, kind="pinn", param_set=ds.param_set, mu_range=_mu_range(ds),
               provenance=_provenance(ds, cfg.seed, info["config"], args.command_line))
    v = info["val"]
    print(f"train: {model.param_count} parameters, {cfg.epochs} epochs in {info['seconds']:.0f} s; val one-step "
          f"heading RMSE {v['heading_rmse_rad']:.5f} rad, {cfg.horizon}-step rollout {v['rollout_heading_rmse_rad']:.5f} rad "
          f"(seed {cfg.seed}, physics weight {cfg.w_physics:g}, {cfg.base} base)")
    print(f"train: wrote {path}, {out / 'train_curves.png'}, {out / 'checkpoints'}")
    return 0


def _float_list(name: str, text: Optional[str]) -> Optional[Tuple[float, ...]]:
    """A comma-separated list of numbers, or None; a bad entry is refused naming the option."""
    if text is None:
        return None
    try:
        return tuple(float(v) for v in text.split(","))
    except ValueError:
        from .train import TrainError

        raise TrainError(f"{name} = {text!r}: expected comma-separated numbers") from None


def _cmd_compress(args: argparse.Namespace) -> int:
    from . import datagen
    from .compress import CompressConfig, compress
    from .surrogate_nn import load_model, save_model
    from .train import parse_layers

    cfg = CompressConfig(
        student=parse_layers(args.student), budget=args.budget, distil_epochs=args.distil_epochs,
        retrain_epochs=args.retrain_epochs, w_physics=0.0 if args.no_physics else args.w_physics,
        w_rollout=args.w_rollout, horizon=args.horizon,
        output_weights=_float_list("output_weights", args.output_weights),
        seed=args.seed,
    ).validate()
    ds = datagen.load(Path(args.data))
    teacher, meta = load_model(Path(args.teacher))
    if meta["param_set"] != ds.param_set:
        from .datagen import DatasetError

        raise DatasetError(f"param_set: teacher {args.teacher} is {meta['param_set']!r}, data {ds.param_set!r}")
    if abs(teacher.dt - float(ds.manifest["dt"])) > 1e-12:
        from .datagen import DatasetError

        raise DatasetError(f"dt: teacher {args.teacher} steps {teacher.dt} s, data {ds.manifest['dt']} s")
    out = check_dir(args.out, "--out")
    path = check_file(Path(args.model) if args.model else out / "picopinn.safetensors", "--model")
    pico, info = compress(teacher, ds, cfg, out, progress=not args.no_progress)
    config = dict(info["config"], teacher=str(args.teacher), teacher_data_hash=meta.get("data_hash", ""),
                  threshold=info["clustering"]["threshold"])
    save_model(pico, path, kind="picopinn", param_set=ds.param_set, mu_range=_mu_range(ds),
               provenance=_provenance(ds, cfg.seed, config, args.command_line))
    v, vt = info["val"], info["val_teacher"]
    print(f"compress: student {info['student_params']} -> {pico.param_count} free parameters "
          f"(threshold {info['clustering']['threshold']:.4g}); val one-step heading RMSE "
          f"{v['heading_rmse_rad']:.5f} rad (teacher {vt['heading_rmse_rad']:.5f}), rollout "
          f"{v['rollout_heading_rmse_rad']:.5f} rad (teacher {vt['rollout_heading_rmse_rad']:.5f}) (seed {cfg.seed})")
    print(f"compress: wrote {path}, {out / 'cluster_threshold.png'}, {out / 'retrain_curves.png'}")
    return 0


def _cmd_eval(args: argparse.Namespace) -> int:
    import json

    from . import datagen, eval_surrogates as ev

    if args.horizon < 1 or args.stride < 1:
        from .datagen import DatasetError

        raise DatasetError(f"horizon = {args.horizon}, stride = {args.stride}: must be positive integers")
    ds = datagen.load(Path(args.data))
    if args.out:
        check_dir(args.out, "--out")
    if args.json:
        check_file(args.json, "--json")
    res = ev.run(ds, Path(args.pinn), Path(args.picopinn), horizon=args.horizon, stride=args.stride,
                 progress=not args.no_progress)
    res["command"] = args.command_line
    table = ev.markdown(res)
    print(f"eval-surrogates: {ds.param_set}, {res['test_episodes']} test episodes, {res['test_samples']} samples "
          f"({res['contact_samples']} in contact), {args.horizon}-step rollouts every {args.stride} steps")
    print(table, end="")
    targets = []
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "eval.md").write_text(table)
        ev.plot(res, out / "eval.png")
        targets += [out / "eval.json"]
    if args.json:
        targets.append(Path(args.json))
    for t in targets:
        t.parent.mkdir(parents=True, exist_ok=True)
        with open(t, "w") as fh:
            json.dump(res, fh, indent=2)
            fh.write("\n")
    if targets or args.out:
        print("eval-surrogates: wrote " + ", ".join(str(t) for t in targets + ([Path(args.out) / "eval.png"] if args.out else [])))
    return 0
