"""``picopit replay``: MCAP recordings in the layout of crates/vehicle_io/src/record.rs."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from mcap.writer import CompressionType, Writer

from picopit import cli
from picopit.replay import ReplayError, read_recording, replay

DT_NS = 20_000_000  # 50 Hz
N = 100  # 2 s


def _state(k: int) -> dict:
    t = k * DT_NS * 1e-9
    psi_t = 0.3 * math.sin(t)
    return {
        "seq": k, "stamp_ns": k * DT_NS, "sent_ns": k * DT_NS + 1_000_000, "wall_sent_ns": 5 + k,
        "target": [20.0 - 2.0 * t, 0.0, psi_t, 0.0, 0.0, 0.0, 10.0 + 20.0 * t, 0.5],
        "bullet": [24.0 * t, -3.0 + t, 0.1 * t, 24.0 - 4.0 * t, 0.0, 0.0],
        "target_input": [0.0, 0.0], "bullet_applied": [0.0, 0.0],
        "flags": 2 if 40 <= k < 50 else 0, "commands_applied": k,
    }


def _mode(k: int) -> int:
    return 1 if 60 <= k < 70 else (2 if k >= 90 else 0)


def _command(k: int) -> dict:
    return {"seq": k, "state_seq": k, "stamp_ns": k * DT_NS + 5_000_000,
            "valid_until_ns": k * DT_NS + 45_000_000, "wall_state_received_ns": 1,
            "wall_sent_ns": 2, "steer": 0.05 * math.sin(k / 10), "torque": 300.0 - 6.0 * k,
            "mode": _mode(k), "_reserved": 0}


def _status(k: int) -> dict:
    faults = (1 << 1) if k in (30, 31, 77) else 0
    if k >= 90:
        faults |= 1 << 3
    return {"seq": k, "state_seq": k, "stamp_ns": k * DT_NS + 5_000_000, "compensated_ns": 5_000_000,
            "ctrl_ns": 1, "plan_ns": 0, "deadline_misses": 0, "fallbacks": 0, "stale_states": 0,
            "phase": min(3, k // 25), "mpc_status": 1, "faults": faults}


def _heartbeat(k: int, peer: int) -> dict:
    return {"seq": k, "wall_sent_ns": k, "vehicle_ns": k * DT_NS if peer == 2 else 0, "peer": peer, "pid": 1}


def _yaw_pose(x: float, y: float, psi: float) -> dict:
    return {"position": {"x": x, "y": y, "z": 0.0},
            "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(psi / 2), "w": math.cos(psi / 2)}}


def write_recording(path: Path, n: int = N, finish: bool = True, edit=None) -> int:
    """Write ``n`` steps of every topic; returns the messages written. Without ``finish`` the
    file is left as a killed process leaves it (no summary, no footer). ``edit(topic, k, msg)``
    may change a message before it is written (returning the message to write)."""
    fh = open(path, "wb")
    w = Writer(fh, compression=CompressionType.NONE, use_chunking=False)
    w.start(profile="", library="test")
    schema = json.dumps({"type": "object"}).encode()
    names = {"/state": "picopit.StateEstimate", "/command": "picopit.ActuatorCommand",
             "/status": "picopit.ControllerStatus", "/heartbeat/controller": "picopit.Heartbeat",
             "/heartbeat/vehicle": "picopit.Heartbeat", "/scene": "foxglove.SceneUpdate",
             "/bullet/pose": "foxglove.PoseInFrame", "/target/pose": "foxglove.PoseInFrame"}
    ch = {}
    for topic, sname in names.items():
        sid = w.register_schema(name=sname, encoding="jsonschema", data=schema)
        ch[topic] = w.register_channel(topic=topic, message_encoding="json", schema_id=sid)
    w.add_metadata("picopit", {"bullet.length": "4.5", "bullet.width": "1.8", "bullet.height": "1.4",
                               "target.length": "5.0", "target.width": "2.0", "target.height": "1.5",
                               "scenario": "test"})
    count = 0

    def put(topic: str, log: int, pub: int, msg: dict) -> None:
        nonlocal count
        if edit is not None:
            msg = edit(topic, log // DT_NS, msg)
        w.add_message(channel_id=ch[topic], log_time=log, publish_time=pub,
                      data=json.dumps(msg).encode(), sequence=count)
        count += 1

    road = {"timestamp": {"sec": 0, "nsec": 0}, "frame_id": "world", "id": "road",
            "lifetime": {"sec": 0, "nsec": 0}, "frame_locked": True, "metadata": [], "cubes": [],
            "lines": [{"type": 0, "pose": _yaw_pose(0, 0, 0), "thickness": 0.15, "scale_invariant": False,
                       "points": [{"x": x, "y": y, "z": 0.01} for x in (0.0, 100.0)],
                       "color": {"r": 1, "g": 1, "b": 1, "a": 1}, "colors": [], "indices": []}
                      for y in (-5.5, 0.0, 5.5)]}
    for k in range(n):
        log = k * DT_NS + 2_000_000
        s = _state(k)
        put("/state", log, s["sent_ns"], s)
        b, t = s["bullet"], s["target"]
        stamp = {"sec": s["stamp_ns"] // 10**9, "nsec": s["stamp_ns"] % 10**9}
        ents = [{"id": who, "frame_id": "world", "timestamp": stamp, "cubes": [{"pose": _yaw_pose(x, y, psi)}]}
                for who, x, y, psi in (("bullet", b[0], b[1], b[2]), ("target", t[6], t[7], t[2]))]
        put("/scene", log, s["stamp_ns"], {"deletions": [], "entities": ents + ([road] if k == 0 else [])})
        put("/bullet/pose", log, s["stamp_ns"], {"timestamp": stamp, "frame_id": "world", "pose": _yaw_pose(b[0], b[1], b[2])})
        put("/target/pose", log, s["stamp_ns"], {"timestamp": stamp, "frame_id": "world", "pose": _yaw_pose(t[6], t[7], t[2])})
        c = _command(k)
        put("/command", log + 300_000, c["stamp_ns"], c)
        st = _status(k)
        put("/status", log + 310_000, st["stamp_ns"], st)
        put("/heartbeat/controller", log + 320_000, log + 320_000, _heartbeat(k, 1))
        put("/heartbeat/vehicle", log + 330_000, k * DT_NS, _heartbeat(k, 2))
    if finish:
        w.finish()
    fh.close()
    return count


def test_replay_writes_the_figure_and_counts(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    total = write_recording(path)
    rec, png, summary = replay(path)
    assert png == tmp_path / "run.png" and png.stat().st_size > 10_000
    assert not rec.truncated
    assert rec.n_messages == total == 8 * N
    assert rec.counts() == {t: N for t in ("/state", "/command", "/status", "/heartbeat/controller",
                                           "/heartbeat/vehicle", "/scene", "/bullet/pose", "/target/pose")}
    assert rec.box("bullet") == (4.5, 1.8, 1.4)
    assert len(rec.road()) == 3
    assert f"{8 * N} messages" in summary
    assert f"/state {N}" in summary and f"/heartbeat/vehicle {N}" in summary
    assert "commands: track 80, fallback 10, safe stop 10" in summary
    assert "deadline missed x3 (first at 0.6" in summary
    assert "peer dead x10" in summary
    assert "final phase: done" in summary
    final = _state(N - 1)
    assert f"bullet {final['bullet'][3]:.2f} m/s" in summary
    assert f"target {final['target'][0]:.2f} m/s" in summary
    assert "truncated" not in summary


def test_cli_replay_with_out(tmp_path: Path, capsys) -> None:
    path = tmp_path / "run.mcap"
    write_recording(path, n=30)
    out = tmp_path / "figs" / "replay.png"
    assert cli.main(["replay", str(path), "--out", str(out)]) == 0
    assert out.exists()
    printed = capsys.readouterr().out
    assert "240 messages" in printed and f"replay: wrote {out}" in printed


@pytest.mark.parametrize("cut", [0, 1, 13])
def test_truncated_file_replays_up_to_its_last_message(tmp_path: Path, cut: int, capsys) -> None:
    path = tmp_path / "killed.mcap"
    total = write_recording(path, n=40, finish=False)
    if cut:
        data = path.read_bytes()
        path.write_bytes(data[:-cut])  # inside the last message
    rec, png, summary = replay(path)
    assert rec.truncated
    assert rec.n_messages == total - (1 if cut else 0)
    assert png.exists()
    assert "truncated" in summary and f"read {rec.n_messages} messages" in summary
    assert cli.main(["replay", str(path)]) == 0
    assert f"read {rec.n_messages} messages" in capsys.readouterr().out


def test_finished_file_cut_before_its_footer(tmp_path: Path) -> None:
    path = tmp_path / "cut.mcap"
    total = write_recording(path, n=10)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) - 40])  # inside the summary section
    rec = read_recording(path)
    assert rec.truncated and rec.n_messages == total


def test_not_mcap_and_missing_files_give_a_clean_error(tmp_path: Path, capsys) -> None:
    bad = tmp_path / "notes.mcap"
    bad.write_text("hello, not an mcap\n")
    with pytest.raises(ReplayError, match="notes.mcap"):
        read_recording(bad)
    assert cli.main(["replay", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "notes.mcap" in err and "not an MCAP file" in err and "Traceback" not in err
    missing = tmp_path / "nope.mcap"
    assert cli.main(["replay", str(missing)]) == 2
    assert "nope.mcap" in capsys.readouterr().err
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    assert cli.main(["replay", str(empty)]) == 2


def _set(topic: str, k: int, field: str, value, raw: bool = False):
    """An ``edit`` that sets (or, with value ``...``, deletes) ``field`` of message ``k`` on
    ``topic``."""
    def edit(t, kk, msg):
        if t == topic and kk == k:
            msg = dict(msg)
            if value is ...:
                del msg[field]
            else:
                msg[field] = value
        return msg
    return edit


@pytest.mark.parametrize("topic,field,value,needle", [
    ("/state", "stamp_ns", ..., "`stamp_ns` is missing"),
    ("/command", "stamp_ns", ..., "`stamp_ns` is missing"),
    ("/status", "faults", ..., "`faults` is missing"),
    ("/state", "stamp_ns", 1e30, "not an integer"),
    ("/state", "stamp_ns", -5, "outside [0, 2^63)"),
    ("/state", "stamp_ns", 2 ** 70, "outside [0, 2^63)"),
    ("/command", "mode", 1e300, "not an integer"),
    ("/command", "mode", 2 ** 40, "outside [0, 2^32)"),
    ("/status", "phase", "pit", "not an integer"),
    ("/command", "steer", "left", "not a number"),
    ("/command", "torque", 1e300, "larger than"),
    ("/state", "bullet", [1.0, 2.0], "not an array of 6 numbers"),
    ("/state", "bullet", [0.0, 0.0, 0.0, 1e308, 0.0, 0.0], "[3]"),
    ("/state", "target", "all of it", "not an array of 8 numbers"),
])
def test_messages_that_parse_but_lack_fields_or_hold_absurd_values_name_topic_and_field(
        tmp_path: Path, capsys, topic, field, value, needle) -> None:
    path = tmp_path / "odd.mcap"
    write_recording(path, n=20, edit=_set(topic, 7, field, value))
    with pytest.raises(ReplayError) as e:
        replay(path)
    msg = str(e.value)
    assert f"{topic} message 8" in msg and f"`{field}`" in msg and needle in msg, msg
    assert cli.main(["replay", str(path)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and f"{topic} message 8" in err
    assert len(err.strip().splitlines()) == 1, err


def test_a_message_that_is_not_an_object_is_named(tmp_path: Path) -> None:
    path = tmp_path / "odd.mcap"
    write_recording(path, n=10, edit=lambda t, k, m: [1, 2] if (t, k) == ("/status", 3) else m)
    with pytest.raises(ReplayError, match=r"/status message 4: not a JSON object"):
        replay(path)


def test_non_finite_states_recorded_as_null_are_drawn_as_gaps(tmp_path: Path) -> None:
    # The recorder writes a non-finite number as null: every pose null is still a figure.
    path = tmp_path / "nulls.mcap"
    write_recording(path, n=20, edit=lambda t, k, m: dict(m, bullet=[None] * 6, target=[None] * 8)
                    if t == "/state" else m)
    rec, png, summary = replay(path)
    assert png.stat().st_size > 0 and "final speeds: bullet nan m/s" in summary


def test_absurd_boxes_and_road_points_fall_back_instead_of_breaking_the_axes(tmp_path: Path) -> None:
    def edit(t, k, m):
        if t == "/scene" and k == 0:
            ents = [dict(e, lines=[{"points": [{"x": 1e308, "y": 0.0}, {"x": "a"}, 5]}, "x"])
                    if e.get("id") == "road" else e for e in m["entities"]]
            return dict(m, entities=ents)
        return m
    path = tmp_path / "odd.mcap"
    write_recording(path, n=10, edit=edit)
    rec, png, _ = replay(path)
    assert rec.road() == [[]] and png.exists()
    rec.metadata["bullet.length"] = "1e308"
    assert rec.box("bullet") == (4.8, 1.85, 1.45)


def test_a_device_is_not_read(capsys) -> None:
    # /dev/zero used to be read until memory ran out.
    assert cli.main(["replay", "/dev/zero"]) == 2
    err = capsys.readouterr().err
    assert "/dev/zero: not a regular file" in err and "Traceback" not in err


def test_out_naming_a_folder_writes_into_it(tmp_path: Path, capsys) -> None:
    path = tmp_path / "run.mcap"
    write_recording(path, n=10)
    folder = tmp_path / "figs"
    folder.mkdir()
    assert cli.main(["replay", str(path), "--out", str(folder)]) == 0
    assert (folder / "run.png").exists() and not (tmp_path / "figs.png").exists()
    new = tmp_path / "new"
    assert cli.main(["replay", str(path), "--out", f"{new}/"]) == 0
    assert (new / "run.png").exists()
    assert cli.main(["replay", str(path), "--out", str(tmp_path / "fig.jpg")]) == 2
    assert "ending in .png" in capsys.readouterr().err


@pytest.mark.parametrize("out", ["/proc/picopit-x/fig.png", "/dev/full"])
def test_an_unwritable_out_is_refused_before_reading(tmp_path: Path, capsys, out) -> None:
    path = tmp_path / "run.mcap"
    write_recording(path, n=10)
    assert cli.main(["replay", str(path), "--out", out]) == 2
    err = capsys.readouterr().err
    assert out.split("/")[1] in err and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
