"""``picopit replay``: a figure and a summary from an MCAP recording of pit-controller/pit-vehicle.

The recordings come from ``crates/vehicle_io/src/record.rs`` (one file per process). Layout:

- profile ``""``, no chunks, no compression; a Metadata record named ``picopit`` with the
  vehicles' boxes (``bullet.length``, ``bullet.width``, ``bullet.height``, the same for
  ``target``; metres as decimal strings), ``recorder.start_monotonic_ns``, ``recorder.pid``,
  ``service.<topic>`` names and the caller's own keys (command line, scenario id, git commit);
- the topics ``replay`` reads are JSON (``message_encoding = "json"``, a ``jsonschema``
  schema); the Foxglove topics (``/scene``, ``/tf``, ``/bullet/pose``, ``/target/pose``:
  protobuf with Foxglove's schemas) and the plot topics are for viewers and are skipped:

  ========================= ============================ ==========================================
  topic                     schema                       message (JSON object)
  ========================= ============================ ==========================================
  ``/state``                ``picopit.StateEstimate``    ``seq, stamp_ns, sent_ns, wall_sent_ns,
                                                         run_start_ns,
                                                         target[8] = [vx, vy, psi, r, p, phi, X, Y],
                                                         bullet[6] = [X, Y, psi, vx, vy, r],
                                                         target_input[2], bullet_applied[2],
                                                         contact_force[2], contact_gamma,
                                                         contact_point[2], flags, commands_applied``
  ``/command``              ``picopit.ActuatorCommand``  ``seq, state_seq, stamp_ns, valid_until_ns,
                                                         wall_state_received_ns, wall_sent_ns, steer,
                                                         torque, mode (0 track, 1 fallback,
                                                         2 safe stop), _reserved``
  ``/status``               ``picopit.ControllerStatus`` ``seq, state_seq, stamp_ns, compensated_ns,
                                                         ctrl_ns, plan_ns, deadline_misses, fallbacks,
                                                         stale_states, phase, mpc_status, faults``
  ``/heartbeat/controller`` ``picopit.Heartbeat``        ``seq, wall_sent_ns, vehicle_ns, peer, pid``
  ``/heartbeat/vehicle``    ``picopit.Heartbeat``        (same)
  ``/road``                 ``picopit.Road``             ``left, right, centre``: ``[[X, Y], ...]``
                                                         (once, at the start)
  ========================= ============================ ==========================================

  A recording without ``/road`` whose ``/scene`` is JSON (an older recorder's) gives the road
  from the first ``road`` entity on ``/scene`` (line strips: left edge, right edge, centre).
- times: ``log_time`` = the recorder's receive time since the recording's start (ns,
  monotonic); ``publish_time`` = the payload's vehicle-clock time (``sent_ns`` of a state,
  ``stamp_ns`` of a command or status). A number that was not finite is ``null``.

The plots use the vehicle clock (``stamp_ns``) so states, commands and statuses line up. A file
whose process was killed lacks its summary and footer and may end inside a record: it is read
with the stream reader up to its last complete record.

Every message on ``/state``, ``/command`` and ``/status`` is checked before it is drawn
(``FIELDS``): a missing field, a value of the wrong type or an absurd one (a stamp that is not
a non-negative integer, a number beyond ``ABSURD`` in size, an array of the wrong length) is a
:class:`ReplayError` naming the topic, the message and the field. ``null`` (a value that was
not finite when recorded) is allowed in the number fields and is drawn as a gap.
"""

from __future__ import annotations

import io
import json
import math
import os
import struct
from collections import Counter, defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Optional, Tuple

MCAP_MAGIC = b"\x89MCAP0\r\n"
_OP_FOOTER = 0x02

TOPICS = ("/state", "/command", "/status", "/heartbeat/controller", "/heartbeat/vehicle",
          "/road", "/scene")
