//! The scenario schema of the PIT Scenario Dataset: one JSON object per line.
//!
//! A scenario fixes the road, the adhesion, the obstacles, both vehicles' initial states,
//! the target driver's behaviour, `T_max`, `ε_ψ` and the parameter set (see
//! `docs/scenarios.md` for the field table with units). Vehicles are placed in **Frenet
//! coordinates** of the road's reference line (station `s`, offset `d` positive to the
//! left, heading relative to the road at `s`) with body-frame velocities; obstacles are
//! world-frame [`Obstacle`]s (rectangles at constant velocity). SI units throughout.
//!
//! [`load_jsonl`] refuses a malformed file with a [`ScenarioError`] that names the line
//! and the field (`line 7: obstacles[2].body.width: …`); nothing here panics on user data.

pub use crate::driver::{
    DriverDef, TargetDriver, Trigger, LANE_KEEP_KD, LANE_KEEP_KPSI, LANE_KEEP_KR,
    LANE_KEEP_MAX_STEER, THROTTLE_GAIN,
};
use dynamics::params::ParamSet;
use dynamics::plant::VehicleInit;
use dynamics::road::{Obstacle, Road};
use dynamics::TargetState;
use serde::{Deserialize, Serialize};
use thiserror::Error;

mod jsonl;
mod road;

pub use jsonl::{load_jsonl, parse_jsonl};
pub use road::RoadDef;

/// Adhesion band boundaries: `low` below 0.4 (snow, ice, gravel), `mid` from 0.4 to below
/// 0.7 (wet asphalt), `high` from 0.7 (dry asphalt).
pub const MU_LOW_MID: f64 = 0.4;
pub const MU_MID_HIGH: f64 = 0.7;
/// Admissible adhesion (the plant accepts (0, 1.5]).
pub const MU_RANGE: (f64, f64) = (0.05, 1.2);
/// Most obstacles in one scenario.
pub const MAX_OBSTACLES: usize = 32;

/// A scenario file or line that cannot be used. `line` is 1-based.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum ScenarioError {
    /// The line is not JSON at all.
    #[error("line {line}: not valid JSON at column {column}: {message}")]
    Syntax {
        line: usize,
        column: usize,
        message: String,
    },
    /// A field is missing, unknown, of the wrong type or out of range.
    #[error("line {line}: {field}: {message}")]
    Field {
        line: usize,
        field: String,
        message: String,
    },
    /// Two scenarios share an id.
    #[error("line {line}: id: `{id}` repeats the scenario of line {first}")]
    DuplicateId {
        line: usize,
        id: String,
        first: usize,
    },
    /// The file could not be read.
    #[error("cannot read {path}: {message}")]
    Io { path: String, message: String },
    /// The file holds no scenario.
    #[error("{path}: no scenarios")]
    Empty { path: String },
    /// The parameter set a scenario names could not be loaded.
    #[error("params: {0}")]
    Params(String),
}

impl ScenarioError {
    pub(crate) fn field(line: usize, field: impl Into<String>, message: impl Into<String>) -> Self {
        Self::Field {
            line,
            field: field.into(),
            message: message.into(),
        }
    }

    /// The same error reported on another line.
    #[must_use]
    pub fn at_line(self, line: usize) -> Self {
        match self {
            Self::Syntax {
                column, message, ..
            } => Self::Syntax {
                line,
                column,
                message,
            },
            Self::Field { field, message, .. } => Self::Field {
                line,
                field,
                message,
            },
            other => other,
        }
    }
}

/// Road type of a scenario.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[serde(rename_all = "snake_case")]
pub enum Category {
    StraightUrban,
    StraightHighway,
    Curved,
}

impl Category {
    pub const ALL: [Category; 3] = [Self::StraightUrban, Self::StraightHighway, Self::Curved];

    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::StraightUrban => "straight_urban",
            Self::StraightHighway => "straight_highway",
            Self::Curved => "curved",
        }
    }

    #[must_use]
    pub fn is_straight(self) -> bool {
        !matches!(self, Self::Curved)
    }
}

