//! The MCAP recorder: every sample on every topic, every message valid against its schema
//! (the Foxglove SDK's for the scene, transforms and poses), and a file that survives SIGKILL
//! up to its last flush.

// `..Default::default()` keeps the fixtures compiling as the payloads grow fields.
#![allow(clippy::needless_update)]

mod common;

use common::schema_check::check_recording;
use dynamics::road::Obstacle;
use foxglove::messages::{FrameTransforms, PoseInFrame, Quaternion, SceneUpdate};
use iceoryx2::port::publisher::Publisher;
use iceoryx2::prelude::*;
use mcap::records::Record;
use mcap::MessageStream;
use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};
use vehicle_io::msg::{
    ActuatorCommand, ControllerStatus, Heartbeat, StateEstimate, PEER_CONTROLLER, PEER_VEHICLE,
};
use vehicle_io::ports::{self, ServiceNames, Svc};
use vehicle_io::record::scene::entity;
use vehicle_io::record::{topic, RecordMeta, Recorder, RoadLines, VehicleBox};

/// Messages per published state: the raw `/state` and the derived topics.
const PER_STATE: u64 = 8;
/// Messages per sample `k` on every topic ([`Pubs::publish`]).
const PER_K: u64 = PER_STATE + 4;

static NEXT: AtomicU32 = AtomicU32::new(0);

/// A service prefix no other test (or test process) uses.
fn unique_prefix() -> String {
    format!(
        "picopit-test-{}-{}",
        std::process::id(),
        NEXT.fetch_add(1, Ordering::Relaxed)
    )
}

