//! MCAP recording of every publish-subscribe service, on a thread of its own.
//!
//! A [`Recorder`] owns a thread with its own iceoryx2 node and one subscriber per
//! publish-subscribe service (state, command, status, both heartbeats). Every
//! [`POLL_PERIOD`] it drains all pending samples and writes each into an MCAP file, so the
//! real-time loop of the process never waits for, or allocates for, the log. The recorder
//! allocates freely (JSON encoding).
//!
//! # Topics
//!
//! | topic                   | schema (encoding `jsonschema`) | from                   |
//! |-------------------------|--------------------------------|------------------------|
//! | `/state`                | `picopit.StateEstimate`        | `<prefix>/state`       |
//! | `/command`              | `picopit.ActuatorCommand`      | `<prefix>/command`     |
//! | `/status`               | `picopit.ControllerStatus`     | `<prefix>/status`      |
//! | `/heartbeat/controller` | `picopit.Heartbeat`            | `<prefix>/heartbeat/controller` |
//! | `/heartbeat/vehicle`    | `picopit.Heartbeat`            | `<prefix>/heartbeat/vehicle`    |
//! | `/scene`                | `foxglove.SceneUpdate`         | each state             |
//! | `/bullet/pose`          | `foxglove.PoseInFrame`         | each state             |
//! | `/target/pose`          | `foxglove.PoseInFrame`         | each state             |
//!
//! Every message is JSON (`message_encoding = "json"`): the raw topics hold the payload as
//! serde writes it (a non-finite number reads `null`); the derived topics follow Foxglove's
//! well-known schemas in frame `world` (x east, y north, z up; orientation = the yaw ψ as a
//! quaternion about z). `/scene` carries one entity per vehicle (`bullet`, `target`: a cube of
//! the vehicle's size centred over its c.g., plus a name label) and, with the first scene and
//! then every [`ROAD_PERIOD_NS`], the entity `road` (the road's polylines; lifetime 0 =
//! forever).
//!
//! # Times
//!
//! `log_time` is the recorder's `CLOCK_MONOTONIC` receive time minus the recording's start
//! (monotonic, ns); `publish_time` is the payload's own vehicle-clock time: the state's
//! `sent_ns`, the command's and status's `stamp_ns`, and for the derived topics the state's
//! `stamp_ns` (when the pose was measured; also the Foxglove `timestamp`), and a heartbeat's
//! `vehicle_ns` when it has one (the vehicle side's); otherwise (the controller's heartbeats)
//! `publish_time` is the `log_time`.
//!
//! # Crash safety
//!
//! The file is written without chunks and flushed to the kernel after every drain that wrote
//! something: a process killed with SIGKILL leaves a file that a streaming reader reads up to
//! the last flushed message (it lacks only the summary and footer). [`Recorder::stop`] (or
//! dropping the recorder) drains a last time, writes summary and footer, and syncs the file.

use crate::msg::{ActuatorCommand, ControllerStatus, Heartbeat, StateEstimate};
use crate::ports::{self, monotonic_ns, PortError, ServiceNames, Svc};
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::ZeroCopySend;
use mcap::records::{MessageHeader, Metadata};
use serde::Serialize;
use serde_json::{json, Value};
use std::collections::BTreeMap;
use std::fmt::Debug;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::thread::JoinHandle;
use std::time::Duration;

/// How often the recorder thread drains its subscribers.
pub const POLL_PERIOD: Duration = Duration::from_millis(1);
/// How often (log time) the road entity is repeated on `/scene`, so a viewer that seeks sees it
/// again soon.
pub const ROAD_PERIOD_NS: u64 = 1_000_000_000;
/// The frame of every derived message.
pub const WORLD_FRAME: &str = "world";
/// The name of the MCAP Metadata record.
pub const METADATA_NAME: &str = "picopit";

/// The topic names, in [`RecordStats`] order.
pub mod topic {
    pub const STATE: &str = "/state";
    pub const COMMAND: &str = "/command";
    pub const STATUS: &str = "/status";
    pub const HEARTBEAT_CONTROLLER: &str = "/heartbeat/controller";
    pub const HEARTBEAT_VEHICLE: &str = "/heartbeat/vehicle";
    pub const SCENE: &str = "/scene";
    pub const BULLET_POSE: &str = "/bullet/pose";
    pub const TARGET_POSE: &str = "/target/pose";
    /// Every topic, raw first.
    pub const ALL: [&str; 8] = [
        STATE,
        COMMAND,
        STATUS,
        HEARTBEAT_CONTROLLER,
        HEARTBEAT_VEHICLE,
        SCENE,
        BULLET_POSE,
        TARGET_POSE,
    ];
}

/// A vehicle's box for the scene (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VehicleBox {
    pub length: f64,
    pub width: f64,
    pub height: f64,
}

impl Default for VehicleBox {
    /// A full-size sedan.
    fn default() -> Self {
        Self {
            length: 4.8,
            width: 1.85,
            height: 1.45,
        }
    }
}

/// The road as polylines in the world frame (`[X, Y]`, m).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RoadLines {
    pub left: Vec<[f64; 2]>,
    pub right: Vec<[f64; 2]>,
    pub centre: Vec<[f64; 2]>,
}

/// What the recording needs besides the samples.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RecordMeta {
    pub bullet: VehicleBox,
    pub target: VehicleBox,
    /// Drawn on `/scene` when given.
    pub road: Option<RoadLines>,
    /// Free-form key/values (command line, scenario id, git commit, …) for the Metadata record
    /// [`METADATA_NAME`]; they override the recorder's own keys of the same name.
    pub metadata: BTreeMap<String, String>,
}