MODES = {0: "track", 1: "fallback", 2: "safe stop"}
PHASES = {0: "chasing", 1: "pit", 2: "stabilising", 3: "done", 4: "aborted"}
FAULTS = {1 << 0: "stale state", 1 << 1: "deadline missed", 1 << 2: "solver failure",
          1 << 3: "peer dead", 1 << 4: "no state", 1 << 5: "bad state"}
DEFAULT_BOX = (4.8, 1.85, 1.45)
#: Numbers beyond this size (m, rad, N m) are refused as absurd.
ABSURD = 1e9
_U32 = 2 ** 32
_STAMP_MAX = 2 ** 63

#: The fields replay reads, per topic: "stamp" (an integer in [0, 2^63) ns), "u32", "num" (a
#: number or null, |x| <= ABSURD) or ("vec", n) (n such numbers).
FIELDS: Dict[str, Dict[str, Any]] = {
    "/state": {"stamp_ns": "stamp", "bullet": ("vec", 6), "target": ("vec", 8), "flags": "u32"},
    "/command": {"stamp_ns": "stamp", "steer": "num", "torque": "num", "mode": "u32"},
    "/status": {"stamp_ns": "stamp", "phase": "u32", "faults": "u32", "fallbacks": "u32",
                "deadline_misses": "u32", "stale_states": "u32"},
}


class ReplayError(Exception):
    """The file is missing, unreadable or not an MCAP recording."""


@dataclass
class Recording:
    """What a recording holds, decoded."""

    path: Path
    #: per topic: list of (log_time_ns, publish_time_ns, decoded JSON)
    messages: Dict[str, List[Tuple[int, int, Any]]] = field(default_factory=lambda: defaultdict(list))
    metadata: Dict[str, str] = field(default_factory=dict)
    #: True when the file ended without its footer (a killed process)
    truncated: bool = False
    #: bytes of a partial record dropped at the end
    dropped_bytes: int = 0
    #: messages whose JSON did not decode (skipped)
    undecodable: int = 0

    @property
    def n_messages(self) -> int:
        return sum(len(v) for v in self.messages.values())

    def counts(self) -> Dict[str, int]:
        return {t: len(v) for t, v in self.messages.items()}

    def box(self, who: str) -> Tuple[float, float, float]:
        """The vehicle's length, width, height from the metadata (a default when missing or
        not a size between 1 cm and 100 m)."""
        try:
            box = tuple(float(self.metadata[f"{who}.{k}"]) for k in ("length", "width", "height"))
        except (KeyError, ValueError, TypeError):
            return DEFAULT_BOX
        ok = all(0.01 <= v <= 100.0 for v in box)
        return box if ok else DEFAULT_BOX  # type: ignore[return-value]

    def road(self) -> List[List[Tuple[float, float]]]:
        """The road's polylines from ``/road``, else from the first ``road`` entity on a JSON
        ``/scene`` (empty without either; points that are not finite numbers are left out)."""
        for _, _, msg in self.messages.get("/road", []):
            if isinstance(msg, dict):
                lines = [msg.get(k) for k in ("left", "right", "centre")]
                return [[(p[0], p[1]) for p in line if _pair(p)] for line in lines if isinstance(line, list)]
        for _, _, msg in self.messages.get("/scene", []):
            ents = msg.get("entities", []) if isinstance(msg, dict) else []
            for e in ents if isinstance(ents, list) else []:
                if isinstance(e, dict) and e.get("id") == "road":
                    lines = e.get("lines", [])
                    return [[(p["x"], p["y"]) for p in line.get("points", []) if _point(p)]
                            for line in (lines if isinstance(lines, list) else [])
                            if isinstance(line, dict) and isinstance(line.get("points", []), list)]
        return []


def _number(v: Any) -> bool:
    """A JSON number (not a bool) that is finite and not absurd."""
    return (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
            and abs(v) <= ABSURD)


def _pair(p: Any) -> bool:
    return isinstance(p, list) and len(p) == 2 and _number(p[0]) and _number(p[1])


