"""``picopit scenarios``: the PIT Scenario Dataset, sampled from a table of priors.

Pipeline (docs/scenarios.md):

1. Read the priors (``data/priors.csv``): one row per parameterised prior with a weight,
   a road category, ranges of target speed, speed difference, gap, lanes, lane width,
   shoulder, curve radius and adhesion, an obstacle density, a target-driver behaviour,
   the parameter set, ``T_max`` and ``ε_ψ``.
2. Generate ``n`` scenarios (3600 by default): each picks a prior by weight and samples its
   attributes uniformly inside the prior's ranges with its own seed (``SeedSequence(seed)``
   spawned per scenario, so every scenario is reproducible on its own).
3. Screen each one through the Rust core (``_core.screen_scenario``): geometry rules, then
   the target alone on the plant under its driver: ``rejected`` / ``trivial`` (stops by
   itself) / ``impossible`` (leaves the road or hits something before the bullet can reach
   it) / ``keep``.
4. Select ``keep`` (2048 by default) of the kept scenarios, stratified by category at the
   target shares (straight-urban 22 %, straight-highway 18 %, curved 60 %), in generation
   order within each category.
5. Compare generated and retained scenarios with the priors: per-attribute KL divergence
   ``KL(P_data || P_prior)`` (nats) on fixed bins; the prior's distribution of an attribute
   is the weight-averaged mixture of the priors' uniform ranges.

Outputs: ``scenarios.jsonl`` (one scenario per line, schema in docs/scenarios.md),
``scenarios.manifest.json`` (seed, command, counts per stage, composition, KL, SHA-256 of the
JSONL, run time) and two figures (category breakdown per stage, KL per attribute).
"""

from __future__ import annotations

import csv
import hashlib
import json
import math
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from . import _core, load_params_dict

CATEGORIES = ("straight_urban", "straight_highway", "curved")
#: Target shares of the retained dataset (the paper: 22.0 / 17.9 / 60.1 %).
TARGET_SHARES = {"straight_urban": 0.22, "straight_highway": 0.18, "curved": 0.60}
ADHESION = ("low", "mid", "high")
DENSITIES = ("none", "sparse", "medium", "dense")
#: Obstacles per density (inclusive ranges).
DENSITY_COUNTS = {"none": (0, 0), "sparse": (1, 2), "medium": (3, 4), "dense": (5, 7)}
DRIVERS = ("none", "lane_keep", "brake", "counter_steer")
PARAM_SETS = ("full_size", "half_scale")
BULLET_LANES = ("adjacent", "same")
#: Adhesion band boundaries (as crates/sim: low < 0.4 <= mid < 0.7 <= high).
MU_LOW_MID, MU_MID_HIGH = 0.4, 0.7

PRIOR_COLUMNS = (
    "prior_id", "category", "params", "weight",
    "target_speed_lo", "target_speed_hi", "speed_diff_lo", "speed_diff_hi",
    "gap_lo", "gap_hi", "bullet_lane",
    "lanes_lo", "lanes_hi", "lane_width_lo", "lane_width_hi", "shoulder_lo", "shoulder_hi",
    "radius_lo", "radius_hi", "mu_band", "mu_lo", "mu_hi",
    "density", "driver", "t_max", "eps_psi_deg", "source",
)

#: Bins of the continuous attributes for the KL divergence.
BINS: Dict[str, np.ndarray] = {
    "target_speed": np.arange(0.0, 30.01, 2.0),
    "speed_diff": np.arange(0.0, 7.01, 0.5),
    "gap": np.arange(0.0, 14.01, 1.0),
    "mu": np.arange(0.1, 1.001, 0.05),
    "lane_width": np.arange(1.5, 4.01, 0.25),
    "radius": np.array([0.0, 20, 40, 60, 80, 100, 130, 160, 200, 250, 300, 400, 500, 650]),
}
CATEGORICAL = {
    "category": CATEGORIES, "adhesion": ADHESION, "density": DENSITIES, "driver": DRIVERS,
    "params": PARAM_SETS, "lanes": tuple(range(1, 9)), "obstacles": tuple(range(0, 8)),
}


class ScenarioGenError(ValueError):
    """A bad priors file or generation setting; the message names the row and the column."""


# --------------------------------------------------------------------------------------
# Priors
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Prior:
    prior_id: str
    category: str
    params: str
    weight: float
    target_speed: Tuple[float, float]
    speed_diff: Tuple[float, float]
    gap: Tuple[float, float]
    bullet_lane: str
    lanes: Tuple[int, int]
    lane_width: Tuple[float, float]
    shoulder: Tuple[float, float]
    radius: Tuple[float, float]
    mu_band: str
    mu: Tuple[float, float]
    density: str
    driver: str
    t_max: float
    eps_psi: float
    source: str


