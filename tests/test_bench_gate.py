"""scripts/bench_gate.py: benches judged by their ratio to the reference of the same run."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
spec = importlib.util.spec_from_file_location("bench_gate", ROOT / "scripts" / "bench_gate.py")
bench_gate = importlib.util.module_from_spec(spec)
sys.modules["bench_gate"] = bench_gate  # dataclasses look their module up by name
spec.loader.exec_module(bench_gate)

SPEC = """
margin = 1.5

[gates."ctrl_step/picopinn"]
reference = "reference/ctrl_step"
ratio = 700

[gates."ipc/state_to_command"]
absolute_ns = 300000
"""


def write_result(criterion: Path, bench: str, median_ns: float) -> None:
    """A criterion result folder as `cargo bench` leaves it (estimates and samples)."""
    d = criterion / bench / "new"
    d.mkdir(parents=True, exist_ok=True)
    (d / "estimates.json").write_text(json.dumps({"median": {"point_estimate": median_ns}}))
    iters = [10.0] * 50
    (d / "sample.json").write_text(json.dumps({"iters": iters, "times": [median_ns * n for n in iters]}))


def run(tmp_path: Path, results: dict[str, float], spec_text: str = SPEC) -> int:
    tmp_path.mkdir(parents=True, exist_ok=True)
    spec_path = tmp_path / "thresholds.toml"
    spec_path.write_text(spec_text)
    criterion = tmp_path / "criterion"
    for bench, ns in results.items():
        write_result(criterion, bench, ns)
    return bench_gate.main(["--spec", str(spec_path), "--criterion", str(criterion)])


def test_a_slower_machine_passes_where_slower_code_fails(tmp_path):
    ok = {"reference/ctrl_step": 3_000, "ctrl_step/picopinn": 2.1e6, "ipc/state_to_command": 90_000}
    assert run(tmp_path / "a", ok) == 0
    # The whole machine 2.5x slower: both scale, the ratio holds.
    slow_machine = {k: 2.5 * v if k != "ipc/state_to_command" else v for k, v in ok.items()}
    assert run(tmp_path / "b", slow_machine) == 0
    # The code 1.6x slower on the same machine: over the 1.5 margin.
    slow_code = dict(ok, **{"ctrl_step/picopinn": 1.6 * 2.1e6})
    assert run(tmp_path / "c", slow_code) == 1


def test_load_at_either_end_of_the_binary_counts(tmp_path):
    # The reference was fast at the start, the machine got busy, the bench and the closing
    # reference both ran slow: judged against the slower reference, it passes.
    loaded = {"reference/ctrl_step": 3_000, "reference/ctrl_step_end": 6_000,
              "ctrl_step/picopinn": 2 * 2.1e6, "ipc/state_to_command": 90_000}
    assert run(tmp_path, loaded) == 0


def test_missing_results_and_absolute_gates_fail(tmp_path, capsys):
    assert run(tmp_path / "a", {"ctrl_step/picopinn": 2.1e6, "ipc/state_to_command": 90_000}) == 1
    assert "no result for its reference reference/ctrl_step" in capsys.readouterr().out
    assert run(tmp_path / "b", {"reference/ctrl_step": 3_000, "ctrl_step/picopinn": 2.1e6,
                                "ipc/state_to_command": 400_000}) == 1
    assert run(tmp_path / "c", {"reference/ctrl_step": 3_000, "ipc/state_to_command": 90_000}) == 1


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("margin = 0.5\n[gates.a]\nabsolute_ns = 1\n", "margin = 0.5: must be a number ≥ 1"),
        ("margin = 1.5\n", "gates: missing or empty"),
        ("margin = 1.5\n[gates.a]\nratio = 2\n", "gates.'a'.reference: a ratio needs the reference"),
        ("margin = 1.5\n[gates.a]\nreference = \"r\"\nratio = -2\n", "gates.'a'.ratio = -2: must be a positive number"),
        ("margin = 1.5\n[gates.a]\nabsolute_ns = 5\nratio = 2\nreference = \"r\"\n", "exactly one of"),
        ("margin = 1.5\n[gates.a]\nabsolute_ns = 5\nlimit = 2\n", "unknown field 'limit'"),
        ("margin = [", "thresholds.toml"),
    ],
)
def test_a_malformed_spec_exits_2_naming_the_field(tmp_path, capsys, text, message):
    assert run(tmp_path, {}, text) == 2
    assert message in capsys.readouterr().err


def test_record_prints_the_measured_ratios(tmp_path, capsys):
    spec_path = tmp_path / "thresholds.toml"
    spec_path.write_text(SPEC)
    criterion = tmp_path / "criterion"
    write_result(criterion, "reference/ctrl_step", 2_000)
    write_result(criterion, "ctrl_step/picopinn", 1.5e6)
    assert bench_gate.main(["--spec", str(spec_path), "--criterion", str(criterion), "--record"]) == 0
    out = capsys.readouterr().out
    assert 'ratio = 750' in out and "absolute_ns = 300000" in out


def test_the_shipped_spec_gates_every_shipped_model_and_parses():
    margin, gates = bench_gate.load_spec(ROOT / "benches" / "thresholds.toml")
    assert margin <= 1.5
    for name in ("full_size_picopinn", "full_size_pinn", "half_scale_picopinn", "half_scale_pinn"):
        assert f"pico_models/step_jac_{name}" in gates
    for g in gates.values():
        if g.ratio is not None:
            assert g.reference.startswith("reference/")


def test_failing_names_the_binary_and_a_filter_for_a_rerun(tmp_path, capsys):
    import re

    spec_path = tmp_path / "thresholds.toml"
    spec_path.write_text(SPEC)
    criterion = tmp_path / "criterion"
    args = ["--spec", str(spec_path), "--criterion", str(criterion), "--failing"]
    # Within the limits: nothing to re-run.
    for bench, ns in {"reference/ctrl_step": 3_000, "ctrl_step/picopinn": 2.1e6,
                      "ipc/state_to_command": 90_000}.items():
        write_result(criterion, bench, ns)
    assert bench_gate.main(args) == 0
    assert capsys.readouterr().out == ""
    # The control step 1.6x slower and the IPC over its absolute limit: one line per binary.
    write_result(criterion, "ctrl_step/picopinn", 1.6 * 2.1e6)
    write_result(criterion, "ipc/state_to_command", 400_000)
    assert bench_gate.main(args) == 0
    lines = dict(line.split(" ", 1) for line in capsys.readouterr().out.splitlines())
    assert set(lines) == {"ctrl_step", "ipc"}
    ctrl = re.compile(lines["ctrl_step"])
    for name in ("ctrl_step/picopinn", "reference/ctrl_step", "reference/ctrl_step_end"):
        assert ctrl.search(name), name
    for name in ("ctrl_step/pinn", "reference/ctrl_step_x", "ipc/state_to_command"):
        assert not ctrl.search(name), name
    assert re.compile(lines["ipc"]).search("ipc/state_to_command")
