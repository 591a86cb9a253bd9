"""The analysis scripts over example outputs: scripts/oracle_surrogate.py counts what the
lines say and refuses a malformed file naming the line; scripts/seed_scatter.sh tabulates the
shipped pair for seed 0 and refuses bad arguments naming them; scripts/reversal_split.py
splits two runs into reaching the reversal and what follows, and names a malformed line."""
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "scripts" / "oracle_surrogate.py"

LINES = [
    "scene sc-00001 curved lane_keep low ideal=1 | 4dof first=1 robust=1 exp=0.67 both=10 "
    "model_only=10 truth_only=0 | picopinn first=0 robust=0 exp=0.00 both=0 model_only=5 "
    "truth_only=10",
    "scene sc-00002 straight_urban none high ideal=1 | 4dof first=0 robust=1 exp=0.33 both=0 "
    "model_only=30 truth_only=10 | picopinn first=1 robust=1 exp=1.00 both=10 model_only=0 "
    "truth_only=0",
    "some other line the example prints",
]


def run(*args):
    return subprocess.run([sys.executable, str(SCRIPT), *map(str, args)],
                          capture_output=True, text=True)


def test_oracle_surrogate_tables_count_the_lines(tmp_path):
    log = tmp_path / "surrogate.txt"
    log.write_text("\n".join(LINES) + "\n")
    episodes = tmp_path / "episodes.txt"
    episodes.write_text(
        "sc-00001 curved low success at 12.00 s | …\n"
        "sc-00002 straight_urban high boundary_violation Target at 5.00 s | …\n")
    r = run(log, "--episodes", episodes, "--model", "picopinn")
    assert r.returncode == 0, r.stderr
    rows = {}  # the first row of each label: the choices' table, then the closed loop's
    for l in r.stdout.splitlines():
        if l.startswith("| "):
            rows.setdefault(l.split("|")[1].strip(), [c.strip() for c in l.split("|")[2:-1]])
    # all: n, ideal, 4dof first / robust / exp, picopinn first / robust / exp
    assert rows["**all**"][:8] == ["2", "100.0 %", "50.0 %", "100.0 %", "50.0 %", "50.0 %",
                                   "50.0 %", "50.0 %"]
    assert rows["adhesion low"][:3] == ["1", "100.0 %", "100.0 %"]
    # 4dof: both 10, called 50, works 20; picopinn: both 10, called 15, works 20.
    verdict = [l for l in r.stdout.splitlines() if l.startswith("| **all** |")][1]
    assert [c.strip() for c in verdict.split("|")[2:-1]] == ["20.0 %", "50.0 %", "66.7 %", "50.0 %"]
    # PicoPINN's first shove works in sc-00002 only, which the closed loop lost.
    assert rows["works"] == ["1", "0"] and rows["fails or none"] == ["1", "1"]


def test_oracle_surrogate_refuses_a_malformed_line(tmp_path):
    log = tmp_path / "bad.txt"
    log.write_text(LINES[0] + "\nscene sc-00003 curved\n")
    r = run(log)
    assert r.returncode == 1
    assert "line 2" in r.stderr and r.stdout == ""
    r = run(tmp_path / "missing.txt")
    assert r.returncode == 1 and "missing.txt" in r.stderr


def test_oracle_surrogate_sets_the_optimum_against_the_average_feasible_shove(tmp_path):
    lines = [
        # 4dof calls shoves feasible in both scenes; picopinn in the first only.
        "scene sc-00001 curved lane_keep low ideal=1 | 4dof first=1 robust=1 exp=0.67 best=1 "
        "mean=0.500 both=2 model_only=2 truth_only=0 | picopinn first=0 robust=0 exp=0.00 "
        "best=0 mean=0.250 both=1 model_only=3 truth_only=1",
        "scene sc-00002 curved none high ideal=1 | 4dof first=0 robust=0 exp=0.00 best=0 "
        "mean=0.000 both=0 model_only=4 truth_only=2 | picopinn first=0 robust=0 exp=0.00 "
        "best=0 mean=0.000 both=0 model_only=0 truth_only=2",
    ]
    log = tmp_path / "surrogate.txt"
    log.write_text("\n".join(lines) + "\n")
    r = run(log)
    assert r.returncode == 0, r.stderr
    table = r.stdout.split("the model's optimum")[1]
    row = [l for l in table.splitlines() if l.startswith("| **all** |")][0]
    cells = [c.strip() for c in row.split("|")[2:-1]]
    # 4dof: 2 scenes, best (1 + 0) / 2, mean (0.5 + 0) / 2; picopinn: 1 scene, 0 and 0.25.
    assert cells == ["2", "50.0 %", "25.0 %", "+25.0 points",
                     "1", "0.0 %", "25.0 %", "-25.0 points"]
    # Logs without the fields (older runs) print no such tables.
    old = tmp_path / "old.txt"
    old.write_text("\n".join(LINES) + "\n")
    out = run(old).stdout
    assert "the model's optimum" not in out and "rejects" not in out


