"""The benchmark's representative cases as one MCAP file, ``cases.mcap``, that Foxglove opens.

Per case ``<c>`` (``success``, ``failure``), time = the episode's time (s → ns):

* ``/<c>/step`` (``picopit.EpisodeStep``, JSON): one message per control step, named fields
  (SI): both vehicles' states and speeds, the commands, the contact force, the phase, the
  planning and control times -- ready for a Plot panel (``/success/step.target.psi``).
* ``/<c>/summary`` (``picopit.EpisodeSummary``, JSON): the outcome, once, at the decision.
* ``/<c>/scene`` (``foxglove.SceneUpdate``): both vehicles as boxes with labels, the road's
  edges (white) and lane lines (grey), the obstacles (grey boxes, moving with their
  velocity), and the contact force on the target as an arrow whose head touches the contact
  point (entity ``contact``, empty apart).
* ``/<c>/tf`` (``foxglove.FrameTransforms``): ``world`` → ``<c>/bullet``, ``<c>/target``.
* ``/<c>/bullet/pose``, ``/<c>/target/pose`` (``foxglove.PoseInFrame``, frame ``world``).

The Foxglove messages are the Foxglove SDK's own types (``foxglove-sdk``), protobuf-encoded
with the SDK's published schemas, written with the ``mcap`` package. Frame ``world`` is the
plant's (X along the road, Y left, Z up); a pose is the yaw ψ as a quaternion about +z.

The contact arrow: the trajectory holds the contact force ``[F_n, F_t]`` averaged over each
step but not where it acted, so the normal and the point come from the recorded footprints
(``_core.footprint_contact``, the plant's separating-axis test); while the recorded poses do
not overlap within a contact, the last overlap's point and normal, fixed in the target's body
frame, stand in. Length: a force of the target's weight is as long as the target.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from . import _core

STEP_SCHEMA = {
    "type": "object",
    "title": "picopit.EpisodeStep",
    "properties": {
        "time": {"type": "number", "description": "s"},
        "target": {"type": "object", "description": "vx, vy, psi, r, p, phi, x, y, speed (SI)"},
        "bullet": {"type": "object", "description": "x, y, psi, vx, vy, r, speed (SI)"},
        "command": {"type": "object", "description": "bullet steer (rad), rear torque (N m)"},
        "target_command": {"type": "object", "description": "target steer (rad), brake (N m)"},
        "contact_force": {"type": "object", "description": "fn, ft (N), averaged over the step"},
        "phase": {"type": "string"},
        "plan_ms": {"type": "number"},
        "ctrl_ms": {"type": "number"},
    },
    "required": ["time", "target", "bullet", "command", "target_command", "contact_force",
                 "phase", "plan_ms", "ctrl_ms"],
}
SUMMARY_SCHEMA = {
    "type": "object",
    "title": "picopit.EpisodeSummary",
    "properties": {k: {} for k in ("scenario", "config", "seed", "success", "cause", "decided_at",
                                  "terminal_heading_error", "min_margin", "contacts")},
}
PHASES = ("chasing", "pit", "stabilising", "done", "aborted")
WORLD = "world"
#: Obstacles are drawn this tall (m); a scenario gives only their footprint.
OBSTACLE_HEIGHT = 1.5

_BULLET = (0.15, 0.45, 0.95, 0.9)
_TARGET = (0.95, 0.3, 0.15, 0.9)
_OBSTACLE = (0.45, 0.45, 0.45, 0.9)
_CONTACT = (0.6, 0.2, 0.85, 1.0)
_EDGE = (0.85, 0.85, 0.85, 1.0)
_LANE = (0.55, 0.55, 0.55, 1.0)
_LABEL = (1.0, 1.0, 1.0, 1.0)


def _fx():
    """The SDK's message module (``foxglove.messages``; ``foxglove.schemas`` in foxglove-sdk
    0.15, the last release for Python 3.9)."""
    try:
        from foxglove import messages
    except ImportError:
        from foxglove import schemas as messages
    return messages


def road_edges(sc: Mapping[str, Any], s_lo: float, s_hi: float) -> List[np.ndarray]:
    """The road's polylines over stations ``[s_lo, s_hi]``: the two outer edges (shoulders
    included), the lane lines, then the carriageway's two edges; each ``(n, 2)`` ``[X, Y]``."""
    road = sc["road"]
    hw = 0.5 * road["lanes"] * road["lane_width"] + road["shoulder"]
    s = np.linspace(max(0.0, s_lo), max(s_lo + 1.0, s_hi), 300)
    lines = []
    for d in (-hw, hw):
        lines.append(_core.road_poses(json.dumps(road), s, np.full_like(s, d))[:, :2])
    carriage = 0.5 * road["lanes"] * road["lane_width"]
    for k in range(1, road["lanes"]):
        d = -carriage + k * road["lane_width"]
        lines.append(_core.road_poses(json.dumps(road), s, np.full_like(s, d))[:, :2])
    for d in (-carriage, carriage):
        lines.append(_core.road_poses(json.dumps(road), s, np.full_like(s, d))[:, :2])
    return lines


