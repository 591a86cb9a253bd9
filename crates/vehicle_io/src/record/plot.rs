//! The plot-ready topics derived from each state: one JSON object per vehicle and one for the
//! contact, with named fields (SI units), so a plot panel takes `/bullet/state.speed` instead
//! of an index into `/state.bullet`. Times are the state's measurement time `stamp_ns`.

use super::scene::timestamp;
use super::schema::{float, floats, object, time};
use super::RoadLines;
use crate::msg::{StateEstimate, STATE_CONTACT};
use serde::Serialize;
use serde_json::{json, Value};

/// `{sec, nsec}` (serialises as Foxglove's time layout).
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Time {
    pub sec: u32,
    pub nsec: u32,
}

fn time_of(ns: u64) -> Time {
    let t = timestamp(ns);
    Time {
        sec: t.sec(),
        nsec: t.nsec(),
    }
}

/// `/bullet/state`.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct BulletPlot {
    pub timestamp: Time,
    pub x: f64,
    pub y: f64,
    pub yaw: f64,
    pub vx: f64,
    pub vy: f64,
    pub yaw_rate: f64,
    pub speed: f64,
    pub steer: f64,
    pub torque: f64,
}

/// `/target/state`.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct TargetPlot {
    pub timestamp: Time,
    pub x: f64,
    pub y: f64,
    pub yaw: f64,
    pub vx: f64,
    pub vy: f64,
    pub yaw_rate: f64,
    pub roll_rate: f64,
    pub roll: f64,
    pub speed: f64,
    pub steer: f64,
    pub brake_torque: f64,
}

/// `/contact`.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct ContactPlot {
    pub timestamp: Time,
    pub in_contact: bool,
    pub normal_force: f64,
    pub tangential_force: f64,
    pub force: f64,
    pub normal_heading: f64,
    pub point_x: f64,
    pub point_y: f64,
}

/// The bullet's named state; `pose` is `(x, y, ψ)` as drawn.
#[must_use]
pub fn bullet(s: &StateEstimate, [x, y, yaw]: [f64; 3]) -> BulletPlot {
    let [_, _, _, vx, vy, r] = s.bullet;
    BulletPlot {
        timestamp: time_of(s.stamp_ns),
        x,
        y,
        yaw,
        vx,
        vy,
        yaw_rate: r,
        speed: vx.hypot(vy),
        steer: s.bullet_applied[0],
        torque: s.bullet_applied[1],
    }
}

/// The target's named state; `pose` is `(x, y, ψ)` as drawn.
#[must_use]
pub fn target(s: &StateEstimate, [x, y, yaw]: [f64; 3]) -> TargetPlot {
    let [vx, vy, _, r, p, phi, _, _] = s.target;
    TargetPlot {
        timestamp: time_of(s.stamp_ns),
        x,
        y,
        yaw,
        vx,
        vy,
        yaw_rate: r,
        roll_rate: p,
        roll: phi,
        speed: vx.hypot(vy),
        steer: s.target_input[0],
        brake_torque: s.target_input[1],
    }
}

/// The contact of a state.
#[must_use]
pub fn contact(s: &StateEstimate) -> ContactPlot {
    let [fn_, ft] = s.contact_force;
    ContactPlot {
        timestamp: time_of(s.stamp_ns),
        in_contact: s.flags & STATE_CONTACT != 0,
        normal_force: fn_,
        tangential_force: ft,
        force: fn_.hypot(ft),
        normal_heading: s.contact_gamma,
        point_x: s.contact_point[0],
        point_y: s.contact_point[1],
    }
}

fn stamp() -> Value {
    time("vehicle clock when the state was measured")
}

/// The JSON Schema of `/bullet/state`.
#[must_use]
pub fn bullet_schema() -> Value {
    object(
        "picopit.BulletPlot",
        "The bullet's state with named fields (derived from /state).",
        json!({
            "timestamp": stamp(),
            "x": float("X (m)"),
            "y": float("Y (m)"),
            "yaw": float("heading psi (rad, unwrapped)"),
            "vx": float("longitudinal speed (m/s, body frame)"),
            "vy": float("lateral speed (m/s, body frame)"),
            "yaw_rate": float("yaw rate r (rad/s)"),
            "speed": float("speed over ground (m/s)"),
            "steer": float("front steer in force (rad)"),
            "torque": float("rear-axle torque in force (N m; negative brakes)"),
        }),
    )
}

/// The JSON Schema of `/target/state`.
#[must_use]
pub fn target_schema() -> Value {
    object(
        "picopit.TargetPlot",
        "The target's state with named fields (derived from /state).",
        json!({
            "timestamp": stamp(),
            "x": float("X (m)"),
            "y": float("Y (m)"),
            "yaw": float("heading psi (rad, unwrapped)"),
            "vx": float("longitudinal speed (m/s, body frame)"),
            "vy": float("lateral speed (m/s, body frame)"),
            "yaw_rate": float("yaw rate r (rad/s)"),
            "roll_rate": float("roll rate p (rad/s)"),
            "roll": float("roll angle phi (rad)"),
            "speed": float("speed over ground (m/s)"),
            "steer": float("the target driver's steer (rad)"),
            "brake_torque": float("the target driver's brake torque (N m)"),
        }),
    )
}

/// The JSON Schema of `/contact`.
#[must_use]
pub fn contact_schema() -> Value {
    object(
        "picopit.Contact",
        "The bullet-target contact (derived from /state; the force is the mean over the period before publication).",
        json!({
            "timestamp": stamp(),
            "in_contact": {"type": "boolean", "description": "the vehicles touch (state flag)"},
            "normal_force": float("F_n on the target (N)"),
            "tangential_force": float("F_t on the target (N)"),
            "force": float("|f_c| (N)"),
            "normal_heading": float("world heading gamma of the normal, bullet into target (rad)"),
            "point_x": float("contact point, target body x (m)"),
            "point_y": float("contact point, target body y (m)"),
        }),
    )
}

/// `/road`: the road's polylines `[[X, Y], …]` (m, frame `world`).
#[derive(Debug, Clone, Copy, Serialize)]
pub struct RoadPlot<'a> {
    pub left: &'a [[f64; 2]],
    pub right: &'a [[f64; 2]],
    pub centre: &'a [[f64; 2]],
}

/// The road message of `road`.
#[must_use]
pub fn road(road: &RoadLines) -> RoadPlot<'_> {
    RoadPlot {
        left: &road.left,
        right: &road.right,
        centre: &road.centre,
    }
}

/// The JSON Schema of `/road`.
#[must_use]
pub fn road_schema() -> Value {
    let line =
        |d: &str| json!({"type": "array", "items": floats(2, "[X, Y] (m)"), "description": d});
    object(
        "picopit.Road",
        "The road as polylines in frame world (written once, when the recording starts).",
        json!({
            "left": line("left edge"),
            "right": line("right edge"),
            "centre": line("reference (centre) line"),
        }),
    )
}