impl RecordMeta {
    /// The vehicles' boxes, no road, no metadata.
    #[must_use]
    pub fn new(bullet: VehicleBox, target: VehicleBox) -> Self {
        Self {
            bullet,
            target,
            ..Self::default()
        }
    }

    /// With the road's polylines.
    #[must_use]
    pub fn with_road(mut self, road: RoadLines) -> Self {
        self.road = Some(road);
        self
    }

    /// With one more metadata entry.
    #[must_use]
    pub fn with_entry(mut self, key: impl Into<String>, value: impl Into<String>) -> Self {
        self.metadata.insert(key.into(), value.into());
        self
    }
}

/// A recording failure, naming the file or the service.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    #[error("recording {}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("recording {}: MCAP: {source}", path.display())]
    Mcap {
        path: PathBuf,
        #[source]
        source: mcap::McapError,
    },
    #[error("recording {}: encoding a `{topic}` message: {reason}", path.display())]
    Encode {
        path: PathBuf,
        topic: &'static str,
        reason: String,
    },
    #[error("recording {}: {source}", path.display())]
    Port {
        path: PathBuf,
        #[source]
        source: PortError,
    },
    #[error("recording {}: the recorder thread {reason}", path.display())]
    Thread { path: PathBuf, reason: String },
}

/// What a finished recording holds.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RecordStats {
    pub path: PathBuf,
    /// Messages written per topic (every topic of [`topic::ALL`] is a key).
    pub messages: BTreeMap<String, u64>,
    /// Samples missing between consecutive `seq` numbers on each raw topic (subscriber buffer
    /// overflow, or a publisher that restarted).
    pub seq_gaps: BTreeMap<String, u64>,
    /// Failed receives per raw topic (the recorder retries on the next poll).
    pub receive_errors: BTreeMap<String, u64>,
    /// States whose derived messages were skipped because a pose number was not finite.
    pub non_finite_states: u64,
    /// Log time of the last message (ns since the recording's start).
    pub last_log_ns: u64,
}

impl RecordStats {
    /// Messages written on all topics.
    #[must_use]
    pub fn total(&self) -> u64 {
        self.messages.values().sum()
    }

    /// Messages written on `topic` (0 for an unknown topic).
    #[must_use]
    pub fn count(&self, topic: &str) -> u64 {
        self.messages.get(topic).copied().unwrap_or(0)
    }
}

/// A running recorder; [`Recorder::stop`] finishes the file.
pub struct Recorder {
    path: PathBuf,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<Result<RecordStats, RecordError>>>,
}

impl Recorder {
    /// Start recording every publish-subscribe service of `names` into `path` (created or
    /// truncated). Returns once the thread's subscribers exist and the file's header, schemas,
    /// channels and metadata are written (and flushed), so samples published afterwards are
    /// recorded.
    ///
    /// # Errors
    /// [`RecordError`] naming the file or service when the thread cannot set up.
    pub fn spawn(names: &ServiceNames, path: &Path, meta: RecordMeta) -> Result<Self, RecordError> {
        let path = path.to_path_buf();
        let stop = Arc::new(AtomicBool::new(false));
        let (ready_tx, ready_rx) = mpsc::sync_channel::<Result<(), RecordError>>(1);
        let (names_t, path_t, stop_t) = (names.clone(), path.clone(), Arc::clone(&stop));
        let thread = std::thread::Builder::new()
            .name("pit-recorder".to_owned())
            .spawn(move || run(&names_t, &path_t, &meta, &stop_t, &ready_tx))
            .map_err(|e| RecordError::Thread {
                path: path.clone(),
                reason: format!("could not start: {e}"),
            })?;
        match ready_rx.recv() {
            Ok(Ok(())) => Ok(Self {
                path,
                stop,
                thread: Some(thread),
            }),
            Ok(Err(e)) => {
                let _ = thread.join();
                Err(e)
            }
            Err(_) => {
                let reason = match thread.join() {
                    Ok(Err(e)) => return Err(e),
                    Ok(Ok(_)) => "ended before it was ready".to_owned(),
                    Err(p) => format!("panicked: {}", panic_text(&p)),
                };
                Err(RecordError::Thread { path, reason })
            }
        }
    }

    /// The file being written.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Whether the thread still records (false after a write failure; [`Recorder::stop`]
    /// then reports it).
    #[must_use]
    pub fn is_running(&self) -> bool {
        self.thread.as_ref().is_some_and(|t| !t.is_finished())
    }

    /// Drain a last time, write the summary and footer, sync the file and join the thread.
    ///
    /// # Errors
    /// The first [`RecordError`] the thread met (the file then holds everything flushed
    /// before it).
    pub fn stop(mut self) -> Result<RecordStats, RecordError> {
        self.finish()
    }

    fn finish(&mut self) -> Result<RecordStats, RecordError> {
        self.stop.store(true, Ordering::Release);
        let Some(thread) = self.thread.take() else {
            return Err(RecordError::Thread {
                path: self.path.clone(),
                reason: "was already stopped".to_owned(),
            });
        };
        match thread.join() {
            Ok(r) => r,
            Err(p) => Err(RecordError::Thread {
                path: self.path.clone(),
                reason: format!("panicked: {}", panic_text(&p)),
            }),
        }
    }
}

impl Drop for Recorder {
    fn drop(&mut self) {
        if self.thread.is_some() {
            if let Err(e) = self.finish() {
                eprintln!("pit-recorder: {e}");
            }
        }
    }
}

fn panic_text(p: &(dyn std::any::Any + Send)) -> String {
    p.downcast_ref::<&str>()
        .map(|s| (*s).to_owned())
        .or_else(|| p.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "(no message)".to_owned())
}

// ---------------------------------------------------------------------------------------------
// The thread.