def station_span(sc: Mapping[str, Any], c: Mapping[str, np.ndarray]) -> Tuple[float, float]:
    """The stations an episode's drawing spans: from 20 m behind the rearmost start to 30 m
    past the frontmost start plus the longest distance driven."""
    s_lo = min(sc["target"]["s"], sc["bullet"]["s"]) - 20.0
    dist = float(np.hypot(np.diff(c["target_x"]), np.diff(c["target_y"])).sum(initial=0.0))
    dist_b = float(np.hypot(np.diff(c["bullet_x"]), np.diff(c["bullet_y"])).sum(initial=0.0))
    return s_lo, max(sc["target"]["s"], sc["bullet"]["s"]) + max(dist, dist_b) + 30.0


def _finite(v: Any) -> Optional[float]:
    if v is None:
        return None
    v = float(v)
    return v if math.isfinite(v) else None


def step_message(v: Mapping[str, float]) -> Dict[str, Any]:
    """One ``/<c>/step`` message from a trajectory row (columns by name)."""
    target = {k: v[f"target_{k}"] for k in ("vx", "vy", "psi", "r", "p", "phi", "x", "y")}
    target["speed"] = math.hypot(v["target_vx"], v["target_vy"])
    bullet = {k: v[f"bullet_{k}"] for k in ("x", "y", "psi", "vx", "vy", "r")}
    bullet["speed"] = math.hypot(v["bullet_vx"], v["bullet_vy"])
    return {
        "time": v["time"],
        "target": target,
        "bullet": bullet,
        "command": {"steer": v["cmd_steer"], "torque": v["cmd_torque"]},
        "target_command": {"steer": v["target_steer"], "brake": v["target_brake"]},
        "contact_force": {"fn": v["contact_fn"], "ft": v["contact_ft"]},
        "phase": PHASES[int(v["phase"])],
        "plan_ms": v["plan_ms"],
        "ctrl_ms": v["ctrl_ms"],
    }


