#!/usr/bin/env python3
"""picopit's coupled MPC side by side with CasADi peers on the identical OCP.

    source .venv/bin/activate
    python benchmarks/peers/run_peers.py [--steps 100] [--solvers ipopt,fatrop,sqp_hpipm]

1. Record a fixed set of states: a closed loop on the plant (``picopit._core.Plant``), as in
   ``crates/mpc/benches/ctrl_step.rs``: straight 3-lane road, target at 15 m/s in the middle
   lane, bullet 10 m behind and 3 m to the left at 17 m/s, picopit's CoupledMpc (4-DOF, RTI)
   with the default reference, 100 steps of 0.05 s; a negative T_r is realised through the
   service brakes with the same force (as ``Plant::set_bullet_command_blended``).
2. Replay the states in order through picopit RTI and picopit converged SCP (each warm-started
   from its own previous plan, as on the vehicle); after each RTI solve, read its
   linearisation and build the peers' OCP of that step (README.md) and solve it with every
   peer, starting from the linearisation point.
3. Score every plan with one yardstick, ``CoupledMpc.evaluate`` (picopit's nonlinear merit),
   and print time per step (median, p99) and merit side by side, with ratios to picopit RTI,
   for all steps and split into apart (bullet-only QP) and in-contact steps.

See README.md for the OCP and what differs.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Dict, List

import numpy as np

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.9 and 3.10: the tomli backport (a picopit dependency there)
    import tomli as tomllib

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from picopit import _core  # noqa: E402

from peer_ocp import OcpConfig, PeerOcp  # noqa: E402

PARAMS = "full_size"
MU = 0.9
DT = 0.05
PEERS = ("ipopt", "fatrop", "sqp_hpipm")
LABEL = {
    "rti": "picopit RTI (1 QP)",
    "conv": "picopit converged SCP",
    "ipopt": "CasADi + IPOPT",
    "fatrop": "CasADi + fatrop",
    "sqp_hpipm": "CasADi sqpmethod + HPIPM",
}


def make_mpc(mode: str = "rti") -> _core.CoupledMpc:
    settings = None
    if mode == "converged":
        settings = 'mode = "converged"\n'
    m = _core.CoupledMpc(PARAMS, MU, "4dof", settings)
    m.set_straight_road()
    return m


def record(steps: int) -> List[Dict[str, np.ndarray]]:
    """The closed loop of ctrl_step.rs on the plant, controlled by picopit RTI."""
    p = tomllib.loads(_core.load_params(PARAMS))["bullet"]
    brake_gain = p["drive_efficiency"] * p["gear_ratio"]  # plant: wheel torque per T_r
    plant = _core.Plant(PARAMS, MU)
    lane = 0.0  # middle lane of 3 is centred on Y = 0
    plant.reset([40.0, lane + 3.0, 0.0, 17.0, 0.0, 0.0], [50.0, lane, 0.0, 15.0, 0.0, 0.0])
    m = make_mpc()
    last = np.zeros(2)
    out = []
    for _ in range(steps):
        xt, xb = plant.target_state(), plant.bullet_state()
        out.append({"target": xt.copy(), "bullet": xb.copy(), "last": last.copy()})
        m.default_reference(xt, xb)
        last = np.asarray(m.solve(xt, xb, last_command=last)["command"], dtype=float)
        if last[1] >= 0.0:
            plant.set_commands(float(last[0]), float(last[1]))
        else:
            plant.set_commands(float(last[0]), 0.0, bullet_brake=-brake_gain * float(last[1]))
        plant.advance(DT)
    return out


def reference_scalars(m: _core.CoupledMpc, xt: np.ndarray, xb: np.ndarray):
    """target_heading and target_weight of the default reference (the binding returns the
    stages only): DefaultPit (left side) sets psi_rev = lane_heading + pi and the weight 1
    once engaged; engaged iff any stage's fn_lo > 0 (the corridor opens only then)."""
    ref = m.reference()
    engaged = bool(np.any(ref[:, 5] > 0.0))
    return ref, float(np.pi), 1.0 if engaged else 0.0