def test_oracle_surrogate_says_what_the_model_holds_against_the_shoves_it_rejects(tmp_path):
    miss = " miss_heading={} miss_road={} miss_stop={} miss_obstacle={}"
    lines = [
        "scene sc-00001 curved lane_keep low ideal=1 | 4dof first=1 robust=1 exp=0.67 "
        "both=2 model_only=2 truth_only=4" + miss.format(4, 0, 1, 0),
        "scene sc-00002 curved none high ideal=1 | 4dof first=0 robust=0 exp=0.00 "
        "both=0 model_only=4 truth_only=6" + miss.format(1, 6, 0, 2),
    ]
    log = tmp_path / "surrogate.txt"
    log.write_text("\n".join(lines) + "\n")
    r = run(log)
    assert r.returncode == 0, r.stderr
    row = [l for l in r.stdout.split("rejects")[1].splitlines() if l.startswith("| 4dof |")][0]
    # 10 rejected successes: heading 5, road 6, stop 1, obstacle 2.
    assert [c.strip() for c in row.split("|")[2:-1]] == ["10", "50.0 %", "60.0 %", "10.0 %",
                                                         "20.0 %"]


SEED_SCATTER = ROOT / "scripts" / "seed_scatter.sh"


def seed_scatter(*args, **env):
    return subprocess.run(["bash", str(SEED_SCATTER), *map(str, args)], capture_output=True,
                          text=True, env={**os.environ, "PYTHON": sys.executable, **env})


def test_seed_scatter_reads_the_shipped_pair_for_seed_0():
    r = seed_scatter(0)
    assert r.returncode == 0, r.stderr
    m = json.loads((ROOT / "models" / "full_size" / "eval.json").read_text())["models"]
    row = [l for l in r.stdout.splitlines() if l.startswith("| 0 |")]
    assert len(row) == 1
    cells = [c.strip() for c in row[0].split("|")[2:-1]]
    t, p = m["pinn"]["heading_rmse_rad"], m["picopinn"]["heading_rmse_rad"]
    assert cells[0] == f"{t * 1e3:.3f} / {p * 1e3:.3f} ({p / t:.2f}×)"
    t, p = m["pinn"]["rollout_heading_rmse_rad"], m["picopinn"]["rollout_heading_rmse_rad"]
    assert cells[1] == f"{t:.4f} / {p:.4f} ({p / t:.2f}×)"


def test_seed_scatter_refuses_bad_arguments_naming_them(tmp_path):
    r = seed_scatter("x")
    assert r.returncode == 2 and "'x'" in r.stderr
    r = seed_scatter("--set", "quarter_scale", 1)
    assert r.returncode == 2 and "quarter_scale" in r.stderr
    missing = tmp_path / "no-data"
    r = seed_scatter("--data", missing, 1)
    assert r.returncode == 2 and str(missing) in r.stderr and r.stdout == ""
    r = seed_scatter()
    assert r.returncode == 2 and "usage" in r.stderr


def test_seed_scatter_trains_into_its_own_folder_never_into_the_shipped_models(tmp_path):
    # A stand-in for the picopit command line: writes the files it is asked for (the
    # evaluation a copy of the shipped one) and logs its calls.
    fake = tmp_path / "picopit"
    log = tmp_path / "calls.txt"
    shipped = ROOT / "models" / "full_size" / "eval.json"
    fake.write_text(f"""#!/usr/bin/env bash
echo "$@" >> {log}
while [ $# -gt 0 ]; do
  case "$1" in
    --model) echo model > "$2"; shift 2 ;;
    --json) cp {shipped} "$2"; shift 2 ;;
    *) shift ;;
  esac
done
""")
    fake.chmod(0o755)
    data = tmp_path / "data"
    data.mkdir()
    (data / "manifest.json").write_text("{}")
    out = tmp_path / "out"
    before = {p: p.read_bytes() for p in (ROOT / "models").rglob("*.safetensors")}
    for s in ("half_scale", "full_size"):  # the second run finds the first's link to models/
        r = seed_scatter("--set", s, "--data", data, "--out", out, 3, PICOPIT=str(fake))
        assert r.returncode == 0, r.stderr
        assert "| 3 |" in r.stdout
    for s in ("half_scale", "full_size"):
        d = out / "models_s3" / s
        assert d.is_dir() and not d.is_symlink()
        assert (d / "pinn.safetensors").read_text() == "model\n"
    assert {p: p.read_bytes() for p in (ROOT / "models").rglob("*.safetensors")} == before
    calls = log.read_text().splitlines()
    assert [c.split()[0] for c in calls] == ["train", "compress", "eval-surrogates"] * 2
    assert all("--seed 3" in c for c in calls if not c.startswith("eval"))


SPLIT = ROOT / "scripts" / "reversal_split.py"


def _episode(scene, outcome, impact, reversed_at):
    imp = "-" if impact is None else f"x {impact[0]:.2f} y 0.80 v {impact[1]:.2f}"
    rev = "-" if reversed_at is None else f"t {reversed_at:.2f} v 1.00"
    return (f"{scene} curved high {outcome} at 6.00 s | herr 0.10 margin 0.20 contacts 1 | "
            f"plan 0.01/ 0.01 ms (7) ctrl 0.01/ 0.02 ms | Done None | fail 0 budget 0 | "
            f"wall 0.30 s | impact {imp} | reversed {rev}")