type McapWriter = mcap::Writer<BufWriter<File>>;

const I_STATE: usize = 0;
const I_COMMAND: usize = 1;
const I_STATUS: usize = 2;
const I_HB_CONTROLLER: usize = 3;
const I_HB_VEHICLE: usize = 4;
const I_SCENE: usize = 5;
const I_BULLET_POSE: usize = 6;
const I_TARGET_POSE: usize = 7;
const N_TOPICS: usize = 8;

/// The MCAP side: writer, channels, counters.
struct Sink {
    path: PathBuf,
    writer: McapWriter,
    channel: [u16; N_TOPICS],
    count: [u64; N_TOPICS],
    last_seq: [Option<u64>; 5],
    gaps: [u64; 5],
    receive_errors: [u64; 5],
    non_finite: u64,
    t0: u64,
    last_log: u64,
    last_road_log: Option<u64>,
    buf: Vec<u8>,
    bullet: VehicleBox,
    target: VehicleBox,
    road: Option<Vec<Line>>,
}

fn run(
    names: &ServiceNames,
    path: &Path,
    meta: &RecordMeta,
    stop: &AtomicBool,
    ready: &mpsc::SyncSender<Result<(), RecordError>>,
) -> Result<RecordStats, RecordError> {
    let port_err = |source: PortError| RecordError::Port {
        path: path.to_path_buf(),
        source,
    };
    let setup = (|| {
        let node = ports::node("pit-recorder").map_err(port_err)?;
        let subs = Subs {
            state: ports::subscriber::<StateEstimate>(&node, &names.state).map_err(port_err)?,
            command: ports::subscriber::<ActuatorCommand>(&node, &names.command)
                .map_err(port_err)?,
            status: ports::subscriber::<ControllerStatus>(&node, &names.status)
                .map_err(port_err)?,
            hb_controller: ports::subscriber::<Heartbeat>(&node, &names.heartbeat_controller)
                .map_err(port_err)?,
            hb_vehicle: ports::subscriber::<Heartbeat>(&node, &names.heartbeat_vehicle)
                .map_err(port_err)?,
        };
        let sink = Sink::create(path, names, meta)?;
        Ok((node, subs, sink))
    })();
    let (_node, subs, mut sink) = match setup {
        Ok(v) => v,
        Err(e) => {
            let _ = ready.send(Err(e));
            return Err(RecordError::Thread {
                path: path.to_path_buf(),
                reason: "failed to set up".to_owned(),
            });
        }
    };
    let _ = ready.send(Ok(()));

    let mut result = Ok(());
    while !stop.load(Ordering::Acquire) {
        if let Err(e) = sink.drain_and_flush(&subs) {
            result = Err(e);
            break;
        }
        std::thread::sleep(POLL_PERIOD);
    }
    if result.is_ok() {
        result = sink.drain_and_flush(&subs);
    }
    // Finish the file even after a failed write: the summary covers what was written.
    let finished = sink.finish();
    result.and(finished)
}

struct Subs {
    state: Subscriber<Svc, StateEstimate, ()>,
    command: Subscriber<Svc, ActuatorCommand, ()>,
    status: Subscriber<Svc, ControllerStatus, ()>,
    hb_controller: Subscriber<Svc, Heartbeat, ()>,
    hb_vehicle: Subscriber<Svc, Heartbeat, ()>,
}

/// At most this many samples per subscriber and drain (the buffer holds
/// [`ports::SUBSCRIBER_BUFFER`]), so a fast publisher cannot keep the recorder from the others.
const MAX_PER_DRAIN: usize = 4 * ports::SUBSCRIBER_BUFFER;

/// Receive up to [`MAX_PER_DRAIN`] samples of `sub` into `out`; a receive error is counted
/// and ends this subscriber's drain.
fn receive_all<T: Debug + Copy + ZeroCopySend + 'static>(
    sub: &Subscriber<Svc, T, ()>,
    errors: &mut u64,
    mut out: impl FnMut(T) -> Result<(), RecordError>,
) -> Result<usize, RecordError> {
    let mut n = 0;
    while n < MAX_PER_DRAIN {
        match sub.receive() {
            Ok(Some(sample)) => {
                let v = *sample.payload();
                drop(sample);
                out(v)?;
                n += 1;
            }
            Ok(None) => break,
            Err(_) => {
                *errors += 1;
                break;
            }
        }
    }
    Ok(n)
}

