"""``picopit seed-scatter``: how much the surrogates' accuracies move with the training seed.

For each seed other than 0, a teacher is trained and a PicoPINN compressed from it as
``models/regenerate.sh`` does (same data, the seed in place of 0; ``picopit train``,
``compress``, ``eval-surrogates`` as child processes), and both are evaluated on the test split.
Seed 0 is the shipped pair: its evaluation is ``models/<set>/eval.json``. The table sets
teacher and PicoPINN side by side per seed, with the ratio.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any, Dict, List, Sequence

#: The table's columns: label, key of ``eval.json``'s models, scale, format.
ROWS = (("one-step heading (mrad)", "heading_rmse_rad", 1e3, "{:.3f}"),
        ("2 s rollout heading (rad)", "rollout_heading_rmse_rad", 1.0, "{:.4f}"),
        ("2 s rollout position (m)", "rollout_position_rmse_m", 1.0, "{:.3f}"),
        ("speed error at 2 s (m/s)", "rollout_final_speed_rmse_mps", 1.0, "{:.3f}"))
SETS = ("full_size", "half_scale")


class SeedScatterError(ValueError):
    """Bad input: a missing data folder or evaluation, a negative seed."""


def load_eval(path: Path) -> Dict[str, Any]:
    """``models.pinn`` and ``models.picopinn`` of an ``eval-surrogates`` JSON; raises
    :class:`SeedScatterError` naming the file."""
    try:
        m = json.loads(Path(path).read_text())["models"]
        return {"pinn": dict(m["pinn"]), "picopinn": dict(m["picopinn"])}
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise SeedScatterError(f"{path}: not an eval-surrogates JSON with models.pinn and "
                               f"models.picopinn ({type(e).__name__}: {e})") from None


def _train_seed(seed: int, param_set: str, data: Path, out: Path, models: Path) -> Path:
    """Train, compress and evaluate one seed (``python -m picopit`` for each step); returns
    its eval.json."""
    run = out / param_set / f"s{seed}"
    dst = out / f"models_s{seed}"
    other = next(s for s in SETS if s != param_set)
    # The other set links to the shipped models unless a run for it filled it already; a link
    # left for this set by such a run is replaced, never written through into the models.
    if (dst / param_set).is_symlink():
        (dst / param_set).unlink()
    (dst / param_set).mkdir(parents=True, exist_ok=True)
    run.mkdir(parents=True, exist_ok=True)
    if not (dst / other).exists():
        os.symlink((models / other).resolve(), dst / other)
    pinn, pico = dst / param_set / "pinn.safetensors", dst / param_set / "picopinn.safetensors"
    steps = (["train", "--data", str(data), "--out", str(run / "train"), "--model", str(pinn),
              "--seed", str(seed), "--no-progress"],
             ["compress", "--teacher", str(pinn), "--data", str(data), "--out", str(run / "compress"),
              "--model", str(pico), "--seed", str(seed), "--no-progress"],
             ["eval-surrogates", "--data", str(data), "--pinn", str(pinn), "--picopinn", str(pico),
              "--out", str(run / "eval"), "--json", str(run / "eval.json"), "--no-progress"])
    for argv in steps:
        rc = subprocess.run([sys.executable, "-m", "picopit", *argv]).returncode
        if rc != 0:
            raise SeedScatterError(f"seed {seed}: picopit {argv[0]} exited with status {rc}")
    return run / "eval.json"


def run(seeds: Sequence[int], param_set: str, data: Path, out: Path, models: Path = Path("models")
        ) -> List[Dict[str, Any]]:
    """The evaluation of each seed (training the seeds other than 0), in order."""
    if any(s < 0 for s in seeds):
        raise SeedScatterError(f"seeds {list(seeds)}: each a non-negative integer")
    if param_set not in SETS:
        raise SeedScatterError(f"--set {param_set}: one of {', '.join(SETS)}")
    if any(s != 0 for s in seeds) and not (Path(data) / "manifest.json").is_file():
        raise SeedScatterError(f"--data {data}: no datagen folder (run models/regenerate.sh {param_set} first)")
    return [load_eval(models / param_set / "eval.json") if s == 0
            else load_eval(_train_seed(s, param_set, Path(data), Path(out), Path(models))) for s in seeds]


def markdown(seeds: Sequence[int], evals: Sequence[Dict[str, Any]]) -> str:
    """Per seed, per column: teacher / PicoPINN (ratio); a dash where a value is missing."""
    head = "| seed | " + " | ".join(f"{r[0]}: teacher / PicoPINN (ratio)" for r in ROWS) + " |"
    lines = [head, "|---" * (len(ROWS) + 1) + "|"]
    for seed, m in zip(seeds, evals):
        cells = []
        for _, key, scale, fmt in ROWS:
            t, p = m["pinn"].get(key), m["picopinn"].get(key)
            cells.append("–" if t is None or p is None
                         else f"{fmt.format(t * scale)} / {fmt.format(p * scale)} ({p / t:.2f}×)")
        lines.append(f"| {seed} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
