"""Every message of an MCAP recording checked against the schema its channel names.

* ``protobuf`` channels: the schema must be one of Foxglove's and byte for byte the one the
  Foxglove SDK publishes (``foxglove-sdk``: ``<Type>.get_schema()``); the message is decoded
  with protobuf from the file's own descriptor set (no picopit or SDK code involved), must
  serialise back to the same bytes (no unknown or malformed fields), and must carry what a
  viewer needs: timestamps, frames, entity ids, unit quaternions, positive sizes, finite
  numbers.
* ``jsonschema`` channels: the message must satisfy its JSON Schema (``jsonschema``).

Used by tests/test_foxglove_logs.py and tests/test_bench.py.
"""

from __future__ import annotations

import json
import math
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List

FOXGLOVE_TYPES = ("SceneUpdate", "FrameTransforms", "PoseInFrame")


@dataclass
class Checked:
    counts: Dict[str, int] = field(default_factory=lambda: defaultdict(int))
    scenes: Dict[str, List[Any]] = field(default_factory=lambda: defaultdict(list))
    json: Dict[str, List[Any]] = field(default_factory=lambda: defaultdict(list))
    schemas: Dict[str, str] = field(default_factory=dict)


def _sdk_schema(name: str) -> bytes:
    try:
        from foxglove import messages as fx
    except ImportError:  # foxglove-sdk 0.15 (Python 3.9)
        from foxglove import schemas as fx
    short = name.split(".", 1)[1]
    assert name.startswith("foxglove.") and short in FOXGLOVE_TYPES, f"unexpected schema {name}"
    return bytes(getattr(fx, short).get_schema().data)


def _message_class(name: str, data: bytes):
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    fds = descriptor_pb2.FileDescriptorSet.FromString(data)
    pool = descriptor_pool.DescriptorPool()
    for f in fds.file:
        pool.Add(f)
    desc = pool.FindMessageTypeByName(name)
    if hasattr(message_factory, "GetMessageClass"):
        return message_factory.GetMessageClass(desc)
    return message_factory.MessageFactory(pool).GetPrototype(desc)  # protobuf < 4.22


def _finite(what: str, *v: float) -> None:
    assert all(math.isfinite(x) for x in v), f"{what}: not finite: {v}"


def _stamp(what: str, m) -> None:
    assert m.HasField("timestamp"), f"{what}: no timestamp"
    assert 0 <= m.timestamp.nanos < 1_000_000_000, f"{what}: nanos {m.timestamp.nanos}"


def _quat(what: str, q) -> None:
    _finite(what, q.x, q.y, q.z, q.w)
    n = q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w
    assert abs(n - 1.0) < 1e-9, f"{what}: |q|^2 = {n}"


def _pose(what: str, p) -> None:
    _finite(what, p.position.x, p.position.y, p.position.z)
    _quat(what, p.orientation)


def _color(what: str, c) -> None:
    assert all(0.0 <= v <= 1.0 for v in (c.r, c.g, c.b, c.a)), f"{what}: colour {c}"


def _scene(what: str, m) -> None:
    assert len(m.entities) > 0, f"{what}: no entities"
    ids = [e.id for e in m.entities]
    assert len(set(ids)) == len(ids), f"{what}: duplicate ids {ids}"
    for e in m.entities:
        w = f"{what}, entity {e.id!r}"
        _stamp(w, e)
        assert e.frame_id and e.id, w
        assert e.HasField("lifetime"), f"{w}: no lifetime"
        for c in e.cubes:
            assert c.HasField("pose") and c.HasField("size") and c.HasField("color"), w
            _pose(w, c.pose)
            assert min(c.size.x, c.size.y, c.size.z) > 0.0, f"{w}: cube size {c.size}"
            _color(w, c.color)
        for a in e.arrows:
            assert a.HasField("pose") and a.HasField("color"), w
            _pose(w, a.pose)
            d = (a.shaft_length, a.shaft_diameter, a.head_length, a.head_diameter)
            _finite(w, *d)
            assert min(d) > 0.0, f"{w}: arrow {d}"
        for ln in e.lines:
            assert ln.HasField("pose") and ln.HasField("color"), w
            _pose(w, ln.pose)
            assert ln.thickness > 0.0 and len(ln.points) >= 2, f"{w}: line"
            for p in ln.points:
                _finite(w, p.x, p.y, p.z)
        for t in e.texts:
            assert t.HasField("pose") and t.text and t.font_size > 0.0, w
            _pose(w, t.pose)
        assert not (e.spheres or e.cylinders or e.triangles or e.models), f"{w}: unexpected primitives"


def _check_foxglove(what: str, name: str, m) -> None:
    if name == "foxglove.SceneUpdate":
        _scene(what, m)
    elif name == "foxglove.PoseInFrame":
        _stamp(what, m)
        assert m.frame_id, f"{what}: frame_id"
        assert m.HasField("pose"), f"{what}: pose"
        _pose(what, m.pose)
    elif name == "foxglove.FrameTransforms":
        assert len(m.transforms) > 0, f"{what}: no transforms"
        for t in m.transforms:
            _stamp(what, t)
            assert t.parent_frame_id and t.child_frame_id and t.parent_frame_id != t.child_frame_id, what
            _finite(what, t.translation.x, t.translation.y, t.translation.z)
            _quat(what, t.rotation)


def check_recording(path: Path) -> Checked:
    """Check every message of the MCAP file ``path`` (asserts, naming topic and message)."""
    import jsonschema
    from mcap.reader import make_reader

    out = Checked()
    classes: Dict[int, Any] = {}
    validators: Dict[int, Any] = {}
    with open(path, "rb") as fh:
        for schema, channel, message in make_reader(fh).iter_messages():
            topic = channel.topic
            what = f"{path.name}: {topic} message {out.counts[topic]}"
            out.counts[topic] += 1
            assert schema is not None, f"{what}: no schema"
            out.schemas[topic] = schema.name
            if schema.encoding == "protobuf":
                assert channel.message_encoding == "protobuf", what
                if schema.id not in classes:
                    assert bytes(schema.data) == _sdk_schema(schema.name), \
                        f"{what}: the schema is not the SDK's {schema.name}"
                    classes[schema.id] = _message_class(schema.name, bytes(schema.data))
                m = classes[schema.id].FromString(message.data)
                assert m.SerializeToString(deterministic=True) == bytes(message.data), \
                    f"{what}: unknown or non-canonical fields"
                _check_foxglove(what, schema.name, m)
                if schema.name == "foxglove.SceneUpdate":
                    out.scenes[topic].append(m)
            elif schema.encoding == "jsonschema":
                assert channel.message_encoding == "json", what
                if schema.id not in validators:
                    doc = json.loads(schema.data)
                    cls = jsonschema.validators.validator_for(doc)
                    cls.check_schema(doc)
                    validators[schema.id] = cls(doc)
                v = json.loads(message.data)
                errors = list(validators[schema.id].iter_errors(v))
                assert not errors, f"{what}: {errors[0].message}"
                out.json[topic].append(v)
            else:
                raise AssertionError(f"{what}: unexpected schema encoding {schema.encoding!r}")
    return out