def _band(mu: float) -> str:
    return "low" if mu < MU_LOW_MID else ("mid" if mu < MU_MID_HIGH else "high")


def parse_priors(rows: Iterable[Mapping[str, str]], source: str = "priors") -> List[Prior]:
    """Validate rows of the priors table (dicts of strings, as csv.DictReader gives)."""
    out: List[Prior] = []
    seen = set()
    for i, row in enumerate(rows, start=2):  # line 1 is the header
        where = f"{source}: line {i}"

        def num(col: str, lo: float = -math.inf, hi: float = math.inf) -> float:
            raw = row.get(col)
            if raw is None or raw == "":
                raise ScenarioGenError(f"{where}: {col}: missing")
            try:
                v = float(raw)
            except ValueError:
                raise ScenarioGenError(f"{where}: {col}: {raw!r} is not a number") from None
            if not (math.isfinite(v) and lo <= v <= hi):
                raise ScenarioGenError(f"{where}: {col}: {v} must lie in [{lo}, {hi}]")
            return v

        def pair(name: str, lo: float, hi: float) -> Tuple[float, float]:
            a, b = num(f"{name}_lo", lo, hi), num(f"{name}_hi", lo, hi)
            if a > b:
                raise ScenarioGenError(f"{where}: {name}_lo = {a} exceeds {name}_hi = {b}")
            return a, b

        def choice(col: str, options: Sequence[str]) -> str:
            v = (row.get(col) or "").strip()
            if v not in options:
                raise ScenarioGenError(f"{where}: {col}: {v!r} is not one of {', '.join(options)}")
            return v

        missing = [c for c in PRIOR_COLUMNS if c not in row]
        if missing:
            raise ScenarioGenError(f"{where}: missing column(s) {', '.join(missing)}")
        pid = (row["prior_id"] or "").strip()
        if not pid or pid in seen:
            raise ScenarioGenError(f"{where}: prior_id: {pid!r} is empty or repeated")
        seen.add(pid)
        category = choice("category", CATEGORIES)
        radius = pair("radius", 0.0, 5000.0)
        if (category == "curved") != (radius[0] > 0):
            raise ScenarioGenError(f"{where}: radius_lo: curved priors need radii > 0, straight ones 0")
        mu = pair("mu", 0.05, 1.2)
        mu_band = choice("mu_band", ADHESION)
        if _band(mu[0]) != mu_band or _band(mu[1] - 1e-9) != mu_band:
            raise ScenarioGenError(f"{where}: mu_lo/mu_hi: {mu} leaves the {mu_band} band")
        lanes = pair("lanes", 1, 8)
        out.append(Prior(
            prior_id=pid, category=category, params=choice("params", PARAM_SETS),
            weight=num("weight", 0.0, 1e6),
            target_speed=pair("target_speed", 0.5, 40.0), speed_diff=pair("speed_diff", 0.0, 15.0),
            gap=pair("gap", 0.2, 50.0), bullet_lane=choice("bullet_lane", BULLET_LANES),
            lanes=(int(lanes[0]), int(lanes[1])), lane_width=pair("lane_width", 1.0, 5.0),
            shoulder=pair("shoulder", 0.0, 5.0), radius=radius, mu_band=mu_band, mu=mu,
            density=choice("density", DENSITIES), driver=choice("driver", DRIVERS),
            t_max=num("t_max", 2.0, 120.0), eps_psi=math.radians(num("eps_psi_deg", 1.0, 90.0)),
            source=(row.get("source") or "").strip(),
        ))
    if not out:
        raise ScenarioGenError(f"{source}: no priors")
    if sum(p.weight for p in out) <= 0:
        raise ScenarioGenError(f"{source}: weight: the weights sum to zero")
    return out


def load_priors(path: Path) -> List[Prior]:
    try:
        with open(path, newline="") as fh:
            return parse_priors(csv.DictReader(fh), source=str(path))
    except OSError as e:
        raise ScenarioGenError(f"cannot read {path}: {e}") from None


