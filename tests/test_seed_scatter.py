"""``picopit seed-scatter``: seed 0 is the shipped pair's evaluation, tabulated teacher /
PicoPINN with the ratio; a seed to train without a datagen folder, or a malformed evaluation,
is one line naming it (exit status 2)."""

from __future__ import annotations

import json
from pathlib import Path

from picopit import cli, seed_scatter

ROOT = Path(__file__).resolve().parents[1]


def test_seed_zero_tabulates_the_shipped_pair(capsys):
    rc = cli.main(["seed-scatter", "0", "--models", str(ROOT / "models")])
    out = capsys.readouterr().out
    assert rc == 0, out
    m = json.loads((ROOT / "models" / "full_size" / "eval.json").read_text())["models"]
    t, p = m["pinn"]["heading_rmse_rad"], m["picopinn"]["heading_rmse_rad"]
    row = [l for l in out.splitlines() if l.startswith("| 0 |")][0]
    cell = row.split("|")[2].strip()
    assert cell == f"{t * 1e3:.3f} / {p * 1e3:.3f} ({p / t:.2f}×)"
    assert out.splitlines()[0].startswith("| seed | one-step heading (mrad)")


def test_a_missing_value_is_a_dash_and_a_ratio_is_picopinn_over_teacher():
    evals = [{"pinn": {"heading_rmse_rad": 0.002, "rollout_position_rmse_m": 0.5},
              "picopinn": {"heading_rmse_rad": 0.003, "rollout_position_rmse_m": 0.25}}]
    row = seed_scatter.markdown([7], evals).splitlines()[2]
    cells = [c.strip() for c in row.split("|")[1:-1]]
    assert cells == ["7", "2.000 / 3.000 (1.50×)", "–", "0.500 / 0.250 (0.50×)", "–"]


def test_bad_input_is_one_line_naming_it(tmp_path, capsys):
    rc = cli.main(["seed-scatter", "1", "--data", str(tmp_path / "nodata")])
    err = capsys.readouterr().err
    assert rc == 2 and "--data" in err and "regenerate.sh" in err and "Traceback" not in err
    bad = tmp_path / "models" / "full_size"
    bad.mkdir(parents=True)
    (bad / "eval.json").write_text('{"models": {"pinn": {}}}')
    rc = cli.main(["seed-scatter", "0", "--models", str(tmp_path / "models")])
    err = capsys.readouterr().err
    assert rc == 2 and "eval.json" in err and "models.picopinn" in err
    rc = cli.main(["seed-scatter", "-1"])
    assert rc == 2 and "non-negative" in capsys.readouterr().err