/// Adhesion band of μ.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[serde(rename_all = "snake_case")]
pub enum Adhesion {
    Low,
    Mid,
    High,
}

impl Adhesion {
    /// The band `mu` falls in.
    #[must_use]
    pub fn of(mu: f64) -> Self {
        if mu < MU_LOW_MID {
            Self::Low
        } else if mu < MU_MID_HIGH {
            Self::Mid
        } else {
            Self::High
        }
    }

    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Low => "low",
            Self::Mid => "mid",
            Self::High => "high",
        }
    }
}

/// The built-in parameter set a scenario runs with.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[serde(rename_all = "snake_case")]
pub enum ParamSetName {
    FullSize,
    HalfScale,
}

impl ParamSetName {
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::FullSize => "full_size",
            Self::HalfScale => "half_scale",
        }
    }

    /// The parameter set.
    ///
    /// # Errors
    /// [`ScenarioError::Params`] if the built-in set does not load (never for a valid build).
    pub fn load(self) -> Result<ParamSet, ScenarioError> {
        ParamSet::builtin(self.name()).map_err(|e| ScenarioError::Params(e.to_string()))
    }
}

/// A vehicle's initial state in the road's Frenet frame (of its c.g.).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct FrenetState {
    /// Station along the reference line (m).
    pub s: f64,
    /// Lateral offset, positive to the left (m).
    pub d: f64,
    /// Heading relative to the road at `s` (rad).
    pub heading: f64,
    /// Body-frame longitudinal and lateral velocity (m/s) and yaw rate (rad/s).
    pub vx: f64,
    pub vy: f64,
    pub r: f64,
}

impl FrenetState {
    fn check(&self, line: usize, name: &str) -> Result<(), ScenarioError> {
        let f = |field: &str| format!("{name}.{field}");
        range(line, &f("s"), self.s, -10_000.0, 20_000.0)?;
        finite(line, &f("d"), self.d)?;
        range(line, &f("heading"), self.heading, -1.2, 1.2)?;
        range(line, &f("vx"), self.vx, 0.0, 60.0)?;
        range(line, &f("vy"), self.vy, -10.0, 10.0)?;
        range(line, &f("r"), self.r, -3.0, 3.0)
    }

    /// The world-frame initial condition on `road`.
    #[must_use]
    pub fn to_world(&self, road: &Road) -> VehicleInit {
        let pose = road.pose_at(self.s);
        let p = road.to_world(self.s, self.d);
        VehicleInit {
            x: p.x,
            y: p.y,
            yaw: pose.heading + self.heading,
            vx: self.vx,
            vy: self.vy,
            r: self.r,
        }
    }
}

/// What an obstacle stands for (informational; the physics only sees the rectangle).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[serde(rename_all = "snake_case")]
pub enum ObstacleRole {
    /// A vehicle in a lane ahead (moving on straights, stopped on curves).
    ForwardTraffic,
    /// An object on the shoulder: parked car, barrier segment, post.
    Roadside,
}

/// An obstacle of a scenario.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ScenarioObstacle {
    pub role: ObstacleRole,
    /// The rectangle at `t = 0` and its constant world velocity.
    pub body: Obstacle,
}

/// One scenario (one line of the dataset).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// Unique id.
    pub id: String,
    pub category: Category,
    /// Parameter set of both vehicles.
    pub params: ParamSetName,
    /// Id of the prior (row of `data/priors.csv`) it was sampled from.
    pub prior: String,
    /// Seed of the sampler for this scenario.
    pub seed: u64,
    pub road: RoadDef,
    /// Road adhesion (peak friction).
    pub mu: f64,
    /// Band of `mu`; must agree with it.
    pub adhesion: Adhesion,
    pub obstacles: Vec<ScenarioObstacle>,
    pub target: FrenetState,
    pub bullet: FrenetState,
    pub driver: DriverDef,
    /// Time limit of an episode (s).
    pub t_max: f64,
    /// Heading tolerance of the reversed-heading goal (rad).
    pub eps_psi: f64,
}