impl Sink {
    fn create(path: &Path, names: &ServiceNames, meta: &RecordMeta) -> Result<Self, RecordError> {
        let file = File::create(path).map_err(|source| RecordError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let mcap_err = |source| RecordError::Mcap {
            path: path.to_path_buf(),
            source,
        };
        let mut writer = mcap::WriteOptions::new()
            .compression(None)
            .use_chunks(false)
            .profile("")
            .library(concat!("picopit-vehicle-io ", env!("CARGO_PKG_VERSION")))
            .create(BufWriter::new(file))
            .map_err(mcap_err)?;
        let schema = |w: &mut McapWriter, name: &str, doc: Value| {
            let data = serde_json::to_vec_pretty(&doc).expect("a JSON value always serialises");
            w.add_schema(name, "jsonschema", &data)
        };
        let s_state =
            schema(&mut writer, "picopit.StateEstimate", state_schema()).map_err(mcap_err)?;
        let s_command =
            schema(&mut writer, "picopit.ActuatorCommand", command_schema()).map_err(mcap_err)?;
        let s_status =
            schema(&mut writer, "picopit.ControllerStatus", status_schema()).map_err(mcap_err)?;
        let s_hb =
            schema(&mut writer, "picopit.Heartbeat", heartbeat_schema()).map_err(mcap_err)?;
        let s_scene =
            schema(&mut writer, "foxglove.SceneUpdate", scene_update_schema()).map_err(mcap_err)?;
        let s_pose = schema(&mut writer, "foxglove.PoseInFrame", pose_in_frame_schema())
            .map_err(mcap_err)?;

        let service_of = [
            Some(&names.state),
            Some(&names.command),
            Some(&names.status),
            Some(&names.heartbeat_controller),
            Some(&names.heartbeat_vehicle),
            None,
            None,
            None,
        ];
        let schema_of = [
            s_state, s_command, s_status, s_hb, s_hb, s_scene, s_pose, s_pose,
        ];
        let mut channel = [0u16; N_TOPICS];
        for i in 0..N_TOPICS {
            let mut md = BTreeMap::new();
            if let Some(service) = service_of[i] {
                md.insert("iceoryx2_service".to_owned(), service.clone());
            } else {
                md.insert("derived_from".to_owned(), topic::STATE.to_owned());
            }
            channel[i] = writer
                .add_channel(schema_of[i], topic::ALL[i], "json", &md)
                .map_err(mcap_err)?;
        }

        let t0 = monotonic_ns();
        let mut md = BTreeMap::new();
        let mut put = |k: &str, v: String| {
            md.insert(k.to_owned(), v);
        };
        for (who, b) in [("bullet", meta.bullet), ("target", meta.target)] {
            put(&format!("{who}.length"), b.length.to_string());
            put(&format!("{who}.width"), b.width.to_string());
            put(&format!("{who}.height"), b.height.to_string());
        }
        put("recorder.start_monotonic_ns", t0.to_string());
        put("recorder.pid", std::process::id().to_string());
        put("recorder.road", meta.road.is_some().to_string());
        for (i, service) in service_of.iter().enumerate() {
            if let Some(s) = service {
                put(
                    &format!("service{}", topic::ALL[i].replace('/', ".")),
                    (*s).clone(),
                );
            }
        }
        for (k, v) in &meta.metadata {
            md.insert(k.clone(), v.clone());
        }
        writer
            .write_metadata(&Metadata {
                name: METADATA_NAME.to_owned(),
                metadata: md,
            })
            .map_err(mcap_err)?;
        writer.flush().map_err(mcap_err)?;

        let road = meta.road.as_ref().map(|r| {
            let grey = Color::rgba(0.85, 0.85, 0.85, 1.0);
            let yellow = Color::rgba(1.0, 0.85, 0.1, 1.0);
            [(&r.left, grey), (&r.right, grey), (&r.centre, yellow)]
                .into_iter()
                .filter(|(pts, _)| pts.len() >= 2)
                .map(|(pts, color)| Line {
                    kind: 0, // LINE_STRIP
                    pose: Pose::identity(),
                    thickness: 0.15,
                    scale_invariant: false,
                    points: pts
                        .iter()
                        .map(|p| Vec3 {
                            x: p[0],
                            y: p[1],
                            z: 0.01,
                        })
                        .collect(),
                    color,
                    colors: [],
                    indices: [],
                })
                .collect()
        });

        Ok(Self {
            path: path.to_path_buf(),
            writer,
            channel,
            count: [0; N_TOPICS],
            last_seq: [None; 5],
            gaps: [0; 5],
            receive_errors: [0; 5],
            non_finite: 0,
            t0,
            last_log: 0,
            last_road_log: None,
            buf: Vec::with_capacity(4096),
            bullet: meta.bullet,
            target: meta.target,
            road,
        })
    }

    fn mcap_err(&self, source: mcap::McapError) -> RecordError {
        RecordError::Mcap {
            path: self.path.clone(),
            source,
        }
    }

    /// Now on the recording's clock (ns since its start; never decreasing).
    fn log_now(&mut self) -> u64 {
        let t = monotonic_ns().saturating_sub(self.t0).max(self.last_log);
        self.last_log = t;
        t
    }

    /// Encode `value` as JSON and write it on topic `i`.
    fn write<T: Serialize>(
        &mut self,
        i: usize,
        log_time: u64,
        publish_time: u64,
        value: &T,
    ) -> Result<(), RecordError> {
        self.buf.clear();
        serde_json::to_writer(&mut self.buf, value).map_err(|e| RecordError::Encode {
            path: self.path.clone(),
            topic: topic::ALL[i],
            reason: e.to_string(),
        })?;
        let header = MessageHeader {
            channel_id: self.channel[i],
            sequence: self.count[i] as u32,
            log_time,
            publish_time,
        };
        self.writer
            .write_to_known_channel(&header, &self.buf)
            .map_err(|e| self.mcap_err(e))?;
        self.count[i] += 1;
        Ok(())
    }

    fn note_seq(&mut self, i: usize, seq: u64) {
        if let Some(last) = self.last_seq[i] {
            if seq > last + 1 {
                self.gaps[i] += seq - last - 1;
            }
        }
        self.last_seq[i] = Some(seq);
    }

    fn on_state(&mut self, s: &StateEstimate) -> Result<(), RecordError> {
        let log = self.log_now();
        self.note_seq(I_STATE, s.seq);
        self.write(I_STATE, log, s.sent_ns, s)?;
        let (bx, by, bpsi) = (s.bullet[0], s.bullet[1], s.bullet[2]);
        let (tx, ty, tpsi) = (s.target[6], s.target[7], s.target[2]);
        if ![bx, by, bpsi, tx, ty, tpsi].iter().all(|v| v.is_finite()) {
            self.non_finite += 1;
            return Ok(());
        }
        let stamp = Time::from_ns(s.stamp_ns);
        let bullet_pose = Pose::planar(bx, by, 0.0, bpsi);
        let target_pose = Pose::planar(tx, ty, 0.0, tpsi);
        let road = match (&self.road, self.last_road_log) {
            (Some(_), None) => true,
            (Some(_), Some(t)) => log.saturating_sub(t) >= ROAD_PERIOD_NS,
            (None, _) => false,
        };
        let mut entities = Vec::with_capacity(3);
        entities.push(vehicle_entity(
            "bullet",
            stamp,
            bullet_pose,
            self.bullet,
            Color::rgba(0.15, 0.45, 0.95, 0.9),
        ));
        entities.push(vehicle_entity(
            "target",
            stamp,
            target_pose,
            self.target,
            Color::rgba(0.95, 0.3, 0.15, 0.9),
        ));
        let road_lines = if road { self.road.take() } else { None };
        if let Some(lines) = &road_lines {
            entities.push(Entity {
                timestamp: stamp,
                frame_id: WORLD_FRAME,
                id: "road",
                lifetime: Time::ZERO,
                frame_locked: true,
                metadata: Vec::new(),
                arrows: [],
                cubes: Vec::new(),
                spheres: [],
                cylinders: [],
                lines: lines.as_slice(),
                triangles: [],
                texts: Vec::new(),
                models: [],
            });
        }
        let scene = SceneUpdate {
            deletions: [],
            entities,
        };
        let r = self.write(I_SCENE, log, s.stamp_ns, &scene);
        drop(scene);
        if road_lines.is_some() {
            self.road = road_lines;
            self.last_road_log = Some(log);
        }
        r?;
        for (i, pose) in [(I_BULLET_POSE, bullet_pose), (I_TARGET_POSE, target_pose)] {
            let msg = PoseInFrame {
                timestamp: stamp,
                frame_id: WORLD_FRAME,
                pose,
            };
            self.write(i, log, s.stamp_ns, &msg)?;
        }
        Ok(())
    }

    /// Drain every subscriber once; flush when something was written.
    fn drain_and_flush(&mut self, subs: &Subs) -> Result<(), RecordError> {
        let mut errors = self.receive_errors;
        let mut n = 0;
        n += receive_all(&subs.state, &mut errors[I_STATE], |s| self.on_state(&s))?;
        n += receive_all(&subs.command, &mut errors[I_COMMAND], |c| {
            let log = self.log_now();
            self.note_seq(I_COMMAND, c.seq);
            self.write(I_COMMAND, log, c.stamp_ns, &c)
        })?;
        n += receive_all(&subs.status, &mut errors[I_STATUS], |c| {
            let log = self.log_now();
            self.note_seq(I_STATUS, c.seq);
            self.write(I_STATUS, log, c.stamp_ns, &c)
        })?;
        for (i, sub) in [
            (I_HB_CONTROLLER, &subs.hb_controller),
            (I_HB_VEHICLE, &subs.hb_vehicle),
        ] {
            n += receive_all(sub, &mut errors[i], |h| {
                let log = self.log_now();
                self.note_seq(i, h.seq);
                // The vehicle's beacons carry the vehicle clock; the controller's do not.
                let publish = if h.vehicle_ns > 0 { h.vehicle_ns } else { log };
                self.write(i, log, publish, &h)
            })?;
        }
        self.receive_errors = errors;
        if n > 0 {
            self.writer.flush().map_err(|e| self.mcap_err(e))?;
        }
        Ok(())
    }

    fn finish(mut self) -> Result<RecordStats, RecordError> {
        let map = |v: &[u64]| {
            topic::ALL
                .iter()
                .zip(v)
                .map(|(t, n)| ((*t).to_owned(), *n))
                .collect::<BTreeMap<_, _>>()
        };
        let stats = RecordStats {
            path: self.path.clone(),
            messages: map(&self.count),
            seq_gaps: map(&self.gaps),
            receive_errors: map(&self.receive_errors),
            non_finite_states: self.non_finite,
            last_log_ns: self.last_log,
        };
        self.writer.finish().map_err(|e| self.mcap_err(e))?;
        let buffered = self.writer.into_inner();
        let io_err = |source| RecordError::Io {
            path: self.path.clone(),
            source,
        };
        let file = buffered.into_inner().map_err(|e| io_err(e.into_error()))?;
        file.sync_all().map_err(io_err)?;
        Ok(stats)
    }
}

// ---------------------------------------------------------------------------------------------
// Foxglove messages (field names as in Foxglove's schemas).

#[derive(Debug, Clone, Copy, Serialize)]
struct Time {
    sec: u32,
    nsec: u32,
}

impl Time {
    const ZERO: Self = Self { sec: 0, nsec: 0 };

