//! The ideal-PIT bound: could *any* PIT succeed on a scenario?
//!
//! A physics ceiling for the closed-loop benchmark, independent of the controller. The target
//! runs alone on the plant under its driver (as in screening). At every candidate contact
//! time from the bullet's earliest arrival ([`crate::screen`]'s kinematic reach bound) on, on
//! either side, the target's rear quarter receives one instantaneous lateral shove — a
//! rigid-body impulse `J = m_T · Δv` ([`Plant::apply_impulse`]) at the PIT contact point
//! (`contact_back` behind the rear axle, on the body side, pointing inward) — and the plant
//! then runs on to `T_max` with the driver reacting to the "contact" as in an episode. The
//! scenario is *ideally feasible* if one shove ends in success by the benchmark's own test
//! ([`Monitor`]: reversed and at rest, or settled reversed at `T_max`; no boundary
//! violation or obstacle hit), the bullet itself ignored.
//!
//! The bound is optimistic about the bullet (it is anywhere, at once, and leaves nothing
//! behind to hit) and restrictive about the push (one impulse, no sustained push or
//! follow-up). It measures how much of the dataset a PIT can save at all.

use crate::outcome::{FailureCause, Monitor, Observation, Outcome, Status};
use crate::scenario::{Scenario, ScenarioError};
use crate::screen::{reach_time, target_alone, ScreenSettings};
use dynamics::geometry::{rotate, Vec2};
use dynamics::plant::{Plant, Which};
use serde::{Deserialize, Serialize};

/// What the oracle tries (serde with defaults).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct OracleSettings {
    /// Shoves as a velocity change of the target's c.g., `J / m_T` (m/s).
    pub shoves: Vec<f64>,
    /// Spacing of the candidate contact times (s).
    pub time_step: f64,
    /// Contact point behind the rear axle (m).
    pub contact_back: f64,
    /// The last candidate time is `T_max − min_remaining` (s).
    pub min_remaining: f64,
    /// Try every shove instead of stopping at the first success (to count them).
    pub exhaustive: bool,
    /// Sides to try: +1 the target's left (pushed right), −1 its right.
    pub sides: Vec<f64>,
    /// Only contact times within `[from, to]` (s), if given (still from the reach bound on).
    pub window: Option<[f64; 2]>,
    /// Screening settings for the bullet's reach bound.
    pub screen: ScreenSettings,
}

impl Default for OracleSettings {
    fn default() -> Self {
        Self {
            shoves: vec![0.5, 1.0, 1.5, 2.0],
            time_step: 0.25,
            contact_back: 0.3,
            min_remaining: 1.0,
            exhaustive: false,
            sides: vec![1.0, -1.0],
            window: None,
            screen: ScreenSettings::default(),
        }
    }
}

impl OracleSettings {
    /// # Errors
    /// [`ScenarioError::Field`] (line 0) naming the first bad setting.
    pub fn validate(&self) -> Result<(), ScenarioError> {
        let bad = |field: &str, message: String| {
            Err(ScenarioError::Field {
                line: 0,
                field: format!("oracle.{field}"),
                message,
            })
        };
        if self.shoves.is_empty() || self.shoves.iter().any(|v| !v.is_finite() || *v < 0.0) {
            return bad(
                "shoves",
                format!("{:?}: need at least one, each finite and ≥ 0", self.shoves),
            );
        }
        for (field, v) in [
            ("time_step", self.time_step),
            ("contact_back", self.contact_back),
            ("min_remaining", self.min_remaining),
        ] {
            if !v.is_finite() || v < 0.0 || (field == "time_step" && v == 0.0) {
                return bad(
                    field,
                    format!(
                        "{v}: must be finite and {}",
                        if field == "time_step" { "> 0" } else { "≥ 0" }
                    ),
                );
            }
        }
        if self.sides.is_empty() || self.sides.iter().any(|&v| v != 1.0 && v != -1.0) {
            return bad("sides", format!("{:?}: each must be +1 or −1", self.sides));
        }
        if let Some([from, to]) = self.window {
            if !(from.is_finite() && to.is_finite() && from <= to) {
                return bad(
                    "window",
                    format!("[{from}, {to}]: must be finite with from ≤ to"),
                );
            }
        }
        Ok(())
    }
}

/// The shove that worked.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
pub struct Shove {
    /// Contact time (s).
    pub time: f64,
    /// +1: on the target's left side (pushed to the right), −1: on its right.
    pub side: f64,
    /// `J / m_T` (m/s).
    pub dv: f64,
    /// When the test decided success (s).
    pub decided_at: f64,
    /// Whether it ended at rest (else settled reversed at `T_max`).
    pub at_rest: bool,
}

/// What the oracle found on one scenario.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct OracleReport {
    /// The earliest successful shove (`None`: no shove succeeds).
    pub feasible: Option<Shove>,
    /// Earliest time the bullet can be at the PIT pose (s).
    pub t_reach: f64,
    /// Number of shoves simulated.
    pub tried: usize,
    /// Number of them that succeeded (at most 1 unless `exhaustive`).
    pub successes: usize,
    /// When the target alone left the road or hit an obstacle, if it did by `T_max`.
    pub alone_fails_at: Option<f64>,
}