impl Scenario {
    /// One JSON line (no trailing newline); round-trips through [`Scenario::from_json_line`].
    ///
    /// # Panics
    /// Never: every field has a JSON representation (validated numbers are finite).
    #[must_use]
    pub fn to_json_line(&self) -> String {
        serde_json::to_string(self).expect("a scenario always serialises")
    }

    /// Check every value: finite numbers, ranges, consistency of category and road, of μ
    /// and its band, vehicles on the road.
    ///
    /// # Errors
    /// [`ScenarioError::Field`] naming the first bad field.
    pub fn validate(&self, line: usize) -> Result<(), ScenarioError> {
        if self.id.is_empty() || self.id.len() > 64 {
            return Err(ScenarioError::field(
                line,
                "id",
                "must have 1 to 64 characters",
            ));
        }
        if self.prior.len() > 64 {
            return Err(ScenarioError::field(
                line,
                "prior",
                "must have at most 64 characters",
            ));
        }
        self.road.check(line)?;
        match (self.category.is_straight(), self.road.radius) {
            (true, Some(_)) => {
                return Err(ScenarioError::field(
                    line,
                    "road.radius",
                    format!("a {} road has no radius", self.category.name()),
                ))
            }
            (false, None) => {
                return Err(ScenarioError::field(
                    line,
                    "road.radius",
                    "a curved road needs a radius",
                ))
            }
            _ => {}
        }
        range(line, "mu", self.mu, MU_RANGE.0, MU_RANGE.1)?;
        let band = Adhesion::of(self.mu);
        if band != self.adhesion {
            return Err(ScenarioError::field(
                line,
                "adhesion",
                format!(
                    "`{}` disagrees with mu = {} (band `{}`: low < {MU_LOW_MID} <= mid < {MU_MID_HIGH} <= high)",
                    self.adhesion.name(),
                    self.mu,
                    band.name()
                ),
            ));
        }
        if self.obstacles.len() > MAX_OBSTACLES {
            return Err(ScenarioError::field(
                line,
                "obstacles",
                format!(
                    "{} obstacles: at most {MAX_OBSTACLES}",
                    self.obstacles.len()
                ),
            ));
        }
        for (i, o) in self.obstacles.iter().enumerate() {
            o.body.validate().map_err(|e| match e {
                dynamics::RoadError::Invalid {
                    field,
                    value,
                    reason,
                } => ScenarioError::field(
                    line,
                    format!("obstacles[{i}].body.{field}"),
                    format!("{value}: {reason}"),
                ),
                other => {
                    ScenarioError::field(line, format!("obstacles[{i}].body"), other.to_string())
                }
            })?;
            for (name, v) in [("length", o.body.length), ("width", o.body.width)] {
                if v > 50.0 {
                    return Err(ScenarioError::field(
                        line,
                        format!("obstacles[{i}].body.{name}"),
                        format!("{v}: at most 50 m"),
                    ));
                }
            }
            let speed = o.body.vx.hypot(o.body.vy);
            if speed > 60.0 {
                return Err(ScenarioError::field(
                    line,
                    format!("obstacles[{i}].body.(vx, vy)"),
                    format!(
                        "({}, {}): speed {speed:.1} m/s; at most 60 m/s",
                        o.body.vx, o.body.vy
                    ),
                ));
            }
        }
        let hw = self.road.half_width();
        for (name, v) in [("target", &self.target), ("bullet", &self.bullet)] {
            v.check(line, name)?;
            if v.d.abs() >= hw {
                return Err(ScenarioError::field(
                    line,
                    format!("{name}.d"),
                    format!(
                        "{}: off the road (|d| must be below the half width {hw})",
                        v.d
                    ),
                ));
            }
        }
        self.driver.check(line, hw)?;
        self.check_obstacles_clear(line)?;
        range(line, "t_max", self.t_max, 1.0, 120.0)?;
        if !(self.eps_psi.is_finite()
            && self.eps_psi > 0.0
            && self.eps_psi <= std::f64::consts::FRAC_PI_2)
        {
            return Err(ScenarioError::field(
                line,
                "eps_psi",
                format!("{}: must lie in (0, π/2]", self.eps_psi),
            ));
        }
        Ok(())
    }