def design_priors() -> List[Dict[str, Any]]:
    """The shipped prior table (docs/scenarios.md, "Priors"): a factorial design over the
    published ranges, 117 rows. Weights make the categories 22 / 18 / 60 % of the draws
    and the adhesion bands 45 / 35 / 20 % (high / mid / low)."""
    rows: List[Dict[str, Any]] = []
    mu_ranges = {  # band -> (lo, hi, source)
        "high": (0.75, 1.0, "dry asphalt 0.8-1.0 (Bosch 0.85)"),
        "mid": (0.45, 0.69, "wet asphalt 0.5-0.65, heavy rain 0.55"),
        "low": (0.15, 0.39, "gravel 0.35, snow 0.2-0.25, icy patches >= 0.15"),
    }
    mu_w = {"high": 0.45, "mid": 0.35, "low": 0.20}
    dens_w = {"none": 0.15, "sparse": 0.35, "medium": 0.30, "dense": 0.20}
    drivers = ("lane_keep", "none", "brake", "counter_steer")

    def add(cat, params, w, ts, dv, gap, lane, lanes, lw, sh, rad, band, dens, drv, tmax, src):
        lo, hi, mu_src = mu_ranges[band] if params == "full_size" else (
            (0.75, 0.95, "dry test track") if band == "high" else (0.5, 0.69, "wet test track"))
        rows.append(dict(
            prior_id=f"P{len(rows) + 1:03d}", category=cat, params=params, weight=w,
            target_speed_lo=ts[0], target_speed_hi=ts[1], speed_diff_lo=dv[0], speed_diff_hi=dv[1],
            gap_lo=gap[0], gap_hi=gap[1], bullet_lane=lane, lanes_lo=lanes[0], lanes_hi=lanes[1],
            lane_width_lo=lw[0], lane_width_hi=lw[1], shoulder_lo=sh[0], shoulder_hi=sh[1],
            radius_lo=rad[0], radius_hi=rad[1], mu_band=band, mu_lo=lo, mu_hi=hi,
            density=dens, driver=drv, t_max=tmax, eps_psi_deg=20.0,
            source=f"{src}; mu: {mu_src}"))

    k = 0
    # Straight urban, full size: 24 = 2 speed bands x 3 adhesion x 4 densities.
    for ts in ((8.0, 12.0), (11.0, 15.6)):
        for band in ADHESION:
            for dens in DENSITIES:
                drv = drivers[k % 4]
                k += 1
                add("straight_urban", "full_size", 0.21 * mu_w[band] * dens_w[dens] / 2, ts, (1.0, 5.0),
                    (3.0, 10.0), "adjacent" if k % 3 else "same", (2, 3), (3.0, 3.5), (0.3, 1.0),
                    (0, 0), band, dens, drv, 12.0,
                    "urban 30-55 km/h; PIT at <= 35 mph common; lanes 3.0-3.5 m")
    # Straight highway, full size: 21 = 2 speed bands x 3 adhesion x 4 densities, less the
    # three dense combinations of the fast band.
    for ts in ((15.6, 20.1), (20.0, 24.0)):
        for band in ADHESION:
            for dens in DENSITIES:
                if ts[0] == 20.0 and dens == "dense":
                    continue
                drv = drivers[k % 4]
                k += 1
                add("straight_highway", "full_size", 0.18 * mu_w[band] * dens_w[dens] / 2, ts, (1.0, 6.0),
                    (4.0, 12.0), "adjacent", (2, 4), (3.5, 3.75), (1.0, 3.0), (0, 0), band, dens, drv,
                    15.0, "PIT guidance 35-45 mph (15.6-20.1 m/s), faster pursuits; lanes 3.5-3.75 m")
    # Curved, full size: 64 = 4 radius bands x 4 adhesion ranges x 4 densities.
    curves = (
        ((60.0, 100.0), (8.0, 11.5), "urban R 60-100 m at 40-50 km/h design speed"),
        ((100.0, 160.0), (10.0, 14.0), "urban R 100-150 m at 50-60 km/h; AASHTO 155 m at 40 mph"),
        ((150.0, 300.0), (12.0, 17.0), "AASHTO R 155-283 m at 40-50 mph"),
        ((280.0, 600.0), (15.0, 21.0), "rural R >= 283 m above 50 mph"),
    )
    bands4 = ("high", "mid", "low", "high")
    for rad, ts, src in curves:
        for j, band in enumerate(bands4):
            for dens in DENSITIES:
                drv = ("lane_keep", "counter_steer", "brake", "lane_keep", "none")[k % 5]
                k += 1
                w = 0.57 * mu_w[band] * dens_w[dens] / 4 / (2 if band == "high" else 1)
                add("curved", "full_size", w, ts, (0.5, 4.5), (3.0, 10.0),
                    "adjacent" if k % 4 else "same", (2, 3), (3.25, 3.75), (0.5, 1.5), rad, band, dens,
                    drv, 12.0, src)
    # Half scale (the paper's platform): 8 priors, ~4 % of draws; target 6.5-9.4 km/h,
    # relative 0.7-4.3 km/h, test-track roads at half the lane width.
    for cat, rad, n in (("straight_urban", (0.0, 0.0), 2), ("curved", (15.0, 40.0), 6)):
        for j in range(n):
            band = "high" if j % 3 != 2 else "mid"
            dens = ("none", "sparse", "medium")[j % 3]
            drv = ("lane_keep", "counter_steer", "brake")[j % 3]
            add(cat, "half_scale", 0.04 / 8, (1.8, 2.6), (0.2, 1.2), (1.0, 3.0), "adjacent", (2, 2),
                (1.75, 2.0), (0.3, 0.6), rad, band, dens, drv, 10.0,
                "paper half-scale trials R1-R4: 7.6-8.4 km/h, relative 0.8-4.2 km/h")
    return rows


