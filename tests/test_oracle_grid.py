"""``picopit oracle --grid-plot``: the whole grid of single shoves on a scene, drawn, with a
run's first contact marked. The map is the bound's own search laid out: its first success is
the shove the bound reports."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from picopit import _core, cli, oracle, oracle_grid

ROOT = Path(__file__).resolve().parents[1]
TEXTBOOK = ROOT / "data" / "textbook" / "scenarios.jsonl"
COARSE = '{"shoves": [0.5, 1.0, 1.5, 2.0, 2.5], "time_step": 0.25}'


def _scene(sid: str):
    return oracle.select(_core.load_scenarios(str(TEXTBOOK)), ids=[sid])[0]


def test_the_map_holds_the_shove_the_bound_finds_first():
    """The bound searches time by time, size by size, side by side and stops at the first
    success; the map simulates every cell: its first success in that order is the bound's."""
    sc = _scene("sc-00002")
    settings = oracle.resolve_settings(COARSE, tiers=False)
    m = oracle_grid.shove_map(sc, settings)
    bound = _core.ideal_pit(json.dumps(dict(sc)), json.dumps(settings))
    assert bound["feasible"] and m.successes > 0
    assert m.success.shape == (len(m.times), 2, 5) and m.times[0] >= m.t_reach - 1e-9
    assert np.allclose(np.diff(m.times), 0.25)
    first = next((t, v, s) for it, t in enumerate(m.times) for iv, v in enumerate(m.shoves)
                 for js, s in enumerate(m.sides) if m.success[it, js, iv])
    shove = bound["shove"]
    assert first == pytest.approx((shove["time"], shove["dv"], shove["side"]))
    assert 1 <= m.widest_band() <= 5
    at = m.at(shove["time"], shove["side"])
    assert at is not None and at[m.shoves.index(shove["dv"])]


def test_a_map_of_zero_shoves_is_empty():
    m = oracle_grid.shove_map(_scene("sc-00002"), oracle.resolve_settings('{"shoves": [0.0], "time_step": 0.5}',
                                                                         tiers=False))
    assert m.successes == 0 and m.widest_band() == 0 and len(m.times) > 3


def test_grid_plot_draws_each_scene_and_marks_the_runs_contact(tmp_path, capsys):
    """--grid-run marks the configuration's first contact and names the sizes that succeed
    at that time on that side; a scene the run did not touch is drawn without a mark."""
    sc = _scene("sc-00002")
    settings = oracle.resolve_settings(COARSE, tiers=True)
    m = oracle_grid.shove_map(sc, settings)
    t = float(m.times[2])
    run = tmp_path / "episodes.csv"
    run.write_text("config,scenario,contact_at,impact_y,success,reversed_at\n"
                   f"picopinn,sc-00002,{t},-0.7,False,{t + 1.5}\n"
                   "picopinn,sc-00004,,,False,\n")
    out = tmp_path / "maps"
    rc = cli.main(["oracle", "--scenarios", str(TEXTBOOK), "--ids", "sc-00002,sc-00004", "--settings", COARSE,
                   "--grid-plot", str(out), "--grid-run", str(run)])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert (out / "sc-00002_shoves.png").stat().st_size > 5000 and (out / "sc-00004_shoves.png").exists()
    lines = {ln.split(":")[0]: ln for ln in text.splitlines() if ln.startswith("sc-")}
    sizes = [f"{v:g}" for v, ok in zip(m.shoves, m.success[2, m.sides.index(-1.0)]) if ok]
    assert f"first contact at {t:.2f} s on the right (lost after reversal)" in lines["sc-00002"]
    assert f"sizes that succeed there: {', '.join(sizes) or 'none'} m/s" in lines["sc-00002"]
    assert f"{m.successes} of {m.success.size} shoves succeed" in lines["sc-00002"]
    assert "first contact" not in lines["sc-00004"]


@pytest.mark.parametrize("argv, words", [
    (["--ids", "sc-00002", "--grid-run", "x"], "--grid-run: only with --grid-plot"),
    (["--n", "21", "--grid-plot", "{tmp}"], "at most 20"),
    (["--ids", "sc-00002", "--grid-plot", "{tmp}", "--tiers"], "not with --tiers"),
    (["--ids", "sc-00002", "--grid-plot", "{tmp}", "--grid-run", "{tmp}/missing"], "no such run"),
    (["--ids", "sc-00002", "--grid-plot", "{file}"], "not a folder"),
])
def test_grid_plot_refuses_bad_input_naming_it(tmp_path, capsys, argv, words):
    (tmp_path / "f.txt").write_text("x")
    argv = [a.replace("{tmp}", str(tmp_path)).replace("{file}", str(tmp_path / "f.txt")) for a in argv]
    rc = cli.main(["oracle", "--scenarios", str(TEXTBOOK), "--no-progress", *argv])
    err = capsys.readouterr().err
    assert rc == 2 and words in err and "Traceback" not in err, err
