//! The target's driver: its definition in a scenario ([`DriverDef`], [`Trigger`]) and its
//! law ([`TargetDriver`]): the lane keeper, the throttle that holds the initial speed until
//! the first contact, and each kind's reaction to the contact.

use crate::scenario::{range, ScenarioError};
use dynamics::params::VehicleParams;
use dynamics::road::Road;
use dynamics::TargetState;
use serde::{Deserialize, Serialize};

/// When a reaction starts.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Trigger {
    /// `delay` seconds after the start of the episode.
    Start,
    /// `delay` seconds after the first bullet–target contact.
    Contact,
}

/// The target driver. Before its reaction every driver but `none` keeps its lane (steer
/// toward the line `d = offset`, see [`TargetDriver`]); the reaction is:
/// * `none`: an incapacitated or fleeing driver off the controls, holding a fixed small steer;
/// * `lane_keep`: keeps steering for its lane throughout, also after being hit: in the
///   direction the car travels, so a car spun round and rolling backwards is steered by the
///   mirrored law, and not while it travels across the road (the law fades out between 60°
///   and 90° of heading error to the direction of travel; [`dynamics::driver::LaneKeeper`]);
/// * `brake`: from its onset brakes with `fraction` of the maximum brake torque (still
///   steering for the lane before the first contact, hands off after it);
/// * `counter_steer`: from `delay` after the first contact steers against the yaw rate,
///   `δ = −gain · r · σ(v_x)`, clamped to `max_steer` ([`counter_steer`]: σ turns the steer
///   round when the car rolls backwards, where the front wheels turn it the other way).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum DriverDef {
    None {
        /// Fixed road-wheel steer (rad).
        steer: f64,
    },
    LaneKeep {
        /// Lateral offset of the followed line (m).
        offset: f64,
        /// Gain multiplier of the lane-keeping law (1 = nominal).
        gain: f64,
    },
    Brake {
        offset: f64,
        gain: f64,
        trigger: Trigger,
        /// Reaction delay after the trigger (s).
        delay: f64,
        /// Share of the maximum brake torque (0–1].
        fraction: f64,
    },
    CounterSteer {
        offset: f64,
        gain: f64,
        /// Reaction delay after the first contact (s).
        delay: f64,
        /// Yaw-rate feedback gain (rad of steer per rad/s).
        steer_gain: f64,
        /// Largest counter-steer (rad).
        max_steer: f64,
    },
}

impl DriverDef {
    #[must_use]
    pub fn kind(&self) -> &'static str {
        match self {
            Self::None { .. } => "none",
            Self::LaneKeep { .. } => "lane_keep",
            Self::Brake { .. } => "brake",
            Self::CounterSteer { .. } => "counter_steer",
        }
    }

    pub(crate) fn check(&self, line: usize, half_width: f64) -> Result<(), ScenarioError> {
        let offset_gain = |offset: f64, gain: f64| -> Result<(), ScenarioError> {
            range(line, "driver.offset", offset, -half_width, half_width)?;
            range(line, "driver.gain", gain, 0.1, 5.0)
        };
        match *self {
            Self::None { steer } => range(line, "driver.steer", steer, -0.3, 0.3),
            Self::LaneKeep { offset, gain } => offset_gain(offset, gain),
            Self::Brake {
                offset,
                gain,
                delay,
                fraction,
                ..
            } => {
                offset_gain(offset, gain)?;
                range(line, "driver.delay", delay, 0.0, 120.0)?;
                if !(fraction.is_finite() && fraction > 0.0 && fraction <= 1.0) {
                    return Err(ScenarioError::field(
                        line,
                        "driver.fraction",
                        format!("{fraction}: must lie in (0, 1]"),
                    ));
                }
                Ok(())
            }
            Self::CounterSteer {
                offset,
                gain,
                delay,
                steer_gain,
                max_steer,
            } => {
                offset_gain(offset, gain)?;
                range(line, "driver.delay", delay, 0.0, 120.0)?;
                range(line, "driver.steer_gain", steer_gain, 0.0, 5.0)?;
                range(line, "driver.max_steer", max_steer, 0.0, 1.0)
            }
        }
    }
}

/// The target driver's command `(δ, T_b)` as a function of time, the first contact and the
/// target's state. Allocation-free; keeps the last Frenet station as the projection hint.
///
/// `T_b` is the driver's longitudinal torque at the wheels (the target models' input):
/// positive brakes, negative is the throttle at the driven axle. Every driver keeps its
/// initial speed with the throttle until the first contact (an out-of-control car is not
/// slowing down on its own) and lets go of it then, or when it starts braking:
/// `−T_b = T_ff + k m R_w (v₀ − v_x)`, clamped to the drive's range, with `T_ff` the wheel
/// torque that balances closed-throttle engine braking, rolling resistance and drag at `v₀`
/// and `k = 1 /s`. Without the throttle a car in gear is slowed by its engine (and stalls
/// once spun round); see `dynamics::params::PowertrainParams`.
///
/// Lane keeping, rolling forwards: `δ = L κ(s) + g (−k_d (d − offset) − k_ψ wrap(ψ − ψ_road)
/// − k_r (r − v κ))` with `L` the wheelbase, `k_d = 0.05 rad/m`, `k_ψ = 0.6`, `k_r = 0.1 s`,
/// scaled by the driver's gain `g` and clamped to `±0.15 rad` (a driver's corrections, not a
/// spin recovery); rolling backwards the same law about the reversed heading with the steer's
/// sign turned round; faded out as the heading error to the direction of travel grows from
/// 60° to 90° ([`dynamics::driver::LaneKeeper`]).
#[derive(Debug, Clone, Copy)]
pub struct TargetDriver {
    def: DriverDef,
    wheelbase: f64,
    brake_max: f64,
    s_hint: f64,
    /// The speed the throttle holds (m/s).
    v_ref: f64,
    /// Wheel torque that balances the resistances at `v_ref` (N m).
    hold_torque: f64,
    /// `k m R_w` of the speed loop (N m per m/s) and the drive's largest wheel torque (N m).
    hold_gain: f64,
    drive_max: f64,
}