def write_priors(path: Path) -> int:
    rows = design_priors()
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(PRIOR_COLUMNS), lineterminator="\n")
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})
    return len(rows)


# --------------------------------------------------------------------------------------
# Sampling one scenario
# --------------------------------------------------------------------------------------


@dataclass
class _Geometry:
    length: float
    width: float
    cg_to_front: float
    lr: float


_GEOM_CACHE: Dict[str, Tuple[_Geometry, _Geometry]] = {}


def _geometry(params: str) -> Tuple[_Geometry, _Geometry]:
    if params not in _GEOM_CACHE:
        p = load_params_dict(params)
        g = lambda v: _Geometry(v["length"], v["width"], v["cg_to_front"], v["lr"])  # noqa: E731
        _GEOM_CACHE[params] = (g(p["bullet"]), g(p["target"]))
    return _GEOM_CACHE[params]


def _poses(road: Dict[str, Any], s: Sequence[float], d: Optional[Sequence[float]] = None) -> np.ndarray:
    return _core.road_poses(json.dumps(road), np.asarray(s, dtype=float),
                            None if d is None else np.asarray(d, dtype=float))


def _lane_center(lane: int, lanes: int, width: float) -> float:
    return (lane + 0.5 - 0.5 * lanes) * width


def _r6(x: float) -> float:
    return float(round(x, 6))