def stats(x: List[float]) -> Dict[str, float]:
    a = np.asarray(x, dtype=float)
    if a.size == 0:
        return {"median": float("nan"), "p99": float("nan"), "mean": float("nan")}
    return {
        "median": float(np.median(a)),
        "p99": float(np.percentile(a, 99)),
        "mean": float(np.mean(a)),
    }


def hard_violation(ocp: PeerOcp, u: np.ndarray, f: np.ndarray, last: np.ndarray,
                   fn_max: np.ndarray) -> float:
    """Largest violation of the hard rows (input bounds, steer rate, force bound, cone)."""
    v = 0.0
    v = max(v, np.max(np.abs(u[:, 0]) - ocp.steer_max))
    v = max(v, np.max(u[:, 1] - ocp.torque_max), np.max(ocp.torque_min - u[:, 1]))
    prev = np.concatenate([[last[0]], u[:-1, 0]])
    v = max(v, np.max(np.abs(u[:, 0] - prev) - ocp.steer_rate * ocp.dt))
    v_f = max(np.max(-f[:, 0]), np.max(f[:, 0] - fn_max),
              np.max(np.abs(f[:, 1]) - ocp.mu_c * f[:, 0]))
    return max(v, 0.0), max(v_f, 0.0)


def machine() -> Dict[str, str]:
    cpu = ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {
        "cpu": cpu,
        "cores": str(os.cpu_count()),
        "python": platform.python_version(),
        "uptime": subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip(),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--steps", type=int, default=100, help="recorded control steps (100)")
    ap.add_argument("--solvers", default=",".join(PEERS), help="peers to run (comma list)")
    ap.add_argument("--json", type=Path, default=None, help="write every number here")
    args = ap.parse_args(argv)
    peers = [s for s in args.solvers.split(",") if s]

    import casadi as ca

    t0 = time.perf_counter()
    states = record(args.steps)
    print(f"recorded {len(states)} states in {time.perf_counter() - t0:.3f} s", flush=True)

    rti, conv = make_mpc("rti"), make_mpc("converged")
    cfg = OcpConfig.from_mpc(_core.load_params(PARAMS), MU, rti.settings)
    t0 = time.perf_counter()
    ocps = {name: PeerOcp(cfg, name) for name in peers}
    print(f"built the CasADi solvers ({', '.join(peers)}) in {time.perf_counter() - t0:.1f} s "
          f"(outside the timing); NLP: {ocps[peers[0]].nz} variables, {ocps[peers[0]].ng} "
          f"constraints" if peers else "no peers", flush=True)

    rows: List[Dict[str, Any]] = []
    for i, st in enumerate(states):
        xt, xb, last = st["target"], st["bullet"], st["last"]
        row: Dict[str, Any] = {"step": i}
        # picopit RTI: the reference of this state, one QP.
        rti.default_reference(xt, xb)
        t = time.perf_counter()
        out = rti.solve(xt, xb, last_command=last)
        row["rti_wall"] = time.perf_counter() - t
        row["rti_total"] = out["times"]["total"]
        plan = rti.plan()
        row["rti_merit"], row["rti_viol"] = rti.evaluate(xt, xb, plan["u"], plan["f"],
                                                          last_command=last)
        row["rti_status"] = out["status"]
        row["coupled"] = bool(out["coupled"])
        lin = rti.linearisation()
        ref, psi_ref, wt = reference_scalars(rti, xt, xb)
        # picopit converged SCP on the same state (its own warm start).
        conv.default_reference(xt, xb)
        t = time.perf_counter()
        outc = conv.solve(xt, xb, last_command=last)
        row["conv_wall"] = time.perf_counter() - t
        row["conv_total"] = outc["times"]["total"]
        planc = conv.plan()
        row["conv_merit"], row["conv_viol"] = rti.evaluate(xt, xb, planc["u"], planc["f"],
                                                            last_command=last)
        row["conv_status"] = outc["status"]
        row["conv_iters"] = outc["scp_iterations"]
        # The peers on the RTI linearisation of this state.
        for name, ocp in ocps.items():
            d = ocp.data(lin, ref, xt, xb, last, np.zeros(2), psi_ref, wt)
            t = time.perf_counter()
            u, f, sstats, _ = ocp.solve(d)
            row[f"{name}_wall"] = time.perf_counter() - t
            row[f"{name}_status"] = sstats.get("return_status", "")
            row[f"{name}_success"] = bool(sstats.get("success", False))
            row[f"{name}_iters"] = int(sstats.get("iter_count", -1))
            row[f"{name}_merit"], row[f"{name}_viol"] = rti.evaluate(xt, xb, u, f,
                                                                      last_command=last)
            row[f"{name}_hard"] = hard_violation(ocp, u, f, last, np.asarray(lin["fn_max"]))
        rows.append(row)
        if i % 10 == 0:
            msg = " ".join(f"{n}={row[f'{n}_wall'] * 1e3:.1f}ms/{row[f'{n}_merit']:.4g}"
                           for n in peers)
            print(f"step {i:3d} coupled={row['coupled']!s:5} rti={row['rti_wall'] * 1e3:.2f}ms/"
                  f"{row['rti_merit']:.4g} conv={row['conv_wall'] * 1e3:.2f}ms/"
                  f"{row['conv_merit']:.4g} {msg}", flush=True)

    report(rows, peers)
    info = machine()
    print(f"\nmachine: {info['cpu']}, {info['cores']} cores; casadi {ca.__version__}; "
          f"load: {info['uptime']}")
    if args.json:
        args.json.write_text(json.dumps({"machine": info, "rows": rows}, indent=1, default=str))
    return 0


def report(rows: List[Dict[str, Any]], peers: List[str]) -> None:
    groups = {
        "all steps": rows,
        "apart (bullet-only QP)": [r for r in rows if not r["coupled"]],
        "in contact (coupled QP)": [r for r in rows if r["coupled"]],
    }
    names = ["rti", "conv"] + peers
    for gname, rs in groups.items():
        if not rs:
            continue
        base = stats([r["rti_wall"] for r in rs])
        base_merit = float(np.sum([r["rti_merit"] for r in rs]))
        print(f"\n{gname}: {len(rs)} steps")
        print(f"| solver | median ms | p99 ms | x RTI (median) | merit: median | sum | "
              f"x RTI (sum) | worst viol | ok |")
        print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
        for n in names:
            w = stats([r[f"{n}_wall"] for r in rs])
            merits = [r[f"{n}_merit"] for r in rs]
            msum = float(np.sum(merits))
            viol = max(r[f"{n}_viol"] for r in rs)
            if n in ("rti", "conv"):
                ok = f"{sum(r[f'{n}_status'] != 'QpFailure' for r in rs)}/{len(rs)}"
            else:
                ok = f"{sum(r[f'{n}_success'] for r in rs)}/{len(rs)}"
            print(f"| {LABEL[n]} | {w['median'] * 1e3:.2f} | {w['p99'] * 1e3:.2f} | "
                  f"{w['median'] / base['median']:.1f} | {np.median(merits):.4g} | {msum:.5g} | "
                  f"{msum / base_merit:.3f} | {viol:.3g} | {ok} |")
        tot = stats([r["rti_total"] for r in rs])
        totc = stats([r["conv_total"] for r in rs])
        print(f"(picopit's own times['total']: RTI median {tot['median'] * 1e3:.2f} ms, p99 "
              f"{tot['p99'] * 1e3:.2f} ms; converged median {totc['median'] * 1e3:.2f} ms, "
              f"p99 {totc['p99'] * 1e3:.2f} ms)")


if __name__ == "__main__":
    raise SystemExit(main())