/// Speed-loop bandwidth of the target driver's throttle (1/s).
pub const THROTTLE_GAIN: f64 = 1.0;

/// Lane-keeping gains (see [`TargetDriver`]; the law is [`dynamics::driver::LaneKeeper`]).
pub use dynamics::driver::{LANE_KEEP_KD, LANE_KEEP_KPSI, LANE_KEEP_KR, LANE_KEEP_MAX_STEER};

impl TargetDriver {
    /// The driver of `def` for vehicle `target`, starting at station `s0` with speed `v0`
    /// (which its throttle holds until the first contact).
    #[must_use]
    pub fn new(def: DriverDef, target: &VehicleParams, s0: f64, v0: f64) -> Self {
        Self {
            def,
            wheelbase: target.wheelbase(),
            brake_max: target.brake_torque_max,
            s_hint: s0,
            v_ref: v0,
            hold_torque: target.cruise_wheel_torque(v0),
            hold_gain: THROTTLE_GAIN * target.mass * target.wheel_radius,
            drive_max: target.drive_efficiency * target.gear_ratio * target.drive_torque_max,
        }
    }

    /// The throttle's wheel torque (≥ 0) that holds the initial speed at speed `vx`.
    fn throttle(&self, vx: f64) -> f64 {
        (self.hold_torque + self.hold_gain * (self.v_ref - vx)).clamp(0.0, self.drive_max)
    }

    #[must_use]
    pub fn def(&self) -> &DriverDef {
        &self.def
    }

    /// The lane-keeping steer toward the line `d = offset`.
    fn lane_keep(&mut self, offset: f64, gain: f64, x: &TargetState, road: &Road) -> f64 {
        let f = road.project_with_hint(dynamics::geometry::Vec2::new(x[6], x[7]), self.s_hint);
        self.s_hint = f.s;
        dynamics::driver::LaneKeeper {
            offset,
            gain,
            wheelbase: self.wheelbase,
        }
        .steer(x, &f)
    }

    /// `(δ, T_b)` at time `t` (s) given the time of the first bullet–target contact (if
    /// any) and the target state `[vx, vy, ψ, r, p, φ, X, Y]`.
    pub fn command(
        &mut self,
        t: f64,
        first_contact: Option<f64>,
        x: &TargetState,
        road: &Road,
    ) -> (f64, f64) {
        let since_contact = first_contact.map(|tc| t - tc);
        // Throttle until the first contact (negative T_b), unless braking.
        let drive = if first_contact.is_none() {
            -self.throttle(x[0])
        } else {
            0.0
        };
        match self.def {
            DriverDef::None { steer } => (steer, drive),
            DriverDef::LaneKeep { offset, gain } => (self.lane_keep(offset, gain, x, road), drive),
            DriverDef::Brake {
                offset,
                gain,
                trigger,
                delay,
                fraction,
            } => {
                let on = match trigger {
                    Trigger::Start => t >= delay,
                    Trigger::Contact => since_contact.is_some_and(|dt| dt >= delay),
                };
                let brake = if on { fraction * self.brake_max } else { drive };
                let steer = if since_contact.is_some() {
                    0.0
                } else {
                    self.lane_keep(offset, gain, x, road)
                };
                (steer, brake)
            }
            DriverDef::CounterSteer {
                offset,
                gain,
                delay,
                steer_gain,
                max_steer,
            } => match since_contact {
                Some(dt) if dt >= delay => (counter_steer(steer_gain, max_steer, x), 0.0),
                Some(_) => (0.0, 0.0),
                None => (self.lane_keep(offset, gain, x, road), drive),
            },
        }
    }
}

/// Below this body-frame speed (m/s) the counter-steer fades out and turns round with the
/// direction of travel ([`counter_steer`]).
pub const COUNTER_STEER_REVERSE_BLEND: f64 = dynamics::driver::REVERSE_BLEND;

/// The counter-steering driver's wheel angle: against the yaw rate `r`,
/// `δ = clamp(−gain · r · σ(v_x), ±max_steer)` with `σ = clamp(v_x / 0.5 m/s, −1, 1)`.
///
/// A steered front axle yaws a car rolling forwards towards the steer and one rolling
/// backwards away from it (the front wheels' slip angle `δ − (v_y + l_f r)/v_x` changes the
/// sign of the `δ` term's moment with `v_x`). A driver who steers to stop the rotation
/// therefore steers the other way once the spin has turned the car past 90° to its path;
/// the bare law `−gain · r` would steer into the spin there and keep it going. Near a
/// standstill the steer fades out.
#[must_use]
pub fn counter_steer(gain: f64, max_steer: f64, x: &TargetState) -> f64 {
    let sigma = (x[0] / COUNTER_STEER_REVERSE_BLEND).clamp(-1.0, 1.0);
    (-gain * x[3] * sigma).clamp(-max_steer, max_steer)
}