    fn from_ns(ns: u64) -> Self {
        Self {
            sec: u32::try_from(ns / 1_000_000_000).unwrap_or(u32::MAX),
            nsec: (ns % 1_000_000_000) as u32,
        }
    }
}

#[derive(Debug, Clone, Copy, Serialize)]
struct Vec3 {
    x: f64,
    y: f64,
    z: f64,
}

#[derive(Debug, Clone, Copy, Serialize)]
struct Quat {
    x: f64,
    y: f64,
    z: f64,
    w: f64,
}

/// The rotation by `yaw` (rad) about +z.
fn yaw_quaternion(yaw: f64) -> Quat {
    let (s, c) = (0.5 * yaw).sin_cos();
    Quat {
        x: 0.0,
        y: 0.0,
        z: s,
        w: c,
    }
}

#[derive(Debug, Clone, Copy, Serialize)]
struct Pose {
    position: Vec3,
    orientation: Quat,
}

impl Pose {
    fn identity() -> Self {
        Self::planar(0.0, 0.0, 0.0, 0.0)
    }

    fn planar(x: f64, y: f64, z: f64, yaw: f64) -> Self {
        Self {
            position: Vec3 { x, y, z },
            orientation: yaw_quaternion(yaw),
        }
    }

    /// This pose moved by `(dx, dy, dz)` in its own frame.
    fn offset(self, dx: f64, dy: f64, dz: f64) -> Self {
        let q = self.orientation;
        let yaw = 2.0 * q.z.atan2(q.w);
        let (s, c) = yaw.sin_cos();
        Self {
            position: Vec3 {
                x: self.position.x + c * dx - s * dy,
                y: self.position.y + s * dx + c * dy,
                z: self.position.z + dz,
            },
            orientation: q,
        }
    }
}

#[derive(Debug, Clone, Copy, Serialize)]
struct Color {
    r: f64,
    g: f64,
    b: f64,
    a: f64,
}

impl Color {
    const fn rgba(r: f64, g: f64, b: f64, a: f64) -> Self {
        Self { r, g, b, a }
    }
}

#[derive(Debug, Clone, Copy, Serialize)]
struct Cube {
    pose: Pose,
    size: Vec3,
    color: Color,
}

#[derive(Debug, Clone, Serialize)]
struct Line {
    #[serde(rename = "type")]
    kind: u8,
    pose: Pose,
    thickness: f64,
    scale_invariant: bool,
    points: Vec<Vec3>,
    color: Color,
    colors: [Color; 0],
    indices: [u32; 0],
}

#[derive(Debug, Clone, Serialize)]
struct Text {
    pose: Pose,
    billboard: bool,
    font_size: f64,
    scale_invariant: bool,
    color: Color,
    text: &'static str,
}

#[derive(Debug, Clone, Serialize)]
struct KeyValue {
    key: &'static str,
    value: &'static str,
}

/// An empty primitive list (serialises as `[]`).
type None0 = [u8; 0];

#[derive(Debug, Serialize)]
struct Entity<'a> {
    timestamp: Time,
    frame_id: &'static str,
    id: &'static str,
    lifetime: Time,
    frame_locked: bool,
    metadata: Vec<KeyValue>,
    arrows: None0,
    cubes: Vec<Cube>,
    spheres: None0,
    cylinders: None0,
    lines: &'a [Line],
    triangles: None0,
    texts: Vec<Text>,
    models: None0,
}