fn temp_file(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("picopit-record-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn meta() -> RecordMeta {
    RecordMeta::new(
        VehicleBox {
            length: 4.5,
            width: 1.75,
            height: 1.5,
            cg_to_front: 2.5,
        },
        VehicleBox {
            length: 5.0,
            width: 2.0,
            height: 1.25,
            cg_to_front: 2.0,
        },
    )
    .with_road(RoadLines {
        left: vec![[0.0, 5.5], [200.0, 5.5]],
        right: vec![[0.0, -5.5], [200.0, -5.5]],
        centre: vec![[0.0, 0.0], [100.0, 0.0], [200.0, 0.0]],
    })
    .with_obstacles(vec![
        Obstacle {
            x: 80.0,
            y: 3.5,
            heading: 0.0,
            vx: 0.0,
            vy: 0.0,
            length: 4.0,
            width: 1.8,
        },
        Obstacle {
            x: 120.0,
            y: -3.5,
            heading: 0.1,
            vx: 10.0,
            vy: 0.5,
            length: 4.5,
            width: 1.9,
        },
    ])
    .with_contact_arrow_scale(1e-3)
    .with_entry("scenario", "unit-test")
    .with_entry("git_commit", "0000000")
}

/// Values that JSON carries exactly (multiples of 1/8).
fn state(k: u64) -> StateEstimate {
    let f = k as f64 * 0.125;
    StateEstimate {
        seq: k,
        stamp_ns: 20_000_000 * k,
        sent_ns: 20_000_000 * k + 1_000_000,
        wall_sent_ns: 1_000 + k,
        target: [20.0 + f, 0.5, 0.25 - f, 0.0, 0.0, -0.125, 10.0 + f, 1.75],
        bullet: [2.0 * f, -3.5, 0.7 + f, 24.0, 0.25, 0.5],
        target_input: [0.0, 100.0 * f],
        bullet_applied: [0.0625, -50.0],
        flags: (k % 3) as u32,
        commands_applied: k as u32,
        run_start_ns: 10_000_000,
        // In contact on every second sample: a force of 1 kN + 125 N k.
        contact_force: if k % 2 == 1 {
            [1000.0 + 1000.0 * f, -250.0]
        } else {
            [0.0; 2]
        },
        contact_gamma: if k % 2 == 1 { -1.5 } else { 0.0 },
        contact_point: if k % 2 == 1 { [-1.5, 0.875] } else { [0.0; 2] },
        ..StateEstimate::default()
    }
}

fn command(k: u64) -> ActuatorCommand {
    ActuatorCommand {
        seq: k,
        state_seq: k,
        stamp_ns: 20_000_000 * k + 5_000_000,
        valid_until_ns: 20_000_000 * k + 45_000_000,
        wall_state_received_ns: 2_000 + k,
        wall_sent_ns: 3_000 + k,
        steer: -0.125 * k as f64,
        torque: 250.0 - 16.0 * k as f64,
        mode: (k % 3) as u32,
        _reserved: 0,
        ..ActuatorCommand::default()
    }
}

fn status(k: u64) -> ControllerStatus {
    ControllerStatus {
        seq: k,
        state_seq: k,
        stamp_ns: 20_000_000 * k + 5_000_000,
        compensated_ns: 5_000_000,
        ctrl_ns: 100_000 + k,
        plan_ns: 0,
        deadline_misses: 0,
        fallbacks: (k / 4) as u32,
        stale_states: 1,
        phase: (k % 5) as u32,
        mpc_status: 1,
        faults: if k % 7 == 3 { 1 << 1 } else { 0 },
        ..ControllerStatus::default()
    }
}

fn heartbeat(k: u64, peer: u32) -> Heartbeat {
    Heartbeat {
        seq: k,
        wall_sent_ns: 4_000 + k,
        vehicle_ns: if peer == PEER_VEHICLE {
            20_000_000 * k + 7
        } else {
            0
        },
        peer,
        pid: 4242,
        ..Heartbeat::default()
    }
}

struct Pubs {
    _node: Node<Svc>,
    state: Publisher<Svc, StateEstimate, ()>,
    command: Publisher<Svc, ActuatorCommand, ()>,
    status: Publisher<Svc, ControllerStatus, ()>,
    hb_c: Publisher<Svc, Heartbeat, ()>,
    hb_v: Publisher<Svc, Heartbeat, ()>,
}

impl Pubs {
    fn open(names: &ServiceNames) -> Self {
        let node = ports::node("record-test").unwrap();
        Self {
            state: ports::publisher(&node, &names.state).unwrap(),
            command: ports::publisher(&node, &names.command).unwrap(),
            status: ports::publisher(&node, &names.status).unwrap(),
            hb_c: ports::publisher(&node, &names.heartbeat_controller).unwrap(),
            hb_v: ports::publisher(&node, &names.heartbeat_vehicle).unwrap(),
            _node: node,
        }
    }

    /// Publish sample `k` on every topic.
    fn publish(&self, k: u64) {
        ports::publish(&self.state, state(k)).unwrap();
        ports::publish(&self.command, command(k)).unwrap();
        ports::publish(&self.status, status(k)).unwrap();
        ports::publish(&self.hb_c, heartbeat(k, PEER_CONTROLLER)).unwrap();
        ports::publish(&self.hb_v, heartbeat(k, PEER_VEHICLE)).unwrap();
    }
}

/// Every message a streaming reader yields before the end (or the first error), and whether
/// it ended with an error.
fn stream(bytes: &[u8]) -> (Vec<mcap::Message<'static>>, bool) {
    let mut out = Vec::new();
    let Ok(reader) = MessageStream::new(bytes) else {
        return (out, true);
    };
    for m in reader {
        match m {
            Ok(m) => out.push(m),
            Err(_) => return (out, true),
        }
    }
    (out, false)
}

/// The JSON messages per topic (the Foxglove topics are protobuf and left out).
fn by_topic(msgs: &[mcap::Message<'static>]) -> BTreeMap<String, Vec<serde_json::Value>> {
    let mut map: BTreeMap<String, Vec<serde_json::Value>> = BTreeMap::new();
    for m in msgs.iter().filter(|m| m.channel.message_encoding == "json") {
        map.entry(m.channel.topic.clone())
            .or_default()
            .push(serde_json::from_slice(&m.data).unwrap());
    }
    map
}

/// The decoded Foxglove messages of `topic`.
fn decoded<T: prost::Message + Default>(msgs: &[mcap::Message<'static>], topic: &str) -> Vec<T> {
    msgs.iter()
        .filter(|m| m.channel.topic == topic)
        .map(|m| T::decode(&m.data[..]).unwrap())
        .collect()
}

fn yaw_of(q: Option<Quaternion>) -> f64 {
    let q = q.unwrap();
    assert_eq!((q.x, q.y), (0.0, 0.0));
    2.0 * q.z.atan2(q.w)
}

fn wrap(a: f64) -> f64 {
    (a + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI) - std::f64::consts::PI
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-9
}

#[test]
#[allow(clippy::needless_range_loop)] // k indexes several topics at once
fn records_every_topic_with_schemas_and_round_trips() {
    const N: u64 = 20;
    let names = ServiceNames::new(&unique_prefix()).unwrap();
    let path = temp_file("all-topics.mcap");
    let rec = Recorder::spawn(&names, &path, meta()).unwrap();
    assert!(rec.is_running());
    let pubs = Pubs::open(&names);
    for k in 0..N {
        pubs.publish(k);
        std::thread::sleep(Duration::from_micros(300));
    }
    let stats = rec.stop().unwrap();
    for t in topic::ALL {
        let n = if t == topic::ROAD { 1 } else { N };
        assert_eq!(stats.count(t), n, "{t}: {stats:?}");
    }
    assert_eq!(stats.total(), PER_K * N + 1);
    assert!(stats.seq_gaps.values().all(|&g| g == 0), "{stats:?}");

    let bytes = std::fs::read(&path).unwrap();
    // A finished file: the footer and summary are there.
    let summary = mcap::Summary::read(&bytes).unwrap().expect("a summary");
    assert_eq!(summary.stats.as_ref().unwrap().message_count, PER_K * N + 1);
    let (msgs, err) = stream(&bytes);
    assert!(!err, "a finished file streams to its end");
    assert_eq!(msgs.len() as u64, PER_K * N + 1);

    // Every message is valid against its channel's schema; the Foxglove ones are the SDK's.
    let checked = check_recording(&bytes);
    assert_eq!(checked.counts.len(), topic::ALL.len());
    for m in &msgs {
        let schema = m.channel.schema.as_ref().expect("a schema");
        let (name, encoding) = match m.channel.topic.as_str() {
            topic::STATE => ("picopit.StateEstimate", "json"),
            topic::COMMAND => ("picopit.ActuatorCommand", "json"),
            topic::STATUS => ("picopit.ControllerStatus", "json"),
            topic::HEARTBEAT_CONTROLLER | topic::HEARTBEAT_VEHICLE => ("picopit.Heartbeat", "json"),
            topic::SCENE => ("foxglove.SceneUpdate", "protobuf"),
            topic::TF => ("foxglove.FrameTransforms", "protobuf"),
            topic::BULLET_POSE | topic::TARGET_POSE => ("foxglove.PoseInFrame", "protobuf"),
            topic::BULLET_STATE => ("picopit.BulletPlot", "json"),
            topic::TARGET_STATE => ("picopit.TargetPlot", "json"),
            topic::CONTACT => ("picopit.Contact", "json"),
            topic::ROAD => ("picopit.Road", "json"),
            other => panic!("unexpected topic {other}"),
        };
        assert_eq!(schema.name, name, "{}", m.channel.topic);
        assert_eq!(m.channel.message_encoding, encoding, "{}", m.channel.topic);
    }

    // Log times are monotonic; publish times are the vehicle stamps.
    assert!(msgs.windows(2).all(|w| w[0].log_time <= w[1].log_time));
    let states: Vec<_> = msgs
        .iter()
        .filter(|m| m.channel.topic == topic::STATE)
        .collect();
    for (k, m) in states.iter().enumerate() {
        assert_eq!(m.publish_time, state(k as u64).sent_ns);
        assert_eq!(m.sequence as usize, k);
    }

    // The road, once, first: the polylines as given.
    let t = by_topic(&msgs);
    assert_eq!(msgs[0].channel.topic, topic::ROAD);
    let road = &t[topic::ROAD][0];
    assert_eq!(road["left"], serde_json::json!([[0.0, 5.5], [200.0, 5.5]]));
    assert_eq!(road["centre"].as_array().unwrap().len(), 3);

    // The raw payloads decode back to the values sent.
    let scenes: Vec<SceneUpdate> = decoded(&msgs, topic::SCENE);
    let tfs: Vec<FrameTransforms> = decoded(&msgs, topic::TF);
    let bullet_poses: Vec<PoseInFrame> = decoded(&msgs, topic::BULLET_POSE);
    let target_poses: Vec<PoseInFrame> = decoded(&msgs, topic::TARGET_POSE);
    for k in 0..N as usize {
        let ku = k as u64;
        let s: StateEstimate = serde_json::from_value(t[topic::STATE][k].clone()).unwrap();
        assert_eq!(s, state(ku));
        let c: ActuatorCommand = serde_json::from_value(t[topic::COMMAND][k].clone()).unwrap();
        assert_eq!(c, command(ku));
        let st: ControllerStatus = serde_json::from_value(t[topic::STATUS][k].clone()).unwrap();
        assert_eq!(st, status(ku));
        let h: Heartbeat =
            serde_json::from_value(t[topic::HEARTBEAT_CONTROLLER][k].clone()).unwrap();
        assert_eq!(h, heartbeat(ku, PEER_CONTROLLER));
        let h: Heartbeat = serde_json::from_value(t[topic::HEARTBEAT_VEHICLE][k].clone()).unwrap();
        assert_eq!(h, heartbeat(ku, PEER_VEHICLE));

        // Poses and transforms: position and yaw of each vehicle, in frame `world`, stamped
        // with stamp_ns.
        let s = state(ku);
        let (sec, nsec) = (
            (s.stamp_ns / 1_000_000_000) as u32,
            (s.stamp_ns % 1_000_000_000) as u32,
        );
        let bullet = (s.bullet[0], s.bullet[1], s.bullet[2]);
        let target = (s.target[6], s.target[7], s.target[2]);
        for (p, (x, y, psi)) in [(&bullet_poses[k], bullet), (&target_poses[k], target)] {
            assert_eq!(p.frame_id, "world");
            let ts = p.timestamp.unwrap();
            assert_eq!((ts.sec(), ts.nsec()), (sec, nsec));
            let pose = p.pose.unwrap();
            let pos = pose.position.unwrap();
            assert_eq!((pos.x, pos.y), (x, y));
            assert!(wrap(yaw_of(pose.orientation) - psi).abs() < 1e-12);
        }
        let tf = &tfs[k].transforms;
        assert_eq!(tf.len(), 2);
        for (f, child, (x, y, psi)) in [(&tf[0], "bullet", bullet), (&tf[1], "target", target)] {
            assert_eq!(
                (f.parent_frame_id.as_str(), f.child_frame_id.as_str()),
                ("world", child)
            );
            let tr = f.translation.unwrap();
            assert_eq!((tr.x, tr.y), (x, y));
            assert!(wrap(yaw_of(f.rotation) - psi).abs() < 1e-12);
        }

        // The plot topics: named fields of the same state.
        let b = &t[topic::BULLET_STATE][k];
        assert_eq!(b["speed"].as_f64(), Some(s.bullet[3].hypot(s.bullet[4])));
        assert_eq!(b["yaw_rate"].as_f64(), Some(s.bullet[5]));
        assert_eq!(b["torque"].as_f64(), Some(s.bullet_applied[1]));
        let tp = &t[topic::TARGET_STATE][k];
        assert_eq!(tp["yaw"].as_f64(), Some(s.target[2]));
        assert_eq!(tp["roll"].as_f64(), Some(s.target[5]));
        assert_eq!(tp["brake_torque"].as_f64(), Some(s.target_input[1]));
        assert_eq!(tp["timestamp"]["nsec"].as_u64(), Some(u64::from(nsec)));
        let c = &t[topic::CONTACT][k];
        assert_eq!(c["normal_force"].as_f64(), Some(s.contact_force[0]));
        assert_eq!(
            c["force"].as_f64(),
            Some(s.contact_force[0].hypot(s.contact_force[1]))
        );
        assert_eq!(c["in_contact"], serde_json::json!(s.flags & 2 != 0));

        // The scene: one cube per vehicle of its size at its pose, the contact, the obstacles
        // where they are at scenario time, and the road on the first.
        let entities = &scenes[k].entities;
        let ids: Vec<_> = entities.iter().map(|e| e.id.as_str()).collect();
        let mut expected = vec![
            entity::BULLET,
            entity::TARGET,
            entity::CONTACT,
            "obstacle/0",
            "obstacle/1",
        ];
        if k == 0 {
            expected.push(entity::ROAD);
            let lines = &entities[5].lines;
            assert_eq!(lines.len(), 3);
            assert_eq!(lines[2].points.len(), 3);
            assert_eq!(lines[0].r#type, 0);
            assert_eq!(lines[0].points[1].y, 5.5);
        }
        assert_eq!(ids, expected);
        for (e, b, (x, y, psi)) in [
            (&entities[0], meta().bullet, bullet),
            (&entities[1], meta().target, target),
        ] {
            assert_eq!(e.frame_id, "world");
            let cube = &e.cubes[0];
            let size = cube.size.unwrap();
            assert_eq!((size.x, size.y, size.z), (b.length, b.width, b.height));
            let pose = cube.pose.unwrap();
            let pos = pose.position.unwrap();
            // Centred on the footprint: cg_to_front − length/2 ahead of the c.g.
            let ahead = b.cg_to_front - 0.5 * b.length;
            let (cx, cy) = (x + ahead * psi.cos(), y + ahead * psi.sin());
            assert!(close(pos.x, cx) && close(pos.y, cy), "{pos:?}");
            assert_eq!(pos.z, 0.5 * b.height);
            assert!(wrap(yaw_of(pose.orientation) - psi).abs() < 1e-12);
            assert_eq!(e.texts.len(), 1);
        }
        // The contact arrow: drawn in contact only, pointing along R(γ) f_c, its head at the
        // contact point (target body frame → world), 1 mm per N long.
        let arrows = &entities[2].arrows;
        if s.contact_force[0] > 0.0 {
            assert_eq!(arrows.len(), 1, "k = {k}");
            let a = arrows[0];
            let pose = a.pose.unwrap();
            let f = s.contact_force;
            let g = s.contact_gamma;
            let fw = (
                f[0] * g.cos() - f[1] * g.sin(),
                f[0] * g.sin() + f[1] * g.cos(),
            );
            let heading = yaw_of(pose.orientation);
            assert!(wrap(heading - fw.1.atan2(fw.0)).abs() < 1e-9);
            let len = a.shaft_length + a.head_length;
            assert!(close(len, f[0].hypot(f[1]) * 1e-3));
            let tail = pose.position.unwrap();
            let (sn, cs) = s.target[2].sin_cos();
            let [px, py] = s.contact_point;
            let point = (
                s.target[6] + cs * px - sn * py,
                s.target[7] + sn * px + cs * py,
            );
            assert!(close(tail.x + len * heading.cos(), point.0));
            assert!(close(tail.y + len * heading.sin(), point.1));
        } else {
            assert!(arrows.is_empty(), "k = {k}");
        }
        // The moving obstacle at t = stamp − run start.
        let tt = s.stamp_ns.saturating_sub(s.run_start_ns) as f64 * 1e-9;
        let ob = entities[4].cubes[0].pose.unwrap().position.unwrap();
        assert!(
            close(ob.x, 120.0 + 10.0 * tt) && close(ob.y, -3.5 + 0.5 * tt),
            "{ob:?}"
        );
        let ob0 = entities[3].cubes[0].pose.unwrap().position.unwrap();
        assert_eq!((ob0.x, ob0.y), (80.0, 3.5));
    }

    // The Metadata record carries the boxes and the caller's entries.
    let metadata: Vec<_> = mcap::read::LinearReader::new(&bytes)
        .unwrap()
        .filter_map(|r| match r.unwrap() {
            Record::Metadata(m) => Some(m),
            _ => None,
        })
        .collect();
    assert_eq!(metadata.len(), 1);
    let md = &metadata[0].metadata;
    assert_eq!(metadata[0].name, "picopit");
    assert_eq!(md["scenario"], "unit-test");
    assert_eq!(md["git_commit"], "0000000");
    assert_eq!(md["bullet.length"], "4.5");
    assert_eq!(md["target.width"], "2");
    assert_eq!(md["recorder.obstacles"], "2");
    assert_eq!(md["service.state"], names.state);
    // PICOPIT_RECORD_KEEP=DIR keeps a copy (e.g. to try `picopit replay` or Foxglove on it).
    if let Ok(dir) = std::env::var("PICOPIT_RECORD_KEEP") {
        std::fs::copy(&path, Path::new(&dir).join("record-test.mcap")).unwrap();
    }
    let _ = std::fs::remove_file(&path);
}

#[test]
fn drop_without_stop_finishes_the_file() {
    let names = ServiceNames::new(&unique_prefix()).unwrap();
    let path = temp_file("dropped.mcap");
    let rec = Recorder::spawn(&names, &path, RecordMeta::default()).unwrap();
    let pubs = Pubs::open(&names);
    for k in 0..5 {
        pubs.publish(k);
    }
    drop(rec);
    let bytes = std::fs::read(&path).unwrap();
    assert!(mcap::Summary::read(&bytes).unwrap().is_some());
    let (msgs, err) = stream(&bytes);
    assert!(!err);
    // No road: the scene is still written.
    assert_eq!(msgs.len() as u64, 5 * PER_K);
    let _ = std::fs::remove_file(&path);
}

#[test]
fn spawn_names_the_file_it_cannot_create() {
    let names = ServiceNames::new(&unique_prefix()).unwrap();
    let path = Path::new("/nonexistent-dir-picopit/x.mcap");
    let e = Recorder::spawn(&names, path, RecordMeta::default())
        .err()
        .expect("cannot create");
    assert!(
        e.to_string().contains("/nonexistent-dir-picopit/x.mcap"),
        "{e}"
    );
}

/// Wait until the file at `path` streams `n` messages (the recorder flushed them).
fn wait_flushed(path: &Path, n: usize) {
    let start = Instant::now();
    loop {
        let bytes = std::fs::read(path).unwrap();
        if stream(&bytes).0.len() >= n {
            return;
        }
        assert!(
            start.elapsed() < Duration::from_secs(20),
            "never flushed {n}"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
}

#[test]
#[allow(clippy::needless_range_loop)]
fn unfinished_and_truncated_files_stream_up_to_the_last_flushed_message() {
    const N: u64 = 10;
    let names = ServiceNames::new(&unique_prefix()).unwrap();
    let path = temp_file("mid-run.mcap");
    let rec = Recorder::spawn(&names, &path, meta()).unwrap();
    let pubs = Pubs::open(&names);
    for k in 0..N {
        pubs.publish(k);
    }
    wait_flushed(&path, (PER_K * N + 1) as usize);
    // Copy the file mid-run: exactly what a killed process leaves behind.
    let bytes = std::fs::read(&path).unwrap();
    assert!(mcap::Summary::read(&bytes).is_err() || mcap::Summary::read(&bytes).unwrap().is_none());
    let (msgs, _) = stream(&bytes);
    assert_eq!(msgs.len() as u64, PER_K * N + 1);
    let t = by_topic(&msgs);
    for k in 0..N as usize {
        let s: StateEstimate = serde_json::from_value(t[topic::STATE][k].clone()).unwrap();
        assert_eq!(s, state(k as u64));
    }

    // Cut inside the last message: everything before it still streams.
    let (all, _) = stream(&bytes);
    for cut in [1usize, 7, 20] {
        let (msgs, err) = stream(&bytes[..bytes.len() - cut]);
        assert!(err, "a truncated file ends with an error, not a panic");
        assert_eq!(msgs.len(), all.len() - 1, "cut {cut}");
    }
    rec.stop().unwrap();
    let _ = std::fs::remove_file(&path);
}

const CHILD_ENV: &str = "PICOPIT_RECORD_CRASH_CHILD";

/// The child of `sigkill_leaves_a_readable_file` (does nothing unless run by it).
#[test]
#[ignore = "run as a child process by sigkill_leaves_a_readable_file"]
fn crash_child() {
    let Ok(spec) = std::env::var(CHILD_ENV) else {
        return;
    };
    let (prefix, path) = spec.split_once('|').unwrap();
    let names = ServiceNames::new(prefix).unwrap();
    let rec = Recorder::spawn(&names, Path::new(path), meta()).unwrap();
    let pubs = Pubs::open(&names);
    for k in 0..12 {
        pubs.publish(k);
    }
    wait_flushed(Path::new(path), 12 * PER_K as usize + 1);
    println!("FLUSHED");
    std::thread::sleep(Duration::from_secs(120));
    drop(rec);
}

#[test]
fn sigkill_leaves_a_readable_file() {
    let prefix = unique_prefix();
    let path = temp_file("killed.mcap");
    let mut child = Command::new(std::env::current_exe().unwrap())
        .args(["crash_child", "--exact", "--ignored", "--nocapture"])
        .env(CHILD_ENV, format!("{prefix}|{}", path.display()))
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let flushed = lines.any(|l| l.map(|l| l.trim() == "FLUSHED").unwrap_or(false));
    child.kill().unwrap(); // SIGKILL
    let _ = child.wait();
    assert!(flushed, "the child never reported its flush");

    let bytes = std::fs::read(&path).unwrap();
    let (msgs, _) = stream(&bytes);
    assert_eq!(msgs.len(), 12 * PER_K as usize + 1);
    let t = by_topic(&msgs);
    let s: StateEstimate = serde_json::from_value(t[topic::STATE][11].clone()).unwrap();
    assert_eq!(s, state(11));
    let _ = std::fs::remove_file(&path);

    // Remove the killed process's iceoryx2 resources.
    let node = ports::node("record-test-cleanup").unwrap();
    let _ = node.try_cleanup_dead_nodes();
}
