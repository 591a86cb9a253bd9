//! Every message of a recording checked against the schema its channel names.
//!
//! - `protobuf` channels: the schema must be one of Foxglove's, byte for byte the one the
//!   Foxglove SDK publishes (`foxglove::Encode::get_schema`); the message must decode as that
//!   type and encode back to the same bytes (no unknown or malformed fields); and the fields a
//!   viewer needs must be there and sane (timestamps, frames, ids, unit quaternions, positive
//!   sizes, finite numbers).
//! - `jsonschema` channels: the message must satisfy its JSON Schema. The validator below
//!   knows the keywords the recorder's schemas use and refuses a schema with any other, so a
//!   schema cannot silently go unchecked.

use foxglove::messages::{
    ArrowPrimitive, Color, CubePrimitive, FrameTransforms, LinePrimitive, Pose, PoseInFrame,
    Quaternion, SceneEntity, SceneUpdate, TextPrimitive, Timestamp, Vector3,
};
use foxglove::Encode;
use prost::Message;
use serde_json::Value;
use std::collections::{BTreeMap, BTreeSet};

/// Messages per topic, and the decoded Foxglove messages of the scene topic.
#[derive(Debug, Default)]
pub struct Checked {
    pub counts: BTreeMap<String, usize>,
    pub scenes: Vec<SceneUpdate>,
    pub json: BTreeMap<String, Vec<Value>>,
}

/// Check every message of the MCAP file `bytes` (a truncated file: up to its last complete
/// message). Panics naming the topic, the message and what is wrong.
pub fn check_recording(bytes: &[u8]) -> Checked {
    let mut out = Checked::default();
    let stream = mcap::MessageStream::new(bytes).expect("an MCAP file");
    for m in stream {
        let Ok(m) = m else { break };
        let topic = m.channel.topic.clone();
        let k = out.counts.entry(topic.clone()).or_default();
        let what = format!("{topic} message {k}");
        *k += 1;
        let schema = m
            .channel
            .schema
            .as_ref()
            .unwrap_or_else(|| panic!("{what}: no schema"));
        match schema.encoding.as_str() {
            "protobuf" => {
                assert_eq!(m.channel.message_encoding, "protobuf", "{what}");
                if let Some(scene) = check_foxglove(&schema.name, &schema.data, &m.data, &what) {
                    out.scenes.push(scene);
                }
            }
            "jsonschema" => {
                assert_eq!(m.channel.message_encoding, "json", "{what}");
                let doc: Value = serde_json::from_slice(&schema.data)
                    .unwrap_or_else(|e| panic!("{what}: schema is not JSON: {e}"));
                assert_eq!(doc["title"], schema.name.as_str(), "{what}");
                let v: Value = serde_json::from_slice(&m.data)
                    .unwrap_or_else(|e| panic!("{what}: not JSON: {e}"));
                validate_json(&doc, &v, &what);
                out.json.entry(topic).or_default().push(v);
            }
            other => panic!("{what}: unexpected schema encoding {other}"),
        }
    }
    out
}

/// Decode `data` as the SDK type `T` whose published schema must be `schema`.
fn decode<T: Encode + Message + Default>(schema: &[u8], data: &[u8], what: &str) -> T {
    let published = T::get_schema().expect("a Foxglove type has a schema");
    assert!(
        schema == &*published.data,
        "{what}: the schema is not the SDK's {} ({} bytes, the SDK's {})",
        published.name,
        schema.len(),
        published.data.len()
    );
    let msg = T::decode(data).unwrap_or_else(|e| panic!("{what}: does not decode: {e}"));
    assert_eq!(
        msg.encode_to_vec(),
        data,
        "{what}: unknown or non-canonical fields"
    );
    msg
}