def _point(p: Any) -> bool:
    return isinstance(p, dict) and _number(p.get("x")) and _number(p.get("y"))


def _problem(v: Any, kind: Any) -> Optional[str]:
    """What is wrong with value ``v`` of kind ``kind`` (``FIELDS``), or None."""
    if kind == "stamp":
        if not isinstance(v, int) or isinstance(v, bool):
            return f"= {v!r}: not an integer number of nanoseconds"
        return None if 0 <= v < _STAMP_MAX else f"= {v}: outside [0, 2^63) ns"
    if kind == "u32":
        if not isinstance(v, int) or isinstance(v, bool):
            return f"= {v!r}: not an integer"
        return None if 0 <= v < _U32 else f"= {v}: outside [0, 2^32)"
    if kind == "num":
        if v is None or _number(v):
            return None
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            return f"= {v!r}: not finite or larger than {ABSURD:g} in size"
        return f"= {v!r}: not a number"
    _, n = kind
    if not isinstance(v, list) or len(v) != n:
        return f"= {str(v)[:60]}: not an array of {n} numbers"
    for j, x in enumerate(v):
        why = _problem(x, "num")
        if why:
            return f"[{j}] {why}"
    return None


def check_messages(rec: Recording) -> None:
    """Check every message replay reads (``FIELDS``); raises :class:`ReplayError` naming the
    file, the topic, the message (1-based, in file order) and the field."""
    for topic, fields in FIELDS.items():
        for i, (_, _, msg) in enumerate(rec.messages.get(topic, [])):
            where = f"{rec.path}: {topic} message {i + 1}"
            if not isinstance(msg, dict):
                raise ReplayError(f"{where}: not a JSON object")
            for name, kind in fields.items():
                if name not in msg:
                    raise ReplayError(f"{where}: field `{name}` is missing")
                why = _problem(msg[name], kind)
                if why:
                    raise ReplayError(f"{where}: field `{name}`{why if why.startswith('[') else ' ' + why}")


def _complete_prefix(data: bytes) -> Tuple[int, bool]:
    """Length of the longest prefix of whole records, and whether the footer was among them."""
    off, n = len(MCAP_MAGIC), len(data)
    while off + 9 <= n:
        op = data[off]
        (length,) = struct.unpack_from("<Q", data, off + 1)
        end = off + 9 + length
        if end > n:
            break
        off = end
        if op == _OP_FOOTER:
            return n, True
    return off, False


def check_source(path: "str | Path") -> Path:
    """``path`` as a Path; raises :class:`ReplayError` when it exists but is not a regular file
    (a folder, or a device such as ``/dev/zero`` that would be read until memory runs out)."""
    path = Path(path)
    if path.exists() and not path.is_file():
        raise ReplayError(f"{path}: not a regular file")
    return path