#[derive(Debug, Serialize)]
struct SceneUpdate<'a> {
    deletions: None0,
    entities: Vec<Entity<'a>>,
}

#[derive(Debug, Serialize)]
struct PoseInFrame {
    timestamp: Time,
    frame_id: &'static str,
    pose: Pose,
}

fn vehicle_entity(
    id: &'static str,
    stamp: Time,
    pose: Pose,
    size: VehicleBox,
    color: Color,
) -> Entity<'static> {
    Entity {
        timestamp: stamp,
        frame_id: WORLD_FRAME,
        id,
        lifetime: Time::ZERO,
        frame_locked: false,
        metadata: vec![KeyValue {
            key: "vehicle",
            value: id,
        }],
        arrows: [],
        cubes: vec![Cube {
            pose: pose.offset(0.0, 0.0, 0.5 * size.height),
            size: Vec3 {
                x: size.length,
                y: size.width,
                z: size.height,
            },
            color,
        }],
        spheres: [],
        cylinders: [],
        lines: &[],
        triangles: [],
        texts: vec![Text {
            pose: pose.offset(0.0, 0.0, size.height + 0.6),
            billboard: true,
            font_size: 14.0,
            scale_invariant: true,
            color: Color::rgba(1.0, 1.0, 1.0, 1.0),
            text: id,
        }],
        models: [],
    }
}

// ---------------------------------------------------------------------------------------------
// JSON Schemas.

const DRAFT: &str = "https://json-schema.org/draft/2020-12/schema";

fn uint(description: &str) -> Value {
    json!({"type": "integer", "minimum": 0, "description": description})
}

fn float(description: &str) -> Value {
    json!({"type": ["number", "null"], "description": description})
}

fn floats(n: usize, description: &str) -> Value {
    json!({
        "type": "array",
        "items": {"type": ["number", "null"]},
        "minItems": n,
        "maxItems": n,
        "description": description,
    })
}

fn object(title: &str, description: &str, properties: Value) -> Value {
    let required: Vec<String> = properties
        .as_object()
        .map(|m| m.keys().cloned().collect())
        .unwrap_or_default();
    json!({
        "$schema": DRAFT,
        "title": title,
        "description": description,
        "type": "object",
        "properties": properties,
        "required": required,
    })
}

/// The JSON Schema of [`StateEstimate`] as recorded on `/state` (a non-finite number reads
/// `null`).
#[must_use]
pub fn state_schema() -> Value {
    object(
        "picopit.StateEstimate",
        "The state estimate of both vehicles (vehicle side, once per control period).",
        json!({
            "seq": uint("sequence number, +1 per estimate"),
            "stamp_ns": uint("vehicle clock when the states were measured (ns)"),
            "sent_ns": uint("vehicle clock when the estimate was published (ns)"),
            "wall_sent_ns": uint("CLOCK_MONOTONIC at publication (ns)"),
            "run_start_ns": uint("vehicle time the current run started (ns)"),
            "target": floats(8, "target [vx, vy, psi, r, p, phi, X, Y] (m/s, rad, rad/s, m)"),
            "bullet": floats(6, "bullet [X, Y, psi, vx, vy, r] (m, rad, m/s, rad/s)"),
            "target_input": floats(2, "target driver's input [steer (rad), brake torque (N m)]"),
            "bullet_applied": floats(2, "bullet command in force [steer (rad), torque (N m)]"),
            "flags": uint("bits: 1 safe stop, 2 contact, 4 finished"),
            "commands_applied": uint("commands the vehicle side has applied so far"),
        }),
    )
}

