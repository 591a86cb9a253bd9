//! The JSON Schemas of the recording's own topics (`picopit.*`): the raw payloads as serde
//! writes them, and the plot-ready topics ([`super::plot`]). The Foxglove topics carry the
//! SDK's published schemas instead (`foxglove::Encode::get_schema`).
//!
//! A unit test checks that every schema names exactly the fields serde writes: **if you add a
//! field to a payload, add it here too.**

use serde_json::{json, Value};

const DRAFT: &str = "https://json-schema.org/draft/2020-12/schema";

pub(super) fn uint(description: &str) -> Value {
    json!({"type": "integer", "minimum": 0, "description": description})
}

/// A number that reads `null` when it was not finite.
pub(super) fn float(description: &str) -> Value {
    json!({"type": ["number", "null"], "description": description})
}

pub(super) fn floats(n: usize, description: &str) -> Value {
    json!({
        "type": "array",
        "items": {"type": ["number", "null"]},
        "minItems": n,
        "maxItems": n,
        "description": description,
    })
}

/// `{sec, nsec}` on the vehicle clock (Foxglove's time layout, so plots can use it).
pub(super) fn time(description: &str) -> Value {
    json!({
        "type": "object",
        "description": description,
        "properties": {
            "sec": {"type": "integer", "minimum": 0},
            "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999},
        },
        "required": ["sec", "nsec"],
        "additionalProperties": false,
    })
}

/// An object schema whose every property is required and no other is allowed.
pub(super) fn object(title: &str, description: &str, properties: Value) -> Value {
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
        "additionalProperties": false,
    })
}

/// The JSON Schema of [`crate::msg::StateEstimate`] as recorded on `/state` (a non-finite
/// number reads `null`).
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
            "contact_force": floats(2, "contact force on the target [F_n, F_t] (N, contact frame; 0 apart)"),
            "contact_gamma": float("world heading of the contact normal, bullet into target (rad)"),
            "contact_point": floats(2, "contact point in the target's body frame [x, y] (m)"),
            "flags": uint("bits: 1 safe stop, 2 contact, 4 finished, 8 restarted"),
            "commands_applied": uint("commands the vehicle side has applied so far"),
        }),
    )
}

/// The JSON Schema of [`crate::msg::ActuatorCommand`] as recorded on `/command`.
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

/// The JSON Schema of [`crate::msg::ControllerStatus`] as recorded on `/status`.
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
            "phase": uint("0 chasing, 1 pit, 2 stabilising, 3 done, 4 aborted"),
            "mpc_status": uint("MPC status: 0 not run, 1 converged, 2 RTI step, 3 iteration cap, 4 time budget, 5 QP failure"),
            "faults": uint("bits: 1 stale state, 2 deadline missed, 4 solver failure, 8 peer dead, 16 no state, 32 bad state"),
            "events": uint("bits: 1 entered stabilisation, 2 decision infeasible (abort)"),
            "_reserved": uint("unused"),
        }),
    )
}

/// The JSON Schema of [`crate::msg::Heartbeat`] as recorded on both heartbeat topics.
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

#[cfg(test)]
mod tests {
    use super::super::{plot, RoadLines};
    use super::*;
    use crate::msg::{ActuatorCommand, ControllerStatus, Heartbeat, StateEstimate};

    fn keys(v: &Value) -> Vec<String> {
        let mut k: Vec<String> = v.as_object().unwrap().keys().cloned().collect();
        k.sort();
        k
    }

    /// The hand-written schemas name exactly the fields serde writes, all required.
    #[test]
    fn schemas_name_exactly_the_fields_serde_writes() {
        let s = StateEstimate::default();
        let poses = ([0.0; 3], [0.0; 3]);
        for (schema, value) in [
            (state_schema(), serde_json::to_value(s)),
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
            (
                plot::bullet_schema(),
                serde_json::to_value(plot::bullet(&s, poses.0)),
            ),
            (
                plot::target_schema(),
                serde_json::to_value(plot::target(&s, poses.1)),
            ),
            (
                plot::contact_schema(),
                serde_json::to_value(plot::contact(&s)),
            ),
            (
                plot::road_schema(),
                serde_json::to_value(plot::road(&RoadLines::default())),
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
            assert_eq!(required, keys(&value), "{}", schema["title"]);
        }
    }
}