def read_recording(path: "str | Path") -> Recording:
    """Read every message of ``path`` with the MCAP stream reader (also a truncated file).

    Raises :class:`ReplayError` naming the file when it is missing or not an MCAP file.
    """
    from mcap.exceptions import McapError
    from mcap.records import Channel, Message, Metadata, Schema
    from mcap.stream_reader import StreamReader

    path = check_source(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise ReplayError(f"{path}: no such file") from None
    except OSError as e:
        raise ReplayError(f"{path}: cannot read: {e.strerror or e}") from None
    except MemoryError:
        raise ReplayError(f"{path}: too large to read into memory") from None
    if not data.startswith(MCAP_MAGIC):
        raise ReplayError(f"{path}: not an MCAP file (no MCAP magic at the start)")
    end, complete = _complete_prefix(data)
    rec = Recording(path=path, truncated=not complete, dropped_bytes=len(data) - end)
    reader = StreamReader(io.BytesIO(data[:end]), skip_magic=False, record_size_limit=None)
    topics: Dict[int, str] = {}
    try:
        for r in reader.records:
            if isinstance(r, Channel):
                # Only the JSON channels: the Foxglove topics (protobuf) are for viewers.
                if r.message_encoding == "json":
                    topics[r.id] = r.topic
            elif isinstance(r, Message):
                topic = topics.get(r.channel_id)
                if topic is None:
                    continue
                try:
                    msg = json.loads(r.data)
                except ValueError:
                    rec.undecodable += 1
                    continue
                rec.messages[topic].append((r.log_time, r.publish_time, msg))
            elif isinstance(r, Metadata) and r.name == "picopit":
                rec.metadata.update(r.metadata)
            elif isinstance(r, Schema):
                pass
    except (McapError, struct.error, ValueError, EOFError) as e:
        # The end of a killed process's file (no footer), or a damaged record: stop there.
        if complete and not rec.n_messages:
            raise ReplayError(f"{path}: not a readable MCAP file: {e}") from None
        rec.truncated = True
    return rec


def _nan(v: Any) -> float:
    return float("nan") if v is None else float(v)


def _series(rec: Recording) -> Dict[str, Any]:
    """Arrays for the plots (vehicle clock, s)."""
    import numpy as np

    st = [m for _, _, m in rec.messages.get("/state", [])]
    cm = [m for _, _, m in rec.messages.get("/command", [])]
    ss = [m for _, _, m in rec.messages.get("/status", [])]
    s: Dict[str, Any] = {}
    s["t"] = np.array([m["stamp_ns"] * 1e-9 for m in st])
    s["bullet"] = np.array([[_nan(v) for v in m["bullet"]] for m in st]).reshape(-1, 6)
    s["target"] = np.array([[_nan(v) for v in m["target"]] for m in st]).reshape(-1, 8)
    s["flags"] = np.array([int(m.get("flags", 0)) for m in st], dtype=int)
    s["tc"] = np.array([m["stamp_ns"] * 1e-9 for m in cm])
    s["steer"] = np.array([_nan(m["steer"]) for m in cm])
    s["torque"] = np.array([_nan(m["torque"]) for m in cm])
    s["mode"] = np.array([int(m["mode"]) if int(m["mode"]) in (0, 1) else 2 for m in cm], dtype=int)
    s["ts"] = np.array([m["stamp_ns"] * 1e-9 for m in ss])
    s["phase"] = np.array([int(m["phase"]) for m in ss], dtype=int)
    s["faults"] = np.array([int(m["faults"]) for m in ss], dtype=int)
    return s


def summarize(rec: Recording) -> str:
    """One paragraph: duration, messages per topic, commands by mode, faults, final speeds."""
    counts = rec.counts()
    logs = [lt for msgs in rec.messages.values() for lt, _, _ in msgs]
    duration = (max(logs) - min(logs)) * 1e-9 if logs else 0.0
    parts = [f"{rec.path.name}: {rec.n_messages} messages over {duration:.2f} s"]
    states = rec.messages.get("/state", [])
    if states:
        t0, t1 = states[0][2]["stamp_ns"] * 1e-9, states[-1][2]["stamp_ns"] * 1e-9
        parts[0] += f" (vehicle clock {t0:.2f}-{t1:.2f} s)"
    order = [t for t in TOPICS if t in counts] + sorted(t for t in counts if t not in TOPICS)
    parts.append("per topic: " + (", ".join(f"{t} {counts[t]}" for t in order) or "none"))
    if rec.truncated:
        parts.append(f"the file is truncated (no footer; a killed process?): read {rec.n_messages} "
                     f"messages up to its last complete record"
                     + (f", {rec.dropped_bytes} bytes of a partial record dropped" if rec.dropped_bytes else ""))
    if rec.undecodable:
        parts.append(f"{rec.undecodable} messages did not decode as JSON")
    modes = Counter(int(m["mode"]) for _, _, m in rec.messages.get("/command", []))
    if modes:
        parts.append("commands: " + ", ".join(f"{MODES.get(k, 'safe stop')} {modes[k]}"
                                               for k in sorted(modes)))
    else:
        parts.append("commands: none")
    faults: Counter = Counter()
    first: Dict[int, float] = {}
    statuses = rec.messages.get("/status", [])
    for _, _, m in statuses:
        for bit in FAULTS:
            if int(m["faults"]) & bit:
                faults[bit] += 1
                first.setdefault(bit, m["stamp_ns"] * 1e-9)
    if faults:
        parts.append("faults: " + ", ".join(f"{FAULTS[b]} x{faults[b]} (first at {first[b]:.2f} s)"
                                             for b in sorted(faults)))
    else:
        parts.append("faults: none" if statuses else "faults: no status recorded")
    if statuses:
        last = statuses[-1][2]
        parts.append(f"final phase: {PHASES.get(int(last['phase']), str(last['phase']))}"
                     f" (fallbacks {last['fallbacks']}, deadline misses {last['deadline_misses']}, "
                     f"stale states {last['stale_states']})")
    if states:
        m = states[-1][2]
        b, t = [_nan(v) for v in m["bullet"]], [_nan(v) for v in m["target"]]
        parts.append(f"final speeds: bullet {math.hypot(b[3], b[4]):.2f} m/s, "
                     f"target {math.hypot(t[0], t[1]):.2f} m/s")
    return "; ".join(parts) + "."


def _footprint(x: float, y: float, psi: float, length: float, width: float):
    import numpy as np

    c, s = math.cos(psi), math.sin(psi)
    corners = np.array([[0.5, 0.5], [0.5, -0.5], [-0.5, -0.5], [-0.5, 0.5], [0.5, 0.5]])
    corners = corners * np.array([length, width])
    return x + c * corners[:, 0] - s * corners[:, 1], y + s * corners[:, 0] + c * corners[:, 1]


def _spans(t, on):
    """Contiguous [start, end) spans of times where ``on`` holds (end: the next sample)."""
    spans, start = [], None
    for i, flag in enumerate(on):
        if flag and start is None:
            start = t[i]
        elif not flag and start is not None:
            spans.append((start, t[i]))
            start = None
    if start is not None:
        spans.append((start, t[-1] + (t[-1] - t[-2] if len(t) > 1 else 0.05)))
    return spans


def plot(rec: Recording, out: "str | Path") -> Path:
    """Draw the replay figure into ``out`` (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    s = _series(rec)
    fig = plt.figure(figsize=(12, 14), constrained_layout=True)
    gs = fig.add_gridspec(5, 1, height_ratios=[1.6, 1, 1, 1, 1])
    ax_xy = fig.add_subplot(gs[0])
    ax_psi = fig.add_subplot(gs[1])
    ax_steer = fig.add_subplot(gs[2], sharex=ax_psi)
    ax_phase = fig.add_subplot(gs[4], sharex=ax_psi)
    ax_torque = fig.add_subplot(gs[3], sharex=ax_psi)
    fig.suptitle(f"picopit replay: {rec.path.name}" + (" (truncated)" if rec.truncated else ""))

    colours = {"bullet": "tab:blue", "target": "tab:red"}
    for line in rec.road():
        if len(line) >= 2:
            xs, ys = zip(*line)
            ax_xy.plot(xs, ys, color="0.6", lw=1.0, zorder=1)
    t = s["t"]
    paths = {"bullet": (s["bullet"][:, 0], s["bullet"][:, 1], s["bullet"][:, 2]),
             "target": (s["target"][:, 6], s["target"][:, 7], s["target"][:, 2])}
    for who, (x, y, psi) in paths.items():
        if not len(t):
            break
        ax_xy.plot(x, y, color=colours[who], lw=1.5, label=who, zorder=3)
        length, width, _ = rec.box(who)
        next_t = -math.inf
        for i in range(len(t)):
            if t[i] >= next_t and np.isfinite([x[i], y[i], psi[i]]).all():
                fx, fy = _footprint(x[i], y[i], psi[i], length, width)
                ax_xy.plot(fx, fy, color=colours[who], lw=0.7, alpha=0.6, zorder=2)
                next_t = t[i] + 0.5
        ax_psi.plot(t, np.degrees(np.unwrap(np.nan_to_num(psi))), color=colours[who], label=who)
    contact = s["flags"] & 2 if len(t) else []
    for a, b in _spans(t, [bool(c) for c in contact]) if len(t) else []:
        ax_psi.axvspan(a, b, color="tab:purple", alpha=0.12, lw=0)
    ax_xy.set_aspect("equal", adjustable="datalim")
    ax_xy.set_xlabel("X (m, east)")
    ax_xy.set_ylabel("Y (m, north)")
    ax_xy.set_title("paths, footprints every 0.5 s")
    ax_psi.set_ylabel("heading psi (deg)")
    ax_psi.set_title("headings (shaded: contact)")

    tc = s["tc"]
    ax_steer.plot(tc, np.degrees(s["steer"]), color="tab:blue", drawstyle="steps-post")
    ax_steer.set_ylabel("steer (deg)")
    ax_steer.set_title("bullet commands (shaded: orange fallback, red safe stop)")
    ax_torque.plot(tc, s["torque"], color="tab:green", drawstyle="steps-post")
    ax_torque.set_ylabel("rear torque (N m)")
    for mode, colour in ((1, "tab:orange"), (2, "tab:red")):
        for a, b in _spans(tc, list(s["mode"] == mode)) if len(tc) else []:
            for ax in (ax_steer, ax_torque):
                ax.axvspan(a, b, color=colour, alpha=0.2, lw=0)

    ts = s["ts"]
    ax_phase.plot(ts, s["phase"], color="k", drawstyle="steps-post", label="phase")
    bits = sorted(FAULTS)
    for j, bit in enumerate(bits):
        hit = (s["faults"] & bit) != 0 if len(ts) else np.zeros(0, bool)
        if hit.any():
            ax_phase.plot(ts[hit], np.full(hit.sum(), -1.0 - j), "|", ms=10, color=f"C{j}")
    ax_phase.set_yticks(list(PHASES) + [-1.0 - j for j in range(len(bits))])
    ax_phase.set_yticklabels(list(PHASES.values()) + [FAULTS[b] for b in bits], fontsize=8)
    ax_phase.set_ylim(-0.5 - len(bits), max(PHASES) + 0.5)
    ax_phase.axhline(-0.5, color="0.7", lw=0.5)
    ax_phase.set_title("controller phase (top) and faults (bottom)")
    ax_phase.set_xlabel("t (s, vehicle clock)")
    for ax in (ax_xy, ax_psi):
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="best", fontsize=8)
    for ax in (ax_xy, ax_psi, ax_steer, ax_torque, ax_phase):
        ax.grid(True, alpha=0.3)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=90)
    plt.close(fig)
    return out


def figure_path(path: "str | Path", out: "Optional[str | Path]" = None) -> Path:
    """Where the figure of recording ``path`` goes: ``out`` when it names a ``.png`` file; inside
    ``out`` as ``<name of path>.png`` when it is a folder (one that exists, or spelled with a
    trailing ``/``); without ``out`` beside ``path``. Raises :class:`ReplayError` for any other
    ``out``."""
    src = Path(path)
    if out is None:
        return src.with_suffix(".png")
    o = Path(out)
    if o.is_dir() or str(out).endswith(("/", os.sep)):
        return o / (src.stem + ".png")
    if o.suffix.lower() != ".png":
        raise ReplayError(f"--out {out}: the figure is a PNG: give a path ending in .png, or a folder")
    return o


def replay(path: "str | Path", out: "Optional[str | Path]" = None) -> Tuple[Recording, Path, str]:
    """Read ``path``, check the messages it draws, draw the figure (``figure_path``) and
    summarise."""
    rec = read_recording(path)
    check_messages(rec)
    png = plot(rec, figure_path(path, out))
    return rec, png, summarize(rec)
