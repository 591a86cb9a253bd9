//! The MCAP side of the recorder: the file, its schemas and channels, and one write per
//! message (JSON for the picopit topics, protobuf for the Foxglove ones).
//!
//! The writer is the `mcap` crate's, unchunked and flushed after every drain (crash safety),
//! with the payload's vehicle-clock time as `publish_time`. The Foxglove messages, their
//! encoding and their schemas come from the Foxglove SDK (`foxglove::Encode`).

use super::{
    plot, scene, schema, topic, RecordError, RecordMeta, RecordStats, Subs, METADATA_NAME,
    ROAD_PERIOD_NS,
};
use crate::msg::StateEstimate;
use crate::ports::{monotonic_ns, ServiceNames};
use foxglove::messages::{FrameTransforms, LinePrimitive, PoseInFrame, SceneUpdate};
use foxglove::Encode;
use mcap::records::{MessageHeader, Metadata};
use serde::Serialize;
use serde_json::Value;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

type McapWriter = mcap::Writer<BufWriter<File>>;

const I_STATE: usize = 0;
const I_COMMAND: usize = 1;
const I_STATUS: usize = 2;
const I_HB_CONTROLLER: usize = 3;
const I_HB_VEHICLE: usize = 4;
const I_SCENE: usize = 5;
const I_TF: usize = 6;
const I_BULLET_POSE: usize = 7;
const I_TARGET_POSE: usize = 8;
const I_BULLET_STATE: usize = 9;
const I_TARGET_STATE: usize = 10;
const I_CONTACT: usize = 11;
const I_ROAD: usize = 12;
const N_TOPICS: usize = topic::ALL.len();
const N_RAW: usize = topic::RAW.len();

/// A schema to register: name, encoding, data.
struct SchemaDef {
    name: String,
    encoding: String,
    data: Vec<u8>,
}

fn json_schema(doc: &Value) -> SchemaDef {
    SchemaDef {
        name: doc["title"].as_str().unwrap_or_default().to_owned(),
        encoding: "jsonschema".to_owned(),
        data: serde_json::to_vec_pretty(doc).expect("a JSON value always serialises"),
    }
}

/// The SDK's published schema of a Foxglove message type.
fn foxglove_schema<T: Encode>() -> SchemaDef {
    let s = T::get_schema().expect("every Foxglove message type has a schema");
    SchemaDef {
        name: s.name,
        encoding: s.encoding,
        data: s.data.into_owned(),
    }
}

/// Every topic's schema and message encoding, in [`topic::ALL`] order.
fn schemas() -> [(SchemaDef, String); N_TOPICS] {
    let json = |doc: Value| (json_schema(&doc), "json".to_owned());
    fn fox<T: Encode>() -> (SchemaDef, String) {
        (foxglove_schema::<T>(), T::get_message_encoding())
    }
    [
        json(schema::state_schema()),
        json(schema::command_schema()),
        json(schema::status_schema()),
        json(schema::heartbeat_schema()),
        json(schema::heartbeat_schema()),
        fox::<SceneUpdate>(),
        fox::<FrameTransforms>(),
        fox::<PoseInFrame>(),
        fox::<PoseInFrame>(),
        json(plot::bullet_schema()),
        json(plot::target_schema()),
        json(plot::contact_schema()),
        json(plot::road_schema()),
    ]
}

/// The MCAP side: writer, channels, counters.
pub(super) struct Sink {
    path: PathBuf,
    writer: McapWriter,
    channel: [u16; N_TOPICS],
    count: [u64; N_TOPICS],
    last_seq: [Option<u64>; N_RAW],
    gaps: [u64; N_RAW],
    receive_errors: [u64; N_RAW],
    non_finite: u64,
    t0: u64,
    last_log: u64,
    last_road_log: Option<u64>,
    buf: Vec<u8>,
    meta: RecordMeta,
    road: Option<Vec<LinePrimitive>>,
}