    /// No obstacle may overlap a vehicle at t = 0 (the episode would start in a collision,
    /// with no heading error or margin to report).
    fn check_obstacles_clear(&self, line: usize) -> Result<(), ScenarioError> {
        if self.obstacles.is_empty() {
            return Ok(());
        }
        let params = self.params.load()?;
        let road = self.build_road()?;
        for (name, v, p) in [
            ("target", &self.target, &params.target),
            ("bullet", &self.bullet, &params.bullet),
        ] {
            let w = v.to_world(&road);
            let pose = dynamics::geometry::Pose2 {
                p_in_world: dynamics::geometry::Vec2::new(w.x, w.y),
                yaw: w.yaw,
            };
            let fp =
                dynamics::geometry::Obb::vehicle_footprint(&pose, p.length, p.width, p.cg_to_front);
            for (i, o) in self.obstacles.iter().enumerate() {
                if dynamics::contact::obb_signed_distance(&fp, &o.body.footprint_at(0.0)) < 0.0 {
                    return Err(ScenarioError::field(
                        line,
                        format!("obstacles[{i}].body"),
                        format!("overlaps the {name} at t = 0"),
                    ));
                }
            }
        }
        Ok(())
    }

    /// The road.
    ///
    /// # Errors
    /// As [`RoadDef::build`].
    pub fn build_road(&self) -> Result<Road, ScenarioError> {
        self.road.build()
    }

    /// The obstacles as the plant takes them.
    #[must_use]
    pub fn obstacles(&self) -> Vec<Obstacle> {
        self.obstacles.iter().map(|o| o.body.clone()).collect()
    }

    /// Initial conditions `(bullet, target)` of the plant on `road` (this scenario's road).
    #[must_use]
    pub fn initial_states(&self, road: &Road) -> (VehicleInit, VehicleInit) {
        (self.bullet.to_world(road), self.target.to_world(road))
    }

    /// The target's initial state `[vx, vy, ψ, r, p, φ, X, Y]` (roll at rest).
    #[must_use]
    pub fn target_state(&self, road: &Road) -> TargetState {
        let t = self.target.to_world(road);
        TargetState::from([t.vx, t.vy, t.yaw, t.r, 0.0, 0.0, t.x, t.y])
    }

    /// The bullet's initial state `[X, Y, ψ, vx, vy, r]`.
    #[must_use]
    pub fn bullet_state(&self, road: &Road) -> [f64; 6] {
        let b = self.bullet.to_world(road);
        [b.x, b.y, b.yaw, b.vx, b.vy, b.r]
    }

    /// The target driver of this scenario for parameter set `params`.
    #[must_use]
    pub fn target_driver(&self, params: &ParamSet) -> TargetDriver {
        TargetDriver::new(self.driver, &params.target, self.target.s, self.target.vx)
    }
}

/// A finite value, else an error naming the line and the field.
pub(crate) fn finite(line: usize, field: &str, v: f64) -> Result<(), ScenarioError> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(ScenarioError::field(
            line,
            field,
            format!("{v}: must be finite"),
        ))
    }
}

/// A finite value in `[lo, hi]`, else an error naming the line and the field.
pub(crate) fn range(
    line: usize,
    field: &str,
    v: f64,
    lo: f64,
    hi: f64,
) -> Result<(), ScenarioError> {
    finite(line, field, v)?;
    if v < lo || v > hi {
        return Err(ScenarioError::field(
            line,
            field,
            format!("{v}: must lie in [{lo}, {hi}]"),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn adhesion_bands() {
        assert_eq!(Adhesion::of(0.2), Adhesion::Low);
        assert_eq!(Adhesion::of(0.4), Adhesion::Mid);
        assert_eq!(Adhesion::of(0.69), Adhesion::Mid);
        assert_eq!(Adhesion::of(0.7), Adhesion::High);
    }
}
