//! The high-fidelity two-vehicle plant: the truth that every controller and surrogate in
//! picopit is measured against (the stand-in for the paper's CarSim + FEA force library).
//!
//! Each vehicle is a multi-body model:
//! * planar chassis motion (the world-frame velocity of the total c.g. and the yaw rate);
//! * sprung-mass roll about a roll axis and pitch about the ground, on springs and dampers,
//!   coupled to the c.g. acceleration;
//! * load transfer to four wheels from the suspension moments plus the unsprung and
//!   roll-centre terms;
//! * four wheels with spin dynamics (drive torque through an open differential, Coulomb
//!   brake and rolling-resistance torque, an implicit update solved together with the
//!   chassis speed, so braking does not depend on the step and stays stable to standstill);
//! * Magic Formula tyres with combined slip, CommonRoad's tyre of the vehicle ([`crate::tyre`]);
//! * aerodynamic drag; actuators with limits, rate limits and first-order lags.
//!
//! The two bodies touch through the compliant contact of [`crate::contact`] between their
//! footprints; both also touch obstacles (static or moving rectangles, stiffer). The
//! integrator is semi-implicit (symplectic) Euler at a fixed step (1 kHz by default):
//! velocities first, then positions with the new velocities. Contact forces are applied in
//! the world frame as an equal and opposite pair at one point, so with tyre forces off the
//! total linear and angular momentum of the two vehicles are conserved to round-off.
//! Everything is deterministic: no clock, no randomness, no allocation per step.
//!
//! It shares no dynamics code with the control-oriented models ([`crate::bullet`],
//! [`crate::target4dof`]): they differ in tyres (axle curves at static load vs combined slip
//! with load transfer), wheel dynamics, roll/pitch, actuators and drag, so a surrogate always
//! faces model mismatch.
//!
//! The module by concept:
//! * this file: the public types (settings, initial conditions, reports, the vehicle state)
//!   and the plant's read-outs and conservation diagnostics;
//! * `chassis`: the constants of one vehicle derived from its parameters, and its driveline;
//! * `setup`: validation, construction, obstacles, adhesion and reset;
//! * `command`: the driver commands and idealised impulses;
//! * `contact`: footprints, the vehicle–vehicle and obstacle contact forces of a step and
//!   their running average;
//! * `step`: the time step, the semi-implicit Euler integration of one vehicle (loads,
//!   tyres, roll/pitch, wheel spin and driveline, actuators).

mod chassis;
mod command;
mod contact;
mod setup;
mod step;

use crate::contact::ContactLaw;
use crate::geometry::{cross, rotate, Pose2, Vec2};
use crate::road::Obstacle;
use crate::target::TargetState;
use chassis::Chassis;
use contact::ContactAccumulator;
use nalgebra::SVector;

/// Air density at 20 °C, sea level (kg/m³).
pub const AIR_DENSITY: f64 = 1.204;

/// Wheel ground speed (m/s) below which an ABS ([`crate::params::VehicleParams::abs_slip`])
/// lets the brakes lock (production systems switch off at walking pace, 5–10 km/h).
pub const ABS_MIN_SPEED: f64 = 2.0;

/// What the target's gearbox has engaged.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Gear {
    /// The forward gear of its powertrain ([`crate::params::PowertrainParams`]): engine
    /// braking, and a stall that holds the driven axle.
    #[default]
    Forward,
    /// Neutral: the wheels roll freely (rolling resistance and drag only), as a car coasting
    /// with the clutch down.
    Neutral,
}

/// Plant settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlantConfig {
    /// Integration step (s); 1e-3 (1 kHz) or finer.
    pub dt: f64,
    /// Road adhesion μ (peak lateral friction at nominal load).
    pub mu: f64,
    /// Tyre and aerodynamic forces on (normal use) or off (diagnostics: with them off only
    /// contact acts, and the conservation laws can be checked).
    pub tyre_forces: bool,
    /// The target's gear (the bullet is driven by wire and has none).
    pub target_gear: Gear,
}

impl Default for PlantConfig {
    fn default() -> Self {
        Self {
            dt: 1e-3,
            mu: 0.9,
            tyre_forces: true,
            target_gear: Gear::Forward,
        }
    }
}

/// Initial condition of one vehicle: pose of the c.g. and body-frame velocities.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct VehicleInit {
    pub x: f64,
    pub y: f64,
    pub yaw: f64,
    pub vx: f64,
    pub vy: f64,
    pub r: f64,
}

/// Which vehicle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Which {
    Bullet = 0,
    Target = 1,
}

/// The vehicle–vehicle contact of one step (or an average over several).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactReport {
    /// `[F_n, F_t]` on the target in the contact frame (N).
    pub fc: Vec2,
    /// World heading of the normal (bullet → target).
    pub gamma: f64,
    pub point_in_world: Vec2,
    /// Point of action in the target's body frame, relative to its c.g.
    pub point_in_target: Vec2,
    /// Point of action in the bullet's body frame, relative to its c.g.
    pub point_in_bullet: Vec2,
    /// Penetration depth (m).
    pub depth: f64,
}

/// A vehicle touching an obstacle in the last step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObstacleContact {
    pub obstacle: usize,
    /// Normal force (N).
    pub normal_force: f64,
}