class _Scene:
    """Builds the Foxglove messages of one case."""

    def __init__(self, case: str, sc: Mapping[str, Any], params: Mapping[str, Any],
                 c: Mapping[str, np.ndarray]):
        self.fx = _fx()
        self.case = case
        self.sc = sc
        self.p = params
        self.size = {w: [params[w]["length"], params[w]["width"], params[w]["cg_to_front"]]
                     for w in ("bullet", "target")}
        self.height = {w: float(params[w]["height"]) for w in ("bullet", "target")}
        weight = params["target"]["mass"] * float(getattr(_core, "GRAVITY", 9.80665))
        self.arrow_scale = params["target"]["length"] / weight
        self.road = road_edges(sc, *station_span(sc, c))
        self.last_contact: Optional[Tuple[float, float, float]] = None  # gamma - psi_T, body x, y

    def _color(self, rgba):
        return self.fx.Color(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])

    def pose(self, x: float, y: float, z: float, yaw: float):
        fx = self.fx
        return fx.Pose(position=fx.Vector3(x=float(x), y=float(y), z=float(z)),
                       orientation=self.quat(yaw))

    def quat(self, yaw: float):
        return self.fx.Quaternion(x=0.0, y=0.0, z=math.sin(0.5 * yaw), w=math.cos(0.5 * yaw))

    def _entity(self, eid: str, ts, **kw):
        fx = self.fx
        return fx.SceneEntity(timestamp=ts, frame_id=WORLD, id=eid,
                              lifetime=fx.Duration(sec=0, nsec=0), **kw)

    def _vehicle(self, who: str, ts, x: float, y: float, psi: float):
        fx = self.fx
        length, width, cg_to_front = self.size[who]
        h = self.height[who]
        # The box is centred on the footprint, which is not centred on the c.g.
        off = cg_to_front - 0.5 * length
        cx, cy = x + off * math.cos(psi), y + off * math.sin(psi)
        color = _BULLET if who == "bullet" else _TARGET
        return self._entity(
            who, ts,
            metadata=[fx.KeyValuePair(key="vehicle", value=who)],
            cubes=[fx.CubePrimitive(pose=self.pose(cx, cy, 0.5 * h, psi),
                                    size=fx.Vector3(x=float(length), y=float(width), z=h),
                                    color=self._color(color))],
            texts=[fx.TextPrimitive(pose=self.pose(x, y, h + 0.6, psi), billboard=True,
                                    font_size=14.0, scale_invariant=True,
                                    color=self._color(_LABEL), text=who)])

    def _arrow(self, v: Mapping[str, float]):
        """The contact force on the target as an arrow, or None apart (module docstring)."""
        fn_, ft = float(v["contact_fn"]), float(v["contact_ft"])
        bullet = [v["bullet_x"], v["bullet_y"], v["bullet_psi"]]
        target = [v["target_x"], v["target_y"], v["target_psi"]]
        if not (fn_ > 0.0 and math.isfinite(ft)):
            self.last_contact = None
            return None
        psi = target[2]
        g = _core.footprint_contact(bullet, self.size["bullet"], target, self.size["target"])
        if g is not None:
            dx, dy = g["point"][0] - target[0], g["point"][1] - target[1]
            c, s = math.cos(psi), math.sin(psi)
            self.last_contact = (g["gamma"] - psi, c * dx + s * dy, -s * dx + c * dy)
        if self.last_contact is None:
            return None
        rel, bx, by = self.last_contact
        c, s = math.cos(psi), math.sin(psi)
        px, py = target[0] + c * bx - s * by, target[1] + s * bx + c * by
        heading = rel + psi + math.atan2(ft, fn_)
        length = max(math.hypot(fn_, ft) * self.arrow_scale, 0.3)
        shaft = 0.05 * self.size["target"][1]
        return self.fx.ArrowPrimitive(
            pose=self.pose(px - length * math.cos(heading), py - length * math.sin(heading),
                           0.5 * self.height["target"], heading),
            shaft_length=0.75 * length, shaft_diameter=shaft, head_length=0.25 * length,
            head_diameter=3.0 * shaft, color=self._color(_CONTACT))

    def _road(self, ts):
        fx = self.fx
        n = len(self.road)
        lines = []
        for k, pts in enumerate(self.road):
            outer = k < 2 or k >= n - 2
            lines.append(fx.LinePrimitive(
                type=fx.LinePrimitiveLineType.LineStrip, pose=self.pose(0.0, 0.0, 0.0, 0.0),
                thickness=0.15 if outer else 0.08, scale_invariant=False,
                points=[fx.Point3(x=float(x), y=float(y), z=0.01) for x, y in pts],
                color=self._color(_EDGE if outer else _LANE)))
        return self._entity("road", ts, frame_locked=True, lines=lines)

    def messages(self, v: Mapping[str, float], ts, with_road: bool):
        """``(scene, tf, bullet pose, target pose)`` of one step."""
        fx = self.fx
        t = float(v["time"])
        bx, by, bpsi = v["bullet_x"], v["bullet_y"], v["bullet_psi"]
        tx, ty, tpsi = v["target_x"], v["target_y"], v["target_psi"]
        entities = [self._vehicle("bullet", ts, bx, by, bpsi),
                    self._vehicle("target", ts, tx, ty, tpsi)]
        arrow = self._arrow(v)
        entities.append(self._entity("contact", ts, arrows=[arrow] if arrow is not None else []))
        for i, ob in enumerate(self.sc.get("obstacles", [])):
            b = ob["body"]
            entities.append(self._entity(
                f"obstacle/{i}", ts,
                cubes=[fx.CubePrimitive(
                    pose=self.pose(b["x"] + b["vx"] * t, b["y"] + b["vy"] * t,
                                   0.5 * OBSTACLE_HEIGHT, b["heading"]),
                    size=fx.Vector3(x=float(b["length"]), y=float(b["width"]), z=OBSTACLE_HEIGHT),
                    color=self._color(_OBSTACLE))]))
        if with_road:
            entities.append(self._road(ts))
        scene = fx.SceneUpdate(entities=entities)

        def tf(child: str, x: float, y: float, yaw: float):
            return fx.FrameTransform(timestamp=ts, parent_frame_id=WORLD,
                                     child_frame_id=f"{self.case}/{child}",
                                     translation=fx.Vector3(x=float(x), y=float(y), z=0.0),
                                     rotation=self.quat(yaw))

        tfs = fx.FrameTransforms(transforms=[tf("bullet", bx, by, bpsi), tf("target", tx, ty, tpsi)])
        poses = [fx.PoseInFrame(timestamp=ts, frame_id=WORLD, pose=self.pose(x, y, 0.0, yaw))
                 for x, y, yaw in ((bx, by, bpsi), (tx, ty, tpsi))]
        return scene, tfs, poses[0], poses[1]