/// The target alone on the plant under its driver, judged by the benchmark's test.
#[derive(Clone)]
struct Alone {
    plant: Plant,
    driver: crate::scenario::TargetDriver,
    monitor: Monitor,
    road: dynamics::road::Road,
    first_contact: Option<f64>,
    steps_per: usize,
    k: usize,
}

const DT: f64 = 0.05;

impl Alone {
    /// One control period: driver command, plant steps, judge. The bullet is the target's
    /// twin for the judge (its footprint is the target's), so only the target is judged.
    fn period(&mut self) -> Status {
        let t = self.k as f64 * DT;
        let x = self.plant.target_state();
        let (steer, brake) = self.driver.command(t, self.first_contact, &x, &self.road);
        self.plant.set_target_command(steer, brake);
        let mut touched = false;
        for _ in 0..self.steps_per {
            self.plant.step();
            touched |= self.plant.obstacle_contacts()[1].is_some();
        }
        self.k += 1;
        let fp = self.plant.footprints()[1];
        self.monitor.observe(&Observation {
            time: self.k as f64 * DT,
            target: self.plant.target_state(),
            footprints: [fp, fp],
            vehicle_contact: false,
            closing_speed: 0.0,
            obstacle_contact: [touched, touched],
        })
    }

    fn time(&self) -> f64 {
        self.k as f64 * DT
    }

    /// Shove the rear quarter on `side` (+1 left, −1 right) inward by `dv · m_T`.
    fn shove(&mut self, side: f64, dv: f64, lr: f64, width: f64, back: f64) {
        let b = *self.plant.body(Which::Target);
        let at = b.pos + rotate(b.yaw, Vec2::new(-(lr + back), side * 0.5 * width));
        let j = rotate(
            b.yaw,
            Vec2::new(0.0, -side * dv * self.plant.mass(Which::Target)),
        );
        self.plant.apply_impulse(Which::Target, j, at);
        self.first_contact = Some(self.time());
    }
}

/// Run the ideal-PIT search on one scenario.
///
/// # Errors
/// [`ScenarioError`] if the scenario's road or parameter set cannot be built, or a setting
/// is bad ([`OracleSettings::validate`]).
pub fn ideal_pit(sc: &Scenario, settings: &OracleSettings) -> Result<OracleReport, ScenarioError> {
    settings.validate()?;
    let params = sc.params.load()?;
    let road = sc.build_road()?;
    let plant = target_alone(sc, &params, &road)?;
    let steps_per = (DT / plant.dt()).round().max(1.0) as usize;
    let mut base = Alone {
        plant,
        driver: sc.target_driver(&params),
        monitor: Monitor::for_scenario(sc)?,
        road: road.clone(),
        first_contact: None,
        steps_per,
        k: 0,
    };
    // The target alone: its stations (for the reach bound) and a snapshot at every
    // candidate time.
    let n = (sc.t_max / DT).ceil() as usize;
    let every = ((settings.time_step / DT).round() as usize).max(1);
    let mut stations = vec![sc.target.s];
    let mut snapshots = vec![base.clone()];
    let mut s_hint = sc.target.s;
    let mut alone_fails_at = None;
    for _ in 0..n {
        let status = base.period();
        let x = base.plant.target_state();
        let f = road.project_with_hint(Vec2::new(x[6], x[7]), s_hint);
        s_hint = f.s;
        stations.push(f.s);
        if let Status::Done(o) = status {
            if let Outcome::Failure {
                cause: FailureCause::BoundaryViolation | FailureCause::SecondaryCollision,
                time,
            } = o
            {
                alone_fails_at = Some(time);
            }
            break;
        }
        if base.k % every == 0 {
            snapshots.push(base.clone());
        }
    }
    let t_reach = reach_time(sc, &params, &stations, DT, &settings.screen);
    let t_last = sc.t_max - settings.min_remaining;
    let pt = &params.target;
    let mut tried = 0;
    let mut successes = 0;
    let mut feasible = None;
    for snap in &snapshots {
        let t = snap.time();
        if t + 1e-9 < t_reach || t > t_last + 1e-9 || snap.monitor.outcome().is_some() {
            continue;
        }
        if let Some([from, to]) = settings.window {
            if t + 1e-9 < from || t > to + 1e-9 {
                continue;
            }
        }
        for &dv in &settings.shoves {
            for &side in &settings.sides {
                tried += 1;
                let mut run = snap.clone();
                run.shove(side, dv, pt.lr, pt.width, settings.contact_back);
                let outcome = loop {
                    if let Status::Done(o) = run.period() {
                        break o;
                    }
                };
                if let Outcome::Success { time } = outcome {
                    successes += 1;
                    feasible.get_or_insert(Shove {
                        time: t,
                        side,
                        dv,
                        decided_at: time,
                        at_rest: run.monitor.metrics().at_rest,
                    });
                    if !settings.exhaustive {
                        return Ok(OracleReport {
                            feasible,
                            t_reach,
                            tried,
                            successes,
                            alone_fails_at,
                        });
                    }
                }
            }
        }
    }
    Ok(OracleReport {
        feasible,
        t_reach,
        tried,
        successes,
        alone_fails_at,
    })
}