def _trace(phases):
    """A trace_episode output: (t, phase, heading deg, F_n) lines and two plan lines."""
    lines = [f"t= {t:5.2f} {ph} Δs= -3.00 T: d=-1.50 ψ-h= {h:6.1f}° v= 9.00 | "
             f"B: d= 0.20 ψ-h=  -8.0° v=10.00 | cmd (-0.100, -300.0) Fn= {fn:6.0f}"
             for t, ph, h, fn in phases]
    lines += ["plan t= 2.00 Pit push 3.05–3.85 s peak 9000 N, predicted heading error  0.10 rad",
              "plan t= 3.10 Pit push 3.10–3.90 s peak 3000 N, predicted heading error  0.05 rad"]
    return "\n".join(lines) + "\n"


def test_reversal_split_counts_reversals_and_the_let_go(tmp_path):
    a, b = tmp_path / "a.txt", tmp_path / "b.txt"
    a.write_text("\n".join([
        _episode("sc-00001", "success", (-1.5, 3.0), 5.0),
        _episode("sc-00002", "boundary_violation Target", (-1.7, 2.0), 6.5),
        _episode("sc-00003", "success", (-1.5, 3.0), 5.0),
        _episode("sc-00004", "secondary_collision Target", None, None),
    ]) + "\n")
    b.write_text("\n".join([
        _episode("sc-00001", "success", (-1.3, 3.4), 5.2),
        _episode("sc-00002", "boundary_violation Target", (-1.5, 2.2), None),
        _episode("sc-00003", "no_termination", (-1.5, 3.0), 5.5),
        _episode("sc-00004", "success", (-1.5, 3.0), 4.0),
    ]) + "\n")
    r = subprocess.run([sys.executable, str(SPLIT), a, b, "--both-contacted"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["sc-00001", "sc-00002", "sc-00003"]
    for d in ("ta", "tb"):
        (tmp_path / d).mkdir()
        for s in ("sc-00001", "sc-00002", "sc-00003"):
            # pushes from 3.0 s, let go at 3.6 s having turned 40° (a) or 30° (b) at 100 or 50°/s
            last = 40.0 if d == "ta" else 30.0
            rate = 100.0 if d == "ta" else 50.0
            (tmp_path / d / f"{s}.txt").write_text(_trace([
                (2.90, "Chasing", 0.0, 0), (3.00, "Pit", 1.0, 9000), (3.50, "Pit", last - 0.1 * rate, 2000),
                (3.60, "Stabilising", last, 0), (3.70, "Stabilising", last + 10, 0)]))
    r = subprocess.run([sys.executable, str(SPLIT), a, b, "--traces", tmp_path / "ta", tmp_path / "tb"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    rows = {}
    for l in r.stdout.splitlines():
        cells = [c.strip() for c in l.strip().strip("|").split("|")]
        rows[cells[0]] = cells[1:]
    assert rows["scenes brought into contact"] == ["3", "4"]
    # of the three both touch, both reverse sc-00001 and sc-00003, only A sc-00002
    key = next(k for k in rows if k.startswith("targets reversed of the 3 both touch"))
    assert rows[key] == ["3 (2 / 1)", "2 (2 / 0)"]
    # both reverse two; A saves both, B one
    assert rows["successes among the 2 both reverse"] == ["2", "1"]
    key = next(k for k in rows if k.startswith("at the let-go"))
    assert rows[key] == ["40.0°, 100°/s, 0.60 s", "30.0°, 50°/s, 0.60 s"]
    # the plan at 2.00 s was made before the first contact (3.00 s): only the 3000 N one counts
    assert rows["mean peak force of the PIT plans made in contact"] == ["3000 N", "3000 N"]


def test_reversal_split_refuses_a_malformed_line_naming_it(tmp_path):
    a = tmp_path / "a.txt"
    a.write_text(_episode("sc-00001", "success", (-1.5, 3.0), 5.0) + "\nsc-00002 curved high\n")
    r = subprocess.run([sys.executable, str(SPLIT), a, a], capture_output=True, text=True)
    assert r.returncode == 1 and f"{a}:2: not an episodes line" in r.stderr
    r = subprocess.run([sys.executable, str(SPLIT), a.with_name("none.txt"), a], capture_output=True, text=True)
    assert r.returncode == 1 and "none.txt" in r.stderr
    other = tmp_path / "other.txt"
    other.write_text(_episode("sc-00009", "success", (-1.5, 3.0), 5.0) + "\n")
    (tmp_path / "ok.txt").write_text(_episode("sc-00001", "success", (-1.5, 3.0), 5.0) + "\n")
    r = subprocess.run([sys.executable, str(SPLIT), tmp_path / "ok.txt", other], capture_output=True, text=True)
    assert r.returncode == 1 and "no scene in common" in r.stderr
