#!/usr/bin/env python3
"""How long and how hard are the contacts: in surrogate training data, and in the closed
loop? (docs/surrogates.md, item 6 "Sustained pushes in the data").

A contact run is a stretch of consecutive 0.05 s steps in contact. Printed per source: the
number of runs, their length in steps (median, p90, max), their peak and mean force
(median, p90; kN). Datasets: the train split of each datagen folder. Closed loop: the
full-size scenes FIRST, FIRST+STEP, … below STOP of the scenario file, run with CONFIG
(a preset or JSON, as `picopit bench` takes it) on two processes.

    .venv/bin/python scripts/contact_runs.py --data runs/surrogates/full_size/data \
        --closed-loop 4dof --scenes 0:192:2
"""
import argparse
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np


def runs(force: np.ndarray, step: np.ndarray) -> np.ndarray:
    """(length, peak, mean) of every run of consecutive steps with force > 0."""
    out, k = [], 0
    while k < len(force):
        if force[k] > 0:
            j = k + 1
            while j < len(force) and force[j] > 0 and step[j] == step[j - 1] + 1:
                j += 1
            out.append((j - k, force[k:j].max(), force[k:j].mean()))
            k = j
        else:
            k += 1
    return np.array(out).reshape(-1, 3)


def report(name: str, r: np.ndarray) -> None:
    if len(r) == 0:
        print(f"{name}: no contact")
        return
    p = lambda c, q: np.percentile(r[:, c], q)  # noqa: E731
    print(f"{name}: {len(r)} runs | steps {p(0, 50):.0f} / {p(0, 90):.0f} / {r[:, 0].max():.0f} "
          f"| peak kN {p(1, 50) / 1e3:.1f} / {p(1, 90) / 1e3:.1f} | mean kN {p(2, 50) / 1e3:.1f} / {p(2, 90) / 1e3:.1f}")


def _episode(job):
    import picopit

    line, config, models = job
    t = picopit.run_episode(line, config, 0, record=True, models_dir=models)["trajectory"]
    if len(t) == 0:
        return np.zeros((0, 3))
    # Sample columns 19 and 20: the contact force [F_n, F_t] averaged over the step.
    return runs(np.hypot(t[:, 19], t[:, 20]), np.arange(len(t)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", nargs="*", default=[], help="datagen folders")
    ap.add_argument("--closed-loop", metavar="CONFIG", help="a benchmark configuration")
    ap.add_argument("--scenes", default="0:192:2", metavar="FIRST:STOP:STEP")
    ap.add_argument("--scenarios", default="data/scenarios.jsonl")
    ap.add_argument("--models", default="models")
    args = ap.parse_args()
    for d in args.data:
        from picopit import datagen

        a = datagen.load(Path(d)).subset("train")
        force = np.linalg.norm(a["fc"], axis=1)
        # runs never cross an episode: the step index restarts at 0
        report(f"{d} (train split)", runs(force, a["step"]))
    if args.closed_loop:
        try:
            first, stop, step = (int(v) for v in args.scenes.split(":"))
            if min(first, stop, step) < 0 or step == 0:
                raise ValueError
        except ValueError:
            ap.error(f"--scenes {args.scenes!r}: expected FIRST:STOP:STEP, non-negative integers, STEP > 0")
        lines = Path(args.scenarios).read_text().splitlines()[first:stop:step]
        jobs = [(l, args.closed_loop, args.models) for l in lines if '"full_size"' in l]
        with ProcessPoolExecutor(2) as ex:
            parts = list(ex.map(_episode, jobs))
        report(f"closed loop {args.closed_loop}, {len(jobs)} full-size scenes", np.concatenate(parts))


if __name__ == "__main__":
    from picopit import ModelError
    from picopit.datagen import DatasetError
    from picopit.surrogate_nn import ModelFileError

    try:
        main()
    except (DatasetError, ModelError, ModelFileError, OSError) as e:
        raise SystemExit(f"{Path(__file__).name}: {e}")