def sample_scenario(prior: Prior, index: int, seed_seq: np.random.SeedSequence) -> Dict[str, Any]:
    """One scenario from ``prior`` with its own seed (the first word of ``seed_seq``)."""
    rng = np.random.default_rng(seed_seq)
    seed = int(seed_seq.generate_state(1, dtype=np.uint64)[0])
    u = lambda r: float(rng.uniform(r[0], r[1]))  # noqa: E731
    half = prior.params == "half_scale"
    scale = 0.45 if half else 1.0
    gb, gt = _geometry(prior.params)

    lanes = int(rng.integers(prior.lanes[0], prior.lanes[1] + 1))
    lane_width, shoulder = u(prior.lane_width), u(prior.shoulder)
    v_t = u(prior.target_speed)
    dv = u(prior.speed_diff)
    gap = u(prior.gap)
    mu = u(prior.mu)
    t_max = prior.t_max
    travel = v_t * t_max + 60.0 * scale
    s_t = 60.0 * scale + u((0.0, 30.0)) * scale
    road: Dict[str, Any] = {"lanes": lanes, "lane_width": _r6(lane_width), "shoulder": _r6(shoulder)}
    if prior.category == "curved":
        radius = u(prior.radius) * (1.0 if rng.random() < 0.5 else -1.0)
        entry = u((30.0, 60.0)) * scale
        transition = min(u((20.0, 50.0)) * scale, 0.25 * abs(radius))
        # The target starts on the entry straight or in the transition.
        s_t = entry - u((0.0, 10.0)) * scale + u((0.0, 1.0)) * transition
        arc = max(10.0, min(math.pi * abs(radius) - transition - 1.0, s_t + travel - entry - transition))
        road.update(length=_r6(2 * entry + 2 * transition + arc), radius=_r6(radius), entry=_r6(entry),
                    transition=_r6(transition))
    else:
        road["length"] = _r6(s_t + travel + 100.0 * scale)

    # Target in a random lane, bullet behind it in an adjacent (or the same) lane.
    lane_t = int(rng.integers(0, lanes))
    d_lane = _lane_center(lane_t, lanes, lane_width)
    d_t = d_lane + u((-0.25, 0.25)) * scale
    if prior.bullet_lane == "adjacent" and lanes > 1:
        options = [lt for lt in (lane_t - 1, lane_t + 1) if 0 <= lt < lanes]
        lane_b = int(options[int(rng.integers(0, len(options)))])
    else:
        lane_b = lane_t
    d_b = _lane_center(lane_b, lanes, lane_width) + u((-0.2, 0.2)) * scale
    s_b = s_t - (gt.length - gt.cg_to_front) - gap - gb.cg_to_front
    v_b = v_t + dv
    pose = _poses(road, [s_t - 0.5, s_t + 0.5, s_b - 0.5, s_b + 0.5])
    kappa_t = float(pose[1, 2] - pose[0, 2])
    kappa_b = float(pose[3, 2] - pose[2, 2])
    target = {"s": _r6(s_t), "d": _r6(d_t), "heading": _r6(u((-0.02, 0.02))), "vx": _r6(v_t), "vy": 0.0,
              "r": _r6(v_t * kappa_t)}
    bullet = {"s": _r6(s_b), "d": _r6(d_b), "heading": 0.0, "vx": _r6(v_b), "vy": 0.0,
              "r": _r6(v_b * kappa_b)}

    gain = _r6(u((0.7, 1.3)))
    if prior.driver == "none":
        driver: Dict[str, Any] = {"kind": "none", "steer": _r6(u((-0.02, 0.02)))}
    elif prior.driver == "lane_keep":
        driver = {"kind": "lane_keep", "offset": _r6(d_lane), "gain": gain}
    elif prior.driver == "brake":
        start = rng.random() < 0.4
        driver = {"kind": "brake", "offset": _r6(d_lane), "gain": gain,
                  "trigger": "start" if start else "contact",
                  "delay": _r6(u((0.0, 8.0)) if start else u((0.2, 0.8))), "fraction": _r6(u((0.1, 0.6)))}
    else:
        driver = {"kind": "counter_steer", "offset": _r6(d_lane), "gain": gain, "delay": _r6(u((0.2, 0.8))),
                  "steer_gain": _r6(u((0.1, 0.4))), "max_steer": _r6(u((0.15, 0.35)))}

    obstacles = _sample_obstacles(prior, rng, road, lanes, lane_width, s_t, v_t, scale)
    return {
        "id": f"sc-{index:05d}", "category": prior.category, "params": prior.params,
        "prior": prior.prior_id, "seed": seed, "road": road, "mu": _r6(mu), "adhesion": _band(_r6(mu)),
        "obstacles": obstacles, "target": target, "bullet": bullet, "driver": driver,
        "t_max": t_max, "eps_psi": _r6(prior.eps_psi),
    }


def _sample_obstacles(prior: Prior, rng: np.random.Generator, road: Dict[str, Any], lanes: int,
                      lane_width: float, s_t: float, v_t: float, scale: float) -> List[Dict[str, Any]]:
    lo, hi = DENSITY_COUNTS[prior.density]
    n = int(rng.integers(lo, hi + 1))
    if n == 0:
        return []
    half_width = 0.5 * lanes * lane_width + float(road["shoulder"])
    specs = []
    for _ in range(n):
        if rng.random() < 0.5:  # forward traffic: a vehicle in a lane ahead
            lane = int(rng.integers(0, lanes))
            s = s_t + float(rng.uniform(25.0, 120.0)) * scale
            d = _lane_center(lane, lanes, lane_width)
            length, width = 4.5 * scale, 1.8 * scale
            moving = prior.category != "curved" and rng.random() < 0.7
            speed = float(rng.uniform(0.4, 0.9)) * v_t if moving else 0.0
            specs.append(("forward_traffic", s, d, length, width, speed))
        else:  # roadside object on the shoulder: parked car, barrier segment, post
            side = 1.0 if rng.random() < 0.5 else -1.0
            kind = int(rng.integers(0, 3))
            length, width = ((4.5, 1.8), (6.0, 0.5), (0.4, 0.4))[kind]
            length, width = length * scale, width * scale
            d = side * (half_width - 0.5 * width - 0.05 * scale)
            s = s_t + float(rng.uniform(-30.0, 150.0)) * scale
            specs.append(("roadside", s, d, length, width, 0.0))
    poses = _poses(road, [sp[1] for sp in specs], [sp[2] for sp in specs])
    out = []
    for sp, (x, y, heading) in zip(specs, poses):
        role, _, _, length, width, speed = sp
        out.append({"role": role, "body": {
            "x": _r6(x), "y": _r6(y), "heading": _r6(heading), "vx": _r6(speed * math.cos(heading)),
            "vy": _r6(speed * math.sin(heading)), "length": _r6(length), "width": _r6(width)}})
    return out