/// The JSON Schema of [`ActuatorCommand`] as recorded on `/command`.
#[must_use]
pub fn command_schema() -> Value {
    object(
        "picopit.ActuatorCommand",
        "The bullet command (controller, in answer to a state estimate).",
        json!({
            "seq": uint("sequence number"),
            "state_seq": uint("the estimate this command answers"),
            "stamp_ns": uint("vehicle time the command was computed for (ns)"),
            "valid_until_ns": uint("apply no later than this vehicle time (ns)"),
            "wall_state_received_ns": uint("CLOCK_MONOTONIC when the estimate arrived (ns)"),
            "wall_sent_ns": uint("CLOCK_MONOTONIC when the command left (ns)"),
            "steer": float("front steer angle (rad)"),
            "torque": float("rear-axle torque (N m; negative brakes)"),
            "mode": {"type": "integer", "enum": [0, 1, 2],
                     "description": "0 track, 1 fallback, 2 safe stop (other values read as safe stop)"},
            "_reserved": uint("reserved"),
        }),
    )
}

/// The JSON Schema of [`ControllerStatus`] as recorded on `/status`.
#[must_use]
pub fn status_schema() -> Value {
    object(
        "picopit.ControllerStatus",
        "The controller's status (published with every command).",
        json!({
            "seq": uint("sequence number"),
            "state_seq": uint("the state this status belongs to"),
            "stamp_ns": uint("vehicle time of the command (ns)"),
            "compensated_ns": uint("latency compensated: command time - measurement time (ns)"),
            "ctrl_ns": uint("control-step time, planning excluded (ns)"),
            "plan_ns": uint("planning time (ns; 0 when not planned)"),
            "deadline_misses": uint("deadline misses since start"),
            "fallbacks": uint("fallback commands since start"),
            "stale_states": uint("stale states since start"),
            "phase": {"type": "integer", "minimum": 0,
                      "description": "0 chasing, 1 pit, 2 stabilising, 3 done, 4 aborted"},
            "mpc_status": uint("MPC status: 0 not run, 1 converged, 2 RTI step, 3 iteration cap, 4 time budget, 5 QP failure"),
            "faults": uint("bits: 1 stale state, 2 deadline missed, 4 solver failure, 8 peer dead, 16 no state, 32 bad state"),
            "events": uint("bits: 1 entered stabilisation, 2 decision infeasible (abort)"),
            "_reserved": uint("unused"),
        }),
    )
}

/// The JSON Schema of [`Heartbeat`] as recorded on both heartbeat topics.
#[must_use]
pub fn heartbeat_schema() -> Value {
    object(
        "picopit.Heartbeat",
        "A liveness beacon (both sides, every period).",
        json!({
            "seq": uint("sequence number"),
            "wall_sent_ns": uint("CLOCK_MONOTONIC at publication (ns)"),
            "vehicle_ns": uint("vehicle clock at publication (ns; vehicle side only, 0 from the controller)"),
            "peer": {"type": "integer", "enum": [1, 2], "description": "1 controller, 2 vehicle"},
            "pid": uint("the sender's process id"),
        }),
    )
}

fn fx_object(properties: Value) -> Value {
    json!({"type": "object", "properties": properties})
}