/// The state of one plant vehicle. Public for logging; change it only through [`Plant`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct VehicleBody {
    /// Total c.g. in the world (m).
    pub pos: Vec2,
    /// Yaw ψ (rad, unwrapped).
    pub yaw: f64,
    /// World-frame velocity of the total c.g. (m/s).
    pub vel: Vec2,
    /// Yaw rate (rad/s).
    pub r: f64,
    /// Roll angle φ (positive: sprung c.g. moves left) and rate.
    pub phi: f64,
    pub p: f64,
    /// Pitch angle θ (positive: nose down, sprung c.g. moves forward) and rate.
    pub theta: f64,
    pub q: f64,
    /// Wheel spin rates FL, FR, RL, RR (rad/s).
    pub omega: [f64; 4],
    /// Actual road-wheel steer (rad), drive torque T_r (N m, motor side), brake torque (N m).
    pub steer: f64,
    pub torque: f64,
    pub brake: f64,
    /// Commands.
    pub cmd_steer: f64,
    pub cmd_torque: f64,
    pub cmd_brake: f64,
    /// Wheel loads of the last step (N).
    pub fz: [f64; 4],
    /// c.g. acceleration of the last step in the body frame (m/s²).
    pub acc_body: Vec2,
    /// The engine has stalled (a vehicle in gear; it stays stalled until reset).
    pub stalled: bool,
}

impl VehicleBody {
    /// Body-frame velocity of the c.g.
    #[inline]
    #[must_use]
    pub fn vel_body(&self) -> Vec2 {
        rotate(-self.yaw, self.vel)
    }

    /// Velocity of the material point at world position `p` (rigid planar motion).
    #[inline]
    #[must_use]
    pub fn point_velocity(&self, p: Vec2) -> Vec2 {
        let d = p - self.pos;
        self.vel + Vec2::new(-self.r * d.y, self.r * d.x)
    }

    /// Linear momentum (kg m/s) for mass `m`.
    #[must_use]
    pub fn momentum(&self, m: f64) -> Vec2 {
        self.vel * m
    }
}

/// The two-vehicle plant.
#[derive(Debug, Clone)]
pub struct Plant {
    config: PlantConfig,
    chassis: [Chassis; 2],
    bodies: [VehicleBody; 2],
    law: ContactLaw,
    obstacle_law: ContactLaw,
    obstacles: Vec<Obstacle>,
    time: f64,
    steps: u64,
    contact: Option<ContactReport>,
    obstacle_contacts: [Option<ObstacleContact>; 2],
    accum: ContactAccumulator,
}

impl Plant {
    #[must_use]
    pub fn obstacles(&self) -> &[Obstacle] {
        &self.obstacles
    }

    #[must_use]
    pub fn config(&self) -> &PlantConfig {
        &self.config
    }

    /// Simulated time (s).
    #[must_use]
    pub fn time(&self) -> f64 {
        self.time
    }

    #[must_use]
    pub fn dt(&self) -> f64 {
        self.config.dt
    }

    /// Full state of one vehicle.
    #[must_use]
    pub fn body(&self, which: Which) -> &VehicleBody {
        &self.bodies[which as usize]
    }

    /// Mass of one vehicle (kg).
    #[must_use]
    pub fn mass(&self, which: Which) -> f64 {
        self.chassis[which as usize].m
    }

    /// Bullet state `[X, Y, ψ, vx, vy, r]` of the c.g.
    #[must_use]
    pub fn bullet_state(&self) -> SVector<f64, 6> {
        let b = &self.bodies[0];
        let v = b.vel_body();
        SVector::<f64, 6>::new(b.pos.x, b.pos.y, b.yaw, v.x, v.y, b.r)
    }

    /// Target state `[vx, vy, ψ, r, p, φ, X, Y]`.
    #[must_use]
    pub fn target_state(&self) -> TargetState {
        let b = &self.bodies[1];
        let v = b.vel_body();
        TargetState::from([v.x, v.y, b.yaw, b.r, b.p, b.phi, b.pos.x, b.pos.y])
    }

    /// The vehicle–vehicle contact of the last step.
    #[must_use]
    pub fn contact(&self) -> Option<ContactReport> {
        self.contact
    }

    /// Obstacle contacts of the last step, per vehicle (bullet, target).
    #[must_use]
    pub fn obstacle_contacts(&self) -> [Option<ObstacleContact>; 2] {
        self.obstacle_contacts
    }

    /// The chassis pose (`world_from_body` of the static c.g., i.e. of the body rectangle).
    #[must_use]
    pub fn chassis_pose(&self, which: Which) -> Pose2 {
        let i = which as usize;
        let b = &self.bodies[i];
        Pose2 {
            p_in_world: b.pos - rotate(b.yaw, self.cg_offset(i)),
            yaw: b.yaw,
        }
    }

    /// Offset of the total c.g. from the chassis origin (body frame) due to roll and pitch.
    #[inline]
    fn cg_offset(&self, i: usize) -> Vec2 {
        self.chassis[i].cg_offset(&self.bodies[i])
    }

    /// Total linear momentum of the two vehicles (kg m/s).
    #[must_use]
    pub fn total_momentum(&self) -> Vec2 {
        self.bodies[0].momentum(self.chassis[0].m) + self.bodies[1].momentum(self.chassis[1].m)
    }

    /// Total angular momentum about the world origin (kg m²/s), planar part.
    #[must_use]
    pub fn total_angular_momentum(&self) -> f64 {
        (0..2)
            .map(|i| {
                let b = &self.bodies[i];
                let c = &self.chassis[i];
                b.r / c.inv_iz + c.m * cross(b.pos, b.vel)
            })
            .sum()
    }

    /// Kinetic energy of the planar motion (translation + yaw) of both vehicles (J).
    #[must_use]
    pub fn planar_kinetic_energy(&self) -> f64 {
        (0..2)
            .map(|i| {
                let b = &self.bodies[i];
                let c = &self.chassis[i];
                0.5 * c.m * b.vel.norm_squared() + 0.5 * b.r * b.r / c.inv_iz
            })
            .sum()
    }
}