def write_mcap(cases: Mapping[str, Mapping[str, Any]], scenes: Mapping[str, Mapping[str, Any]],
               path: Path) -> Optional[str]:
    """Write ``cases`` (kind → recorded episode with its ``trajectory``) to ``path``;
    ``scenes[kind]`` is the case's validated scenario. Returns a note instead when the
    ``mcap`` or ``foxglove-sdk`` package is missing (nothing is written then)."""
    try:
        from mcap.writer import Writer
    except ImportError:
        return "the mcap package is not installed: no MCAP written (pip install mcap)"
    try:
        fx = _fx()
    except ImportError:
        return "the foxglove-sdk package is not installed: no MCAP written (pip install foxglove-sdk)"
    from . import load_params_dict

    cols = list(_core.trajectory_columns())
    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start(profile="", library="picopit bench")
        schema_ids: Dict[str, int] = {}

        def schema(name: str, encoding: str, data: bytes) -> int:
            if name not in schema_ids:
                schema_ids[name] = w.register_schema(name, encoding, data)
            return schema_ids[name]

        def foxglove_channel(topic: str, msg_type) -> int:
            s = msg_type.get_schema()
            return w.register_channel(topic, "protobuf",
                                      schema(s.name, s.encoding, bytes(s.data)))

        step_id = schema("picopit.EpisodeStep", "jsonschema", json.dumps(STEP_SCHEMA).encode())
        sum_id = schema("picopit.EpisodeSummary", "jsonschema", json.dumps(SUMMARY_SCHEMA).encode())
        for name, case in cases.items():
            sc = scenes[name]
            ch = w.register_channel(f"/{name}/step", "json", step_id)
            chs = w.register_channel(f"/{name}/summary", "json", sum_id)
            fox = [foxglove_channel(f"/{name}/scene", fx.SceneUpdate),
                   foxglove_channel(f"/{name}/tf", fx.FrameTransforms),
                   foxglove_channel(f"/{name}/bullet/pose", fx.PoseInFrame),
                   foxglove_channel(f"/{name}/target/pose", fx.PoseInFrame)]
            tr = np.asarray(case["trajectory"])
            c = {k: tr[:, i] for i, k in enumerate(cols)} if len(tr) else {k: np.zeros(0) for k in cols}
            scene = _Scene(name, sc, load_params_dict(sc["params"]), c)
            road_at: Optional[float] = None
            for seq, row in enumerate(tr):
                v = dict(zip(cols, row.tolist()))
                ns = int(round(v["time"] * 1e9))
                w.add_message(ch, log_time=ns, publish_time=ns, sequence=seq,
                              data=json.dumps(step_message(v)).encode())
                ts = fx.Timestamp(sec=ns // 1_000_000_000, nsec=ns % 1_000_000_000)
                # The road with the first scene and then every second (back soon after a seek).
                with_road = road_at is None or v["time"] - road_at >= 1.0
                if with_road:
                    road_at = v["time"]
                for channel, msg in zip(fox, scene.messages(v, ts, with_road)):
                    w.add_message(channel, log_time=ns, publish_time=ns, sequence=seq,
                                  data=msg.encode())
            ns = int(round(float(tr[-1, 0]) * 1e9)) if len(tr) else 0
            summ = {k: _finite(case[k]) if isinstance(case[k], float) else case[k]
                    for k in SUMMARY_SCHEMA["properties"]}
            w.add_message(chs, log_time=ns, publish_time=ns, sequence=0, data=json.dumps(summ).encode())
        w.finish()
    return None


def topics(kinds: Sequence[str]) -> List[str]:
    """Every topic ``write_mcap`` writes for the cases ``kinds``."""
    return [f"/{k}/{t}" for k in kinds
            for t in ("step", "summary", "scene", "tf", "bullet/pose", "target/pose")]