# --------------------------------------------------------------------------------------
# KL divergence
# --------------------------------------------------------------------------------------


def kl_divergence(p: np.ndarray, q: np.ndarray, floor: float = 1e-12) -> float:
    """``KL(p || q) = Σ p log(p / q)`` in nats over bins with ``p > 0`` (both normalised
    first); ``q`` is floored at ``floor`` where it vanishes under a non-empty ``p`` bin."""
    p = np.asarray(p, dtype=float)
    q = np.asarray(q, dtype=float)
    if p.shape != q.shape or p.sum() <= 0 or q.sum() <= 0 or (p < 0).any() or (q < 0).any():
        raise ValueError("kl_divergence: p and q must be non-negative histograms of one shape")
    p = p / p.sum()
    q = q / q.sum()
    m = p > 0
    return float(np.sum(p[m] * np.log(p[m] / np.maximum(q[m], floor))))


def _uniform_mass(lo: float, hi: float, edges: np.ndarray) -> np.ndarray:
    """Mass of U(lo, hi) in each bin (a point mass when lo == hi)."""
    if hi <= lo:
        idx = int(np.clip(np.searchsorted(edges, lo, side="right") - 1, 0, len(edges) - 2))
        out = np.zeros(len(edges) - 1)
        out[idx] = 1.0
        return out
    a = np.clip(edges[:-1], lo, hi)
    b = np.clip(edges[1:], lo, hi)
    return (b - a) / (hi - lo)


def attribute_values(sc: Mapping[str, Any]) -> Dict[str, Any]:
    """The compared attributes of one scenario."""
    t, b = sc["target"], sc["bullet"]
    gb, gt = _geometry(sc["params"])
    gap = (t["s"] - (gt.length - gt.cg_to_front)) - (b["s"] + gb.cg_to_front)
    return {
        "category": sc["category"], "adhesion": sc["adhesion"], "params": sc["params"],
        "driver": sc["driver"]["kind"], "lanes": sc["road"]["lanes"],
        "obstacles": len(sc["obstacles"]), "target_speed": t["vx"], "speed_diff": b["vx"] - t["vx"],
        "gap": gap, "mu": sc["mu"], "lane_width": sc["road"]["lane_width"],
        "radius": abs(sc["road"]["radius"]) if "radius" in sc["road"] else None,
        "density": _prior_index[sc["prior"]].density if sc["prior"] in _prior_index else None,
    }


_prior_index: Dict[str, Prior] = {}


def prior_distribution(priors: Sequence[Prior], attr: str) -> np.ndarray:
    """The weight-averaged distribution of an attribute under the priors (on BINS or the
    categories of CATEGORICAL); radius only over curved priors."""
    ws = np.array([p.weight for p in priors], dtype=float)
    if attr in BINS:
        edges = BINS[attr]
        acc = np.zeros(len(edges) - 1)
        for p, w in zip(priors, ws):
            rng_ = {"target_speed": p.target_speed, "speed_diff": p.speed_diff, "gap": p.gap, "mu": p.mu,
                    "lane_width": p.lane_width, "radius": p.radius}[attr]
            if attr == "radius" and p.category != "curved":
                continue
            acc += w * _uniform_mass(rng_[0], rng_[1], edges)
        return acc / acc.sum()
    cats = CATEGORICAL[attr]
    acc = np.zeros(len(cats))
    for p, w in zip(priors, ws):
        if attr == "lanes":
            n = p.lanes[1] - p.lanes[0] + 1
            for k in range(p.lanes[0], p.lanes[1] + 1):
                acc[cats.index(k)] += w / n
        elif attr == "obstacles":
            lo, hi = DENSITY_COUNTS[p.density]
            for k in range(lo, hi + 1):
                acc[cats.index(k)] += w / (hi - lo + 1)
        else:
            acc[cats.index(getattr(p, {"adhesion": "mu_band"}.get(attr, attr)))] += w
    return acc / acc.sum()


def data_distribution(values: Sequence[Any], attr: str) -> np.ndarray:
    vals = [v for v in values if v is not None]
    if attr in BINS:
        edges = BINS[attr]
        idx = np.clip(np.searchsorted(edges, np.asarray(vals, dtype=float), side="right") - 1, 0, len(edges) - 2)
        return np.bincount(idx, minlength=len(edges) - 1).astype(float)
    cats = CATEGORICAL[attr]
    acc = np.zeros(len(cats))
    for v in vals:
        acc[cats.index(v)] += 1
    return acc