fn check_foxglove(name: &str, schema: &[u8], data: &[u8], what: &str) -> Option<SceneUpdate> {
    match name {
        "foxglove.SceneUpdate" => {
            let s: SceneUpdate = decode(schema, data, what);
            check_scene(&s, what);
            Some(s)
        }
        "foxglove.PoseInFrame" => {
            let p: PoseInFrame = decode(schema, data, what);
            stamp(p.timestamp, what);
            assert!(!p.frame_id.is_empty(), "{what}: frame_id");
            pose(p.pose, what);
            None
        }
        "foxglove.FrameTransforms" => {
            let t: FrameTransforms = decode(schema, data, what);
            assert!(!t.transforms.is_empty(), "{what}: no transforms");
            for tf in &t.transforms {
                stamp(tf.timestamp, what);
                assert!(!tf.parent_frame_id.is_empty(), "{what}: parent frame");
                assert!(!tf.child_frame_id.is_empty(), "{what}: child frame");
                assert_ne!(tf.parent_frame_id, tf.child_frame_id, "{what}");
                vector(tf.translation, what);
                quaternion(tf.rotation, what);
            }
            None
        }
        other => panic!("{what}: schema {other} is not one the recorder writes"),
    }
}

/// Whether `data` decodes as the Foxglove type `schema` names (false for another name).
pub fn decodes(schema: &str, data: &[u8]) -> bool {
    match schema {
        "foxglove.SceneUpdate" => SceneUpdate::decode(data).is_ok(),
        "foxglove.PoseInFrame" => PoseInFrame::decode(data).is_ok(),
        "foxglove.FrameTransforms" => FrameTransforms::decode(data).is_ok(),
        _ => false,
    }
}

fn stamp(t: Option<Timestamp>, what: &str) {
    let t = t.unwrap_or_else(|| panic!("{what}: no timestamp"));
    assert!(t.nsec() < 1_000_000_000, "{what}: nsec {}", t.nsec());
}

fn finite(v: &[f64], what: &str) {
    assert!(v.iter().all(|x| x.is_finite()), "{what}: not finite: {v:?}");
}

fn vector(v: Option<Vector3>, what: &str) -> Vector3 {
    let v = v.unwrap_or_else(|| panic!("{what}: missing vector"));
    finite(&[v.x, v.y, v.z], what);
    v
}

fn quaternion(q: Option<Quaternion>, what: &str) {
    let q = q.unwrap_or_else(|| panic!("{what}: missing orientation"));
    finite(&[q.x, q.y, q.z, q.w], what);
    let n = q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w;
    assert!((n - 1.0).abs() < 1e-9, "{what}: |q|² = {n}");
}

fn pose(p: Option<Pose>, what: &str) {
    let p = p.unwrap_or_else(|| panic!("{what}: missing pose"));
    vector(p.position, what);
    quaternion(p.orientation, what);
}

fn color(c: Option<Color>, what: &str) {
    let c = c.unwrap_or_else(|| panic!("{what}: missing color"));
    for v in [c.r, c.g, c.b, c.a] {
        assert!((0.0..=1.0).contains(&v), "{what}: colour {c:?}");
    }
}

fn cube(c: &CubePrimitive, what: &str) {
    pose(c.pose, what);
    let s = vector(c.size, what);
    assert!(
        s.x > 0.0 && s.y > 0.0 && s.z > 0.0,
        "{what}: cube size {s:?}"
    );
    color(c.color, what);
}

fn arrow(a: &ArrowPrimitive, what: &str) {
    pose(a.pose, what);
    let d = [
        a.shaft_length,
        a.shaft_diameter,
        a.head_length,
        a.head_diameter,
    ];
    finite(&d, what);
    assert!(d.iter().all(|&x| x > 0.0), "{what}: arrow {a:?}");
    color(a.color, what);
}