fn fx_time(description: &str) -> Value {
    json!({
        "type": "object",
        "title": "time",
        "description": description,
        "properties": {"sec": {"type": "integer", "minimum": 0}, "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999}},
    })
}

fn fx_vec3(title: &str) -> Value {
    json!({
        "type": "object",
        "title": title,
        "properties": {"x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}},
    })
}

fn fx_pose() -> Value {
    json!({
        "type": "object",
        "title": "foxglove.Pose",
        "properties": {
            "position": fx_vec3("foxglove.Vector3"),
            "orientation": {
                "type": "object",
                "title": "foxglove.Quaternion",
                "properties": {"x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}, "w": {"type": "number"}},
            },
        },
    })
}

fn fx_color() -> Value {
    json!({
        "type": "object",
        "title": "foxglove.Color",
        "properties": {"r": {"type": "number"}, "g": {"type": "number"}, "b": {"type": "number"}, "a": {"type": "number"}},
    })
}

fn fx_array(items: Value) -> Value {
    json!({"type": "array", "items": items})
}

fn fx_titled(title: &str, mut v: Value) -> Value {
    v["title"] = json!(title);
    v
}

/// The JSON Schema of `foxglove.SceneUpdate` (Foxglove's field names and layout).
#[must_use]
pub fn scene_update_schema() -> Value {
    let num = json!({"type": "number"});
    let boolean = json!({"type": "boolean"});
    let points = fx_array(fx_vec3("foxglove.Point3"));
    let arrow = fx_titled(
        "foxglove.ArrowPrimitive",
        fx_object(json!({
            "pose": fx_pose(), "shaft_length": num, "shaft_diameter": num,
            "head_length": num, "head_diameter": num, "color": fx_color(),
        })),
    );
    let cube = fx_titled(
        "foxglove.CubePrimitive",
        fx_object(
            json!({"pose": fx_pose(), "size": fx_vec3("foxglove.Vector3"), "color": fx_color()}),
        ),
    );
    let sphere = fx_titled(
        "foxglove.SpherePrimitive",
        fx_object(
            json!({"pose": fx_pose(), "size": fx_vec3("foxglove.Vector3"), "color": fx_color()}),
        ),
    );
    let cylinder = fx_titled(
        "foxglove.CylinderPrimitive",
        fx_object(json!({
            "pose": fx_pose(), "size": fx_vec3("foxglove.Vector3"),
            "bottom_scale": num, "top_scale": num, "color": fx_color(),
        })),
    );
    let line = fx_titled(
        "foxglove.LinePrimitive",
        fx_object(json!({
            "type": {"type": "integer", "oneOf": [
                {"title": "LINE_STRIP", "const": 0},
                {"title": "LINE_LOOP", "const": 1},
                {"title": "LINE_LIST", "const": 2},
            ]},
            "pose": fx_pose(),
            "thickness": {"type": "number", "minimum": 0},
            "scale_invariant": boolean,
            "points": points,
            "color": fx_color(),
            "colors": fx_array(fx_color()),
            "indices": fx_array(json!({"type": "integer", "minimum": 0})),
        })),
    );
    let triangles = fx_titled(
        "foxglove.TriangleListPrimitive",
        fx_object(json!({
            "pose": fx_pose(), "points": points, "color": fx_color(),
            "colors": fx_array(fx_color()),
            "indices": fx_array(json!({"type": "integer", "minimum": 0})),
        })),
    );
    let text = fx_titled(
        "foxglove.TextPrimitive",
        fx_object(json!({
            "pose": fx_pose(), "billboard": boolean, "font_size": num,
            "scale_invariant": boolean, "color": fx_color(), "text": {"type": "string"},
        })),
    );
    let model = fx_titled(
        "foxglove.ModelPrimitive",
        fx_object(json!({
            "pose": fx_pose(), "scale": fx_vec3("foxglove.Vector3"), "color": fx_color(),
            "override_color": boolean, "url": {"type": "string"},
            "media_type": {"type": "string"},
            "data": {"type": "string", "contentEncoding": "base64"},
        })),
    );
    let key_value = fx_titled(
        "foxglove.KeyValuePair",
        fx_object(json!({"key": {"type": "string"}, "value": {"type": "string"}})),
    );
    let deletion = fx_titled(
        "foxglove.SceneEntityDeletion",
        fx_object(json!({
            "timestamp": fx_time("timestamp of the deletion"),
            "type": {"type": "integer", "oneOf": [
                {"title": "MATCHING_ID", "const": 0},
                {"title": "ALL", "const": 1},
            ]},
            "id": {"type": "string"},
        })),
    );
    let entity = fx_titled(
        "foxglove.SceneEntity",
        fx_object(json!({
            "timestamp": fx_time("timestamp of the entity"),
            "frame_id": {"type": "string"},
            "id": {"type": "string"},
            "lifetime": fx_time("how long the entity stays visible (0: until replaced or deleted)"),
            "frame_locked": boolean,
            "metadata": fx_array(key_value),
            "arrows": fx_array(arrow),
            "cubes": fx_array(cube),
            "spheres": fx_array(sphere),
            "cylinders": fx_array(cylinder),
            "lines": fx_array(line),
            "triangles": fx_array(triangles),
            "texts": fx_array(text),
            "models": fx_array(model),
        })),
    );
    json!({
        "$schema": DRAFT,
        "title": "foxglove.SceneUpdate",
        "description": "An update to the entities displayed in a 3D scene",
        "type": "object",
        "properties": {
            "deletions": fx_array(deletion),
            "entities": fx_array(entity),
        },
    })
}

/// The JSON Schema of `foxglove.PoseInFrame`.
#[must_use]
pub fn pose_in_frame_schema() -> Value {
    json!({
        "$schema": DRAFT,
        "title": "foxglove.PoseInFrame",
        "description": "A timestamped pose for an object or reference frame in 3D space",
        "type": "object",
        "properties": {
            "timestamp": fx_time("timestamp of the pose"),
            "frame_id": {"type": "string"},
            "pose": fx_pose(),
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn yaw_quaternion_round_trips() {
        for psi in [-3.0, -0.4, 0.0, 0.7, 3.1] {
            let q = yaw_quaternion(psi);
            assert!((2.0 * q.z.atan2(q.w) - psi).abs() < 1e-12);
            assert!((q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn pose_offset_moves_in_the_body_frame() {
        let p = Pose::planar(1.0, 2.0, 0.0, std::f64::consts::FRAC_PI_2).offset(1.0, 0.0, 0.5);
        assert!((p.position.x - 1.0).abs() < 1e-12);
        assert!((p.position.y - 3.0).abs() < 1e-12);
        assert!((p.position.z - 0.5).abs() < 1e-12);
    }

    /// The hand-written schemas name exactly the fields serde writes.
    #[test]
    fn payload_schemas_match_the_payloads() {
        fn keys(v: &Value) -> Vec<String> {
            let mut k: Vec<String> = v.as_object().unwrap().keys().cloned().collect();
            k.sort();
            k
        }
        for (schema, value) in [
            (
                state_schema(),
                serde_json::to_value(StateEstimate::default()),
            ),
            (
                command_schema(),
                serde_json::to_value(ActuatorCommand::default()),
            ),
            (
                status_schema(),
                serde_json::to_value(ControllerStatus::default()),
            ),
            (
                heartbeat_schema(),
                serde_json::to_value(Heartbeat::default()),
            ),
        ] {
            let value = value.unwrap();
            assert_eq!(
                keys(&schema["properties"]),
                keys(&value),
                "{}",
                schema["title"]
            );
            let mut required: Vec<String> =
                serde_json::from_value(schema["required"].clone()).unwrap();
            required.sort();
            assert_eq!(required, keys(&value));
        }
    }

    #[test]
    fn time_splits_nanoseconds() {
        let t = Time::from_ns(3_250_000_001);
        assert_eq!((t.sec, t.nsec), (3, 250_000_001));
    }
}