KL_ATTRIBUTES = ("category", "adhesion", "density", "driver", "params", "lanes", "obstacles",
                 "target_speed", "speed_diff", "gap", "mu", "lane_width", "radius")


def kl_table(priors: Sequence[Prior], scenarios: Sequence[Mapping[str, Any]]) -> Dict[str, float]:
    _prior_index.update({p.prior_id: p for p in priors})
    rows = [attribute_values(s) for s in scenarios]
    out = {}
    for attr in KL_ATTRIBUTES:
        p = data_distribution([r[attr] for r in rows], attr)
        if p.sum() == 0:
            continue
        out[attr] = round(kl_divergence(p, prior_distribution(priors, attr)), 6)
    return out


# --------------------------------------------------------------------------------------
# Generation
# --------------------------------------------------------------------------------------


@dataclass
class GenerateConfig:
    n: int = 3600
    keep: int = 2048
    seed: int = 0
    workers: int = 2

    def validate(self) -> "GenerateConfig":
        for name, lo in (("n", 1), ("keep", 1), ("workers", 1)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < lo:
                raise ScenarioGenError(f"{name} = {v!r}: must be an integer >= {lo}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise ScenarioGenError(f"seed = {self.seed!r}: must be a non-negative integer")
        return self


@dataclass
class GenerateResult:
    generated: List[Dict[str, Any]]
    screens: List[Dict[str, Any]]
    retained: List[Dict[str, Any]]
    counts: Dict[str, Any]
    kl: Dict[str, Dict[str, float]]
    seconds: float
    composition: Dict[str, Dict[str, int]] = field(default_factory=dict)


def _select(kept: List[Dict[str, Any]], keep: int) -> List[Dict[str, Any]]:
    """Stratified selection: per category round(keep · share) in generation order; any
    shortfall is filled from the other categories in generation order."""
    if len(kept) <= keep:
        return list(kept)
    by_cat = {c: [s for s in kept if s["category"] == c] for c in CATEGORIES}
    quota = {c: int(round(keep * TARGET_SHARES[c])) for c in CATEGORIES}
    quota["curved"] += keep - sum(quota.values())
    chosen = set()
    for c in CATEGORIES:
        for s in by_cat[c][:quota[c]]:
            chosen.add(s["id"])
    for s in kept:
        if len(chosen) >= keep:
            break
        chosen.add(s["id"])
    return [s for s in kept if s["id"] in chosen]


def generate(priors: Sequence[Prior], cfg: GenerateConfig, progress: bool = True) -> GenerateResult:
    cfg.validate()
    t0 = time.perf_counter()
    weights = np.array([p.weight for p in priors], dtype=float)
    weights /= weights.sum()
    root = np.random.SeedSequence(cfg.seed)
    choose_rng = np.random.default_rng(root.spawn(1)[0])
    picks = choose_rng.choice(len(priors), size=cfg.n, p=weights)
    seeds = root.spawn(cfg.n)
    generated = [sample_scenario(priors[int(k)], i, seeds[i]) for i, k in enumerate(picks)]
    lines = [json.dumps(s, separators=(",", ":")) for s in generated]

    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=len(lines), desc="scenarios: screening", unit="sc", leave=False,
                   dynamic_ncols=True, disable=None)
    screens: List[Dict[str, Any]] = [None] * len(lines)  # type: ignore[list-item]

    def work(i: int) -> Tuple[int, Dict[str, Any]]:
        try:
            return i, _core.screen_scenario(lines[i])
        except _core.ScenarioError as e:
            # A sample the scenario format refuses (an obstacle on a vehicle at t = 0) is
            # rejected like one the geometry rules refuse.
            return i, {"verdict": "rejected", "reason": f"invalid: {e}", "t_fail": None, "t_stop": None,
                       "t_reach": math.inf, "simulated": 0.0, "min_margin": math.nan}

    try:
        with ThreadPoolExecutor(max_workers=cfg.workers) as pool:
            for i, rep in pool.map(work, range(len(lines))):
                screens[i] = rep
                if bar is not None:
                    bar.update(1)
    finally:
        if bar is not None:
            bar.close()

    verdicts = {v: 0 for v in ("rejected", "trivial", "impossible", "keep")}
    reasons: Dict[str, int] = {}
    for rep in screens:
        verdicts[rep["verdict"]] += 1
        key = f"{rep['verdict']}:{rep['reason'].split(':')[0]}"
        reasons[key] = reasons.get(key, 0) + 1
    kept = [s for s, rep in zip(generated, screens) if rep["verdict"] == "keep"]
    retained = _select(kept, cfg.keep)
    # Canonical form through the core's validation (same bytes as a later load).
    retained = [_core.validate_scenario_line(json.dumps(s), i + 1) for i, s in enumerate(retained)]

    def comp(rows: Sequence[Mapping[str, Any]]) -> Dict[str, Dict[str, int]]:
        out: Dict[str, Dict[str, int]] = {}
        _prior_index.update({p.prior_id: p for p in priors})
        for attr in ("category", "adhesion", "density", "driver", "params"):
            vals = [attribute_values(r)[attr] for r in rows]
            out[attr] = {c: int(sum(v == c for v in vals)) for c in CATEGORICAL[attr]}
        return out

    counts = {
        "priors": len(priors), "generated": cfg.n, "rule_rejected": verdicts["rejected"],
        "trivial": verdicts["trivial"], "impossible": verdicts["impossible"],
        "screened_keep": verdicts["keep"], "retained": len(retained), "reasons": dict(sorted(reasons.items())),
    }
    kl = {"generated": kl_table(priors, generated), "retained": kl_table(priors, retained)}
    return GenerateResult(generated=generated, screens=screens, retained=retained, counts=counts, kl=kl,
                          seconds=time.perf_counter() - t0,
                          composition={"generated": comp(generated), "screened_keep": comp(kept),
                                       "retained": comp(retained)})


def jsonl_text(scenarios: Sequence[Mapping[str, Any]]) -> str:
    return "".join(json.dumps(s, separators=(",", ":")) + "\n" for s in scenarios)


def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def write_outputs(res: GenerateResult, out: Path, manifest_extra: Mapping[str, Any],
                  figures: bool = True) -> Dict[str, Path]:
    out.mkdir(parents=True, exist_ok=True)
    paths = {"jsonl": out / "scenarios.jsonl", "manifest": out / "scenarios.manifest.json"}
    paths["jsonl"].write_text(jsonl_text(res.retained))
    shares = {c: round(res.composition["retained"]["category"][c] / max(1, len(res.retained)), 4)
              for c in CATEGORIES}
    manifest = {
        "format": "picopit-scenarios", "version": 1, **manifest_extra,
        "counts": res.counts, "retained_shares": shares, "composition": res.composition,
        "kl_nats": res.kl, "seconds": round(res.seconds, 1),
        "sha256": sha256_file(paths["jsonl"]),
    }
    if figures:
        paths["categories_png"] = out / "scenarios_categories.png"
        paths["kl_png"] = out / "scenarios_kl.png"
        plot(res, paths["categories_png"], paths["kl_png"])
    with open(paths["manifest"], "w") as fh:
        json.dump(manifest, fh, indent=2)
        fh.write("\n")
    return paths


def plot(res: GenerateResult, categories_png: Path, kl_png: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    stages = ("generated", "screened_keep", "retained")
    fig, axes = plt.subplots(1, 3, figsize=(13, 4))
    for ax, attr in zip(axes, ("category", "adhesion", "density")):
        cats = CATEGORICAL[attr]
        width = 0.27
        for j, st in enumerate(stages):
            c = res.composition[st][attr]
            tot = max(1, sum(c.values()))
            ax.bar(np.arange(len(cats)) + (j - 1) * width, [100 * c[k] / tot for k in cats], width,
                   label=f"{st} ({tot})")
        if attr == "category":
            ax.plot(np.arange(3), [100 * TARGET_SHARES[c] for c in cats], "k_", ms=30, mew=2,
                    label="target share")
        ax.set_xticks(np.arange(len(cats)))
        ax.set_xticklabels([c.replace("_", "\n") for c in cats])
        ax.set_ylabel("% of scenarios")
        ax.set_title(attr)
        ax.grid(axis="y", alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle("PIT Scenario Dataset: composition per stage")
    fig.tight_layout()
    fig.savefig(categories_png, dpi=110)
    plt.close(fig)

    attrs = [a for a in KL_ATTRIBUTES if a in res.kl["retained"]]
    fig, ax = plt.subplots(figsize=(10, 4))
    x = np.arange(len(attrs))
    ax.bar(x - 0.2, [res.kl["generated"].get(a, 0.0) for a in attrs], 0.4, label="generated vs priors")
    ax.bar(x + 0.2, [res.kl["retained"][a] for a in attrs], 0.4, label="retained vs priors")
    ax.set_xticks(x)
    ax.set_xticklabels(attrs, rotation=30, ha="right")
    ax.set_ylabel("KL divergence (nats)")
    ax.set_title("Per-attribute KL(data || priors)")
    ax.legend()
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(kl_png, dpi=110)
    plt.close(fig)
