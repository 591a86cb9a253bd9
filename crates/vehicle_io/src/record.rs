//! MCAP recording of every publish-subscribe service, on a thread of its own.
//!
//! A [`Recorder`] owns a thread with its own iceoryx2 node and one subscriber per
//! publish-subscribe service (state, command, status, both heartbeats). Every
//! [`POLL_PERIOD`] it drains all pending samples and writes each into an MCAP file, so the
//! real-time loop of the process never waits for, or allocates for, the log. The recorder
//! allocates freely (encoding).
//!
//! # Topics
//!
//! | topic                   | schema                     | encoding | from               |
//! |-------------------------|----------------------------|----------|--------------------|
//! | `/state`                | `picopit.StateEstimate`    | JSON     | `<prefix>/state`   |
//! | `/command`              | `picopit.ActuatorCommand`  | JSON     | `<prefix>/command` |
//! | `/status`               | `picopit.ControllerStatus` | JSON     | `<prefix>/status`  |
//! | `/heartbeat/controller` | `picopit.Heartbeat`        | JSON     | `<prefix>/heartbeat/controller` |
//! | `/heartbeat/vehicle`    | `picopit.Heartbeat`        | JSON     | `<prefix>/heartbeat/vehicle`    |
//! | `/scene`                | `foxglove.SceneUpdate`     | protobuf | each state         |
//! | `/tf`                   | `foxglove.FrameTransforms` | protobuf | each state         |
//! | `/bullet/pose`          | `foxglove.PoseInFrame`     | protobuf | each state         |
//! | `/target/pose`          | `foxglove.PoseInFrame`     | protobuf | each state         |
//! | `/bullet/state`         | `picopit.BulletPlot`       | JSON     | each state         |
//! | `/target/state`         | `picopit.TargetPlot`       | JSON     | each state         |
//! | `/contact`              | `picopit.Contact`          | JSON     | each state         |
//! | `/road`                 | `picopit.Road`             | JSON     | once, at the start |
//!
//! The raw topics hold the payload as serde writes it (a non-finite number reads `null`), with
//! the JSON Schemas of [`schema`]. The `foxglove.*` topics are the Foxglove SDK's own message
//! types with the SDK's published protobuf schemas ([`scene`]); the plot topics carry named
//! fields ([`plot`]). `/scene` holds one entity per vehicle (a cube of its size and a label),
//! `contact` (the contact force as an arrow, empty apart), one per obstacle, and, with the first
//! scene and then every [`ROAD_PERIOD_NS`], `road` (the road's polylines, never expiring).
//!
//! # Times
//!
//! `log_time` is the recorder's `CLOCK_MONOTONIC` receive time minus the recording's start
//! (monotonic, ns); `publish_time` is the payload's own vehicle-clock time: the state's
//! `sent_ns`, the command's and status's `stamp_ns`, and for the derived topics the state's
//! `stamp_ns` (when the pose was measured; also their `timestamp`), and a heartbeat's
//! `vehicle_ns` when it has one (the vehicle side's); otherwise (the controller's heartbeats)
//! `publish_time` is the `log_time`.
//!
//! # Crash safety
//!
//! The file is written without chunks and flushed to the kernel after every drain that wrote
//! something: a process killed with SIGKILL leaves a file that a streaming reader reads up to
//! the last flushed message (it lacks only the summary and footer). [`Recorder::stop`] (or
//! dropping the recorder) drains a last time, writes summary and footer, and syncs the file.

mod plot;
pub mod scene;
pub mod schema;
mod sink;

use crate::msg::{ActuatorCommand, ControllerStatus, Heartbeat, StateEstimate};
use crate::ports::{self, PortError, ServiceNames, Svc};
use dynamics::road::Obstacle;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::ZeroCopySend;
use sink::Sink;
use std::collections::BTreeMap;
use std::fmt::Debug;
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
    pub const TF: &str = "/tf";
    pub const BULLET_POSE: &str = "/bullet/pose";
    pub const TARGET_POSE: &str = "/target/pose";
    pub const BULLET_STATE: &str = "/bullet/state";
    pub const TARGET_STATE: &str = "/target/state";
    pub const CONTACT: &str = "/contact";
    /// The road's polylines, once, when the recording starts (when the recorder has a road).
    pub const ROAD: &str = "/road";
    /// The raw topics (one per iceoryx2 publish-subscribe service).
    pub const RAW: [&str; 5] = [
        STATE,
        COMMAND,
        STATUS,
        HEARTBEAT_CONTROLLER,
        HEARTBEAT_VEHICLE,
    ];
    /// Every topic: the raw ones, the derived ones (one message each per finite state), and
    /// [`ROAD`].
    pub const ALL: [&str; 13] = [
        STATE,
        COMMAND,
        STATUS,
        HEARTBEAT_CONTROLLER,
        HEARTBEAT_VEHICLE,
        SCENE,
        TF,
        BULLET_POSE,
        TARGET_POSE,
        BULLET_STATE,
        TARGET_STATE,
        CONTACT,
        ROAD,
    ];
}

/// A vehicle's box for the scene (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VehicleBox {
    pub length: f64,
    pub width: f64,
    pub height: f64,
    /// From the c.g. forward to the front bumper (the box is centred on the footprint).
    pub cg_to_front: f64,
}

impl Default for VehicleBox {
    /// A full-size sedan.
    fn default() -> Self {
        Self {
            length: 4.8,
            width: 1.85,
            height: 1.45,
            cg_to_front: 2.4,
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
#[derive(Debug, Clone, PartialEq)]
pub struct RecordMeta {
    pub bullet: VehicleBox,
    pub target: VehicleBox,
    /// Drawn on `/scene` when given.
    pub road: Option<RoadLines>,
    /// Drawn on `/scene` as boxes [`scene::OBSTACLE_HEIGHT`] tall, moving with their velocity
    /// (scenario time: `stamp_ns − run_start_ns`).
    pub obstacles: Vec<Obstacle>,
    /// Length of the contact-force arrow per newton (m/N; [`RecordMeta::new`]: 1 m per 10 kN).
    pub contact_arrow_scale: f64,
    /// Free-form key/values (command line, scenario id, git commit, …) for the Metadata record
    /// [`METADATA_NAME`]; they override the recorder's own keys of the same name.
    pub metadata: BTreeMap<String, String>,
}

impl Default for RecordMeta {
    /// Two full-size sedans, no road, no obstacles, no metadata.
    fn default() -> Self {
        Self::new(VehicleBox::default(), VehicleBox::default())
    }
}

impl RecordMeta {
    /// The vehicles' boxes, no road, no obstacles, no metadata.
    #[must_use]
    pub fn new(bullet: VehicleBox, target: VehicleBox) -> Self {
        Self {
            bullet,
            target,
            road: None,
            obstacles: Vec::new(),
            contact_arrow_scale: 1e-4,
            metadata: BTreeMap::new(),
        }
    }

    /// With the road's polylines.
    #[must_use]
    pub fn with_road(mut self, road: RoadLines) -> Self {
        self.road = Some(road);
        self
    }

    /// With the scenario's obstacles.
    #[must_use]
    pub fn with_obstacles(mut self, obstacles: Vec<Obstacle>) -> Self {
        self.obstacles = obstacles;
        self
    }

    /// With the contact-force arrow's length per newton (m/N).
    #[must_use]
    pub fn with_contact_arrow_scale(mut self, metres_per_newton: f64) -> Self {
        self.contact_arrow_scale = metres_per_newton;
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