impl Sink {
    pub(super) fn create(
        path: &Path,
        names: &ServiceNames,
        meta: &RecordMeta,
    ) -> Result<Self, RecordError> {
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

        let service_of = [
            &names.state,
            &names.command,
            &names.status,
            &names.heartbeat_controller,
            &names.heartbeat_vehicle,
        ];
        let mut schema_ids: BTreeMap<String, u16> = BTreeMap::new();
        let mut channel = [0u16; N_TOPICS];
        for (i, (def, encoding)) in schemas().into_iter().enumerate() {
            let schema_id = match schema_ids.get(&def.name) {
                Some(&id) => id,
                None => {
                    let id = writer
                        .add_schema(&def.name, &def.encoding, &def.data)
                        .map_err(mcap_err)?;
                    schema_ids.insert(def.name.clone(), id);
                    id
                }
            };
            let mut md = BTreeMap::new();
            match service_of.get(i) {
                Some(service) => md.insert("iceoryx2_service".to_owned(), (*service).clone()),
                None => md.insert("derived_from".to_owned(), topic::STATE.to_owned()),
            };
            channel[i] = writer
                .add_channel(schema_id, topic::ALL[i], &encoding, &md)
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
        put("recorder.obstacles", meta.obstacles.len().to_string());
        for (i, service) in service_of.iter().enumerate() {
            put(
                &format!("service{}", topic::ALL[i].replace('/', ".")),
                (*service).clone(),
            );
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

        let mut sink = Self {
            path: path.to_path_buf(),
            writer,
            channel,
            count: [0; N_TOPICS],
            last_seq: [None; N_RAW],
            gaps: [0; N_RAW],
            receive_errors: [0; N_RAW],
            non_finite: 0,
            t0,
            last_log: 0,
            last_road_log: None,
            buf: Vec::with_capacity(16 * 1024),
            road: scene::road_lines(meta),
            meta: meta.clone(),
        };
        if let Some(road) = &meta.road {
            sink.write_json(I_ROAD, 0, 0, &plot::road(road))?;
        }
        sink.writer.flush().map_err(|e| sink.mcap_err(e))?;
        Ok(sink)
    }

    fn mcap_err(&self, source: mcap::McapError) -> RecordError {
        RecordError::Mcap {
            path: self.path.clone(),
            source,
        }
    }

    fn encode_err(&self, i: usize, reason: String) -> RecordError {
        RecordError::Encode {
            path: self.path.clone(),
            topic: topic::ALL[i],
            reason,
        }
    }

    /// Now on the recording's clock (ns since its start; never decreasing).
    fn log_now(&mut self) -> u64 {
        let t = monotonic_ns().saturating_sub(self.t0).max(self.last_log);
        self.last_log = t;
        t
    }

    /// Write the encoded message in `self.buf` on topic `i`.
    fn write_buf(&mut self, i: usize, log_time: u64, publish_time: u64) -> Result<(), RecordError> {
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

    /// Encode `value` as JSON and write it on topic `i`.
    fn write_json<T: Serialize>(
        &mut self,
        i: usize,
        log_time: u64,
        publish_time: u64,
        value: &T,
    ) -> Result<(), RecordError> {
        self.buf.clear();
        serde_json::to_writer(&mut self.buf, value)
            .map_err(|e| self.encode_err(i, e.to_string()))?;
        self.write_buf(i, log_time, publish_time)
    }

    /// Encode a Foxglove message with the SDK (protobuf) and write it on topic `i`.
    fn write_foxglove<T: Encode>(
        &mut self,
        i: usize,
        log_time: u64,
        publish_time: u64,
        msg: &T,
    ) -> Result<(), RecordError> {
        self.buf.clear();
        msg.encode(&mut self.buf)
            .map_err(|e| self.encode_err(i, e.to_string()))?;
        self.write_buf(i, log_time, publish_time)
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
        self.write_json(I_STATE, log, s.sent_ns, s)?;
        let Some(poses) = scene::vehicle_poses(s) else {
            self.non_finite += 1;
            return Ok(());
        };
        let road_due = match self.last_road_log {
            None => true,
            Some(t) => log.saturating_sub(t) >= ROAD_PERIOD_NS,
        };
        let road = self.road.as_deref().filter(|_| road_due);
        let with_road = road.is_some();
        let update = scene::scene_update(s, poses, &self.meta, road);
        self.write_foxglove(I_SCENE, log, s.stamp_ns, &update)?;
        if with_road {
            self.last_road_log = Some(log);
        }
        let stamp = s.stamp_ns;
        self.write_foxglove(I_TF, log, stamp, &scene::frame_transforms(s, poses))?;
        self.write_foxglove(I_BULLET_POSE, log, stamp, &scene::pose_in_frame(s, poses.0))?;
        self.write_foxglove(I_TARGET_POSE, log, stamp, &scene::pose_in_frame(s, poses.1))?;
        self.write_json(I_BULLET_STATE, log, stamp, &plot::bullet(s, poses.0))?;
        self.write_json(I_TARGET_STATE, log, stamp, &plot::target(s, poses.1))?;
        self.write_json(I_CONTACT, log, stamp, &plot::contact(s))
    }

    /// Drain every subscriber once; flush when something was written.
    pub(super) fn drain_and_flush(&mut self, subs: &Subs) -> Result<(), RecordError> {
        let mut errors = self.receive_errors;
        let mut n = 0;
        n += super::receive_all(&subs.state, &mut errors[I_STATE], |s| self.on_state(&s))?;
        n += super::receive_all(&subs.command, &mut errors[I_COMMAND], |c| {
            let log = self.log_now();
            self.note_seq(I_COMMAND, c.seq);
            self.write_json(I_COMMAND, log, c.stamp_ns, &c)
        })?;
        n += super::receive_all(&subs.status, &mut errors[I_STATUS], |c| {
            let log = self.log_now();
            self.note_seq(I_STATUS, c.seq);
            self.write_json(I_STATUS, log, c.stamp_ns, &c)
        })?;
        for (i, sub) in [
            (I_HB_CONTROLLER, &subs.hb_controller),
            (I_HB_VEHICLE, &subs.hb_vehicle),
        ] {
            n += super::receive_all(sub, &mut errors[i], |h| {
                let log = self.log_now();
                self.note_seq(i, h.seq);
                // The vehicle's beacons carry the vehicle clock; the controller's do not.
                let publish = if h.vehicle_ns > 0 { h.vehicle_ns } else { log };
                self.write_json(i, log, publish, &h)
            })?;
        }
        self.receive_errors = errors;
        if n > 0 {
            self.writer.flush().map_err(|e| self.mcap_err(e))?;
        }
        Ok(())
    }

    pub(super) fn finish(mut self) -> Result<RecordStats, RecordError> {
        let map = |names: &[&str], v: &[u64]| {
            names
                .iter()
                .zip(v)
                .map(|(t, n)| ((*t).to_owned(), *n))
                .collect::<BTreeMap<_, _>>()
        };
        let stats = RecordStats {
            path: self.path.clone(),
            messages: map(&topic::ALL, &self.count),
            seq_gaps: map(&topic::RAW, &self.gaps),
            receive_errors: map(&topic::RAW, &self.receive_errors),
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