fn line(l: &LinePrimitive, what: &str) {
    assert!(
        (0..=2).contains(&l.r#type),
        "{what}: line type {}",
        l.r#type
    );
    pose(l.pose, what);
    assert!(l.thickness > 0.0, "{what}: thickness");
    assert!(
        l.points.len() >= 2,
        "{what}: a line of {} points",
        l.points.len()
    );
    for p in &l.points {
        finite(&[p.x, p.y, p.z], what);
    }
    color(l.color, what);
}

fn text(t: &TextPrimitive, what: &str) {
    pose(t.pose, what);
    assert!(
        !t.text.is_empty() && t.font_size > 0.0,
        "{what}: text {t:?}"
    );
    color(t.color, what);
}

fn check_scene(s: &SceneUpdate, what: &str) {
    assert!(!s.entities.is_empty(), "{what}: no entities");
    let mut ids = BTreeSet::new();
    for e in &s.entities {
        let what = format!("{what}, entity {:?}", e.id);
        check_entity(e, &what);
        assert!(ids.insert(e.id.clone()), "{what}: duplicate id");
    }
}

fn check_entity(e: &SceneEntity, what: &str) {
    stamp(e.timestamp, what);
    assert!(!e.frame_id.is_empty(), "{what}: frame_id");
    assert!(!e.id.is_empty(), "{what}: id");
    let life = e.lifetime.unwrap_or_else(|| panic!("{what}: no lifetime"));
    assert!(life.sec() >= 0, "{what}: lifetime");
    e.cubes.iter().for_each(|c| cube(c, what));
    e.arrows.iter().for_each(|a| arrow(a, what));
    e.lines.iter().for_each(|l| line(l, what));
    e.texts.iter().for_each(|t| text(t, what));
    assert!(
        e.spheres.is_empty() && e.cylinders.is_empty() && e.triangles.is_empty(),
        "{what}: primitives the recorder does not draw"
    );
    assert!(e.models.is_empty(), "{what}: models");
}

/// The JSON Schema keywords the validator understands.
const KEYWORDS: [&str; 14] = [
    "$schema",
    "title",
    "description",
    "type",
    "properties",
    "required",
    "additionalProperties",
    "items",
    "minItems",
    "maxItems",
    "minimum",
    "maximum",
    "enum",
    "contentEncoding",
];

fn type_ok(t: &str, v: &Value) -> bool {
    match t {
        "object" => v.is_object(),
        "array" => v.is_array(),
        "string" => v.is_string(),
        "boolean" => v.is_boolean(),
        "null" => v.is_null(),
        "number" => v.is_number(),
        "integer" => v.is_i64() || v.is_u64(),
        other => panic!("unknown JSON Schema type {other}"),
    }
}

/// `v` satisfies `schema` (the keywords of [`KEYWORDS`]).
pub fn validate_json(schema: &Value, v: &Value, what: &str) {
    let s = schema
        .as_object()
        .unwrap_or_else(|| panic!("{what}: schema not an object"));
    for k in s.keys() {
        assert!(
            KEYWORDS.contains(&k.as_str()),
            "{what}: unknown keyword {k}"
        );
    }
    if let Some(t) = s.get("type") {
        let ok = match t {
            Value::String(t) => type_ok(t, v),
            Value::Array(ts) => ts.iter().any(|t| type_ok(t.as_str().unwrap(), v)),
            _ => panic!("{what}: bad type keyword"),
        };
        assert!(ok, "{what}: {v} is not of type {t}");
    }
    if let Some(e) = s.get("enum") {
        assert!(e.as_array().unwrap().contains(v), "{what}: {v} not in {e}");
    }
    if let Some(x) = v.as_f64() {
        if let Some(min) = s.get("minimum").and_then(Value::as_f64) {
            assert!(x >= min, "{what}: {x} < {min}");
        }
        if let Some(max) = s.get("maximum").and_then(Value::as_f64) {
            assert!(x <= max, "{what}: {x} > {max}");
        }
    }
    if let Some(items) = v.as_array() {
        if let Some(n) = s.get("minItems").and_then(Value::as_u64) {
            assert!(
                items.len() as u64 >= n,
                "{what}: {} items < {n}",
                items.len()
            );
        }
        if let Some(n) = s.get("maxItems").and_then(Value::as_u64) {
            assert!(
                items.len() as u64 <= n,
                "{what}: {} items > {n}",
                items.len()
            );
        }
        if let Some(item) = s.get("items") {
            for (i, x) in items.iter().enumerate() {
                validate_json(item, x, &format!("{what}[{i}]"));
            }
        }
    }
    if let Some(obj) = v.as_object() {
        let props = s.get("properties").and_then(Value::as_object);
        for r in s
            .get("required")
            .and_then(Value::as_array)
            .into_iter()
            .flatten()
        {
            let r = r.as_str().unwrap();
            assert!(obj.contains_key(r), "{what}: field `{r}` is missing");
        }
        for (k, x) in obj {
            match props.and_then(|p| p.get(k)) {
                Some(p) => validate_json(p, x, &format!("{what}.{k}")),
                None => assert!(
                    s.get("additionalProperties") != Some(&Value::Bool(false)),
                    "{what}: field `{k}` is not in the schema"
                ),
            }
        }
    }
}
