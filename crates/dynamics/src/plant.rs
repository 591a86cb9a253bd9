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

use crate::contact::{obb_contact, ContactGeometry, ContactLaw};
use crate::error::ParamError;
use crate::geometry::{cross, rotate, Obb, Pose2, Vec2};
use crate::params::{ParamSet, TyreParams, VehicleParams};
use crate::road::Obstacle;
use crate::target::TargetState;
use crate::tyre::{combined_slip4, tan_slip, V_LOW};
use crate::GRAVITY;
use nalgebra::SVector;

/// Air density at 20 °C, sea level (kg/m³).
pub const AIR_DENSITY: f64 = 1.204;

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

impl PlantConfig {
    pub fn validate(&self) -> Result<(), ParamError> {
        let bad = |field: &str, value: f64, reason: &'static str| {
            Err(ParamError::Invalid {
                field: format!("plant.{field}"),
                value,
                reason,
            })
        };
        if !(self.dt.is_finite() && self.dt > 0.0 && self.dt <= 1e-3) {
            return bad("dt", self.dt, "must lie in (0, 1e-3] s (1 kHz or finer)");
        }
        if !(self.mu.is_finite() && self.mu > 0.0 && self.mu <= 1.5) {
            return bad("mu", self.mu, "must lie in (0, 1.5]");
        }
        Ok(())
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

/// Constants of one vehicle, derived once from its parameters.
#[derive(Debug, Clone)]
struct Chassis {
    inv_m: f64,
    m: f64,
    ms: f64,
    inv_iz: f64,
    h_roll: f64,
    h_pitch: f64,
    roll_inertia: f64,
    pitch_inertia: f64,
    k_roll: [f64; 2],
    c_roll: [f64; 2],
    k_pitch: f64,
    c_pitch: f64,
    track: [f64; 2],
    wheelbase: f64,
    /// Wheel positions relative to the chassis origin (static c.g.): FL, FR, RL, RR.
    wheel_pos: [Vec2; 4],
    fz_static: [f64; 4],
    /// Lateral load transfer per axle per unit a_y (unsprung + roll-centre terms), N/(m/s²).
    lat_transfer: [f64; 2],
    /// Longitudinal load transfer of the unsprung masses per unit a_x, N/(m/s²).
    long_transfer: f64,
    h_bumper_roll: f64,
    h_bumper: f64,
    rw: f64,
    iw: f64,
    drive_gain: f64,
    brake_share: [f64; 4],
    steer_max: f64,
    steer_rate_max: f64,
    /// Exact first-order-lag factors `1 − exp(−dt/τ)` for steer and torques.
    steer_lag: f64,
    torque_limits: (f64, f64),
    torque_lag: f64,
    brake_max: f64,
    rolling_resistance: f64,
    drag: f64,
    length: f64,
    width: f64,
    cg_to_front: f64,
    tyre: TyreParams,
    mu_scale: f64,
    /// The engaged powertrain, per driven (rear) wheel; `None` for a by-wire vehicle or a
    /// target in neutral.
    driveline: Option<Driveline>,
}

/// A powertrain in gear, reduced to one driven wheel (each rear wheel carries half the axle
/// torque).
#[derive(Debug, Clone, Copy)]
struct Driveline {
    /// Closed-throttle engine braking per driven wheel, `½ i_g T_drag` (N m).
    drag: f64,
    /// Holding torque of the stalled engine per driven wheel, `½ i_g T_stall` (N m).
    hold: f64,
    /// Axle speed at the engine's stall speed, `ω_stall / i_g` (rad/s).
    stall_axle_speed: f64,
}

impl Driveline {
    fn new(p: &VehicleParams) -> Option<Self> {
        p.powertrain.as_ref().map(|pt| Self {
            drag: 0.5 * p.gear_ratio * pt.engine_drag_torque,
            hold: 0.5 * p.gear_ratio * pt.stall_torque,
            stall_axle_speed: pt.stall_speed / p.gear_ratio,
        })
    }
}

impl Chassis {
    /// Offset of the total c.g. from the chassis origin (body frame).
    #[inline]
    fn cg_offset(&self, b: &VehicleBody) -> Vec2 {
        Vec2::new(self.h_pitch * b.theta, self.h_roll * b.phi) * (self.ms * self.inv_m)
    }

    #[inline]
    fn cg_rate(&self, b: &VehicleBody) -> Vec2 {
        Vec2::new(self.h_pitch * b.q, self.h_roll * b.p) * (self.ms * self.inv_m)
    }

    /// Displacement of the sprung body at bumper height from the chassis origin.
    #[inline]
    fn bumper_offset(&self, b: &VehicleBody) -> Vec2 {
        Vec2::new(self.h_bumper * b.theta, self.h_bumper_roll * b.phi)
    }

    #[inline]
    fn bumper_rate(&self, b: &VehicleBody) -> Vec2 {
        Vec2::new(self.h_bumper * b.q, self.h_bumper_roll * b.p)
    }

    fn new(p: &VehicleParams, mu: f64, dt: f64, driveline: Option<Driveline>) -> Self {
        let l = p.wheelbase();
        let (fz_f, fz_r) = p.static_axle_loads();
        let mus = p.mass - p.sprung_mass;
        let h_roll = p.roll_arm();
        let h_pitch = p.h_sprung;
        let ms2 = p.sprung_mass * p.sprung_mass;
        let ms_axle = [p.sprung_mass * p.lr / l, p.sprung_mass * p.lf / l];
        let lat_transfer = [
            (ms_axle[0] * p.h_roll_axis + 0.5 * mus * p.wheel_radius) / p.track_front,
            (ms_axle[1] * p.h_roll_axis + 0.5 * mus * p.wheel_radius) / p.track_rear,
        ];
        let bf = p.brake_bias_front;
        Self {
            inv_m: 1.0 / p.mass,
            m: p.mass,
            ms: p.sprung_mass,
            inv_iz: 1.0 / p.iz,
            h_roll,
            h_pitch,
            // Inertias about the roll / pitch axes, reduced by the coupling to the c.g.
            // motion (the c.g. acceleration is the state's, not the axis').
            roll_inertia: p.ix_sprung + p.sprung_mass * h_roll * h_roll
                - ms2 * h_roll * h_roll / p.mass,
            pitch_inertia: p.iy_sprung + p.sprung_mass * h_pitch * h_pitch
                - ms2 * h_pitch * h_pitch / p.mass,
            k_roll: [p.roll_stiffness_front, p.roll_stiffness_rear],
            c_roll: [p.roll_damping_front, p.roll_damping_rear],
            k_pitch: p.pitch_stiffness,
            c_pitch: p.pitch_damping,
            track: [p.track_front, p.track_rear],
            wheelbase: l,
            wheel_pos: [
                Vec2::new(p.lf, 0.5 * p.track_front),
                Vec2::new(p.lf, -0.5 * p.track_front),
                Vec2::new(-p.lr, 0.5 * p.track_rear),
                Vec2::new(-p.lr, -0.5 * p.track_rear),
            ],
            fz_static: [0.5 * fz_f, 0.5 * fz_f, 0.5 * fz_r, 0.5 * fz_r],
            lat_transfer,
            long_transfer: mus * p.wheel_radius / l,
            h_bumper_roll: p.bumper_height - p.h_roll_axis,
            h_bumper: p.bumper_height,
            rw: p.wheel_radius,
            iw: p.wheel_inertia,
            drive_gain: p.drive_efficiency * p.gear_ratio,
            brake_share: [0.5 * bf, 0.5 * bf, 0.5 * (1.0 - bf), 0.5 * (1.0 - bf)],
            steer_max: p.steer_max,
            steer_rate_max: p.steer_rate_max,
            steer_lag: lag_factor(dt, p.steer_time_constant),
            torque_limits: (p.drive_torque_min, p.drive_torque_max),
            torque_lag: lag_factor(dt, p.torque_time_constant),
            brake_max: p.brake_torque_max,
            rolling_resistance: p.rolling_resistance,
            drag: 0.5 * AIR_DENSITY * p.drag_area,
            length: p.length,
            width: p.width,
            cg_to_front: p.cg_to_front,
            tyre: p.tyre.clone(),
            mu_scale: p.tyre.mu_scale(mu),
            driveline,
        }
    }
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

/// External forces gathered for one vehicle during a step (world frame).
#[derive(Debug, Clone, Copy, Default)]
struct External {
    force: Vec2,
    moment: f64,
    /// Sum of contact forces (they act at bumper height, so they roll and pitch the body).
    contact_force: Vec2,
}

impl External {
    #[inline]
    fn add(&mut self, f: Vec2, at: Vec2, cg: Vec2) {
        self.force += f;
        self.contact_force += f;
        self.moment += cross(at - cg, f);
    }
}

#[derive(Debug, Clone, Copy, Default)]
struct ContactAccumulator {
    impulse_fn: f64,
    impulse_ft: f64,
    normal_weighted: Vec2,
    point_world: Vec2,
    point_target: Vec2,
    point_bullet: Vec2,
    depth_max: f64,
    since: f64,
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

/// Largest `ω dt` of a contact the plant accepts: a contact period of at least 4π (≈ 12.6)
/// steps, so the spring–damper is integrated, not aliased.
const MAX_CONTACT_OMEGA_DT: f64 = 0.5;

/// Refuse a contact stiffness the plant step cannot resolve: `ω = √(k · m_eff⁻¹)` with the
/// largest effective inverse mass a contact can see (a blow at the farthest body corner,
/// perpendicular to its arm) for the car–car pair and for either car on an obstacle.
fn check_contact_resolved(params: &ParamSet, dt: f64) -> Result<(), ParamError> {
    let inverse_mass = |v: &VehicleParams| {
        let reach = v.cg_to_front.max(v.length - v.cg_to_front);
        1.0 / v.mass + (reach * reach + 0.25 * v.width * v.width) / v.iz
    };
    let (b, t) = (inverse_mass(&params.bullet), inverse_mass(&params.target));
    let k = params.contact.stiffness;
    let k_obstacle = k * params.contact.obstacle_stiffness_factor;
    let omega = (k * (b + t)).sqrt().max((k_obstacle * b.max(t)).sqrt());
    if omega * dt > MAX_CONTACT_OMEGA_DT {
        return Err(ParamError::Invalid {
            field: "contact.stiffness".to_owned(),
            value: k,
            reason: "too stiff for the plant step: a contact period must span at least 12 steps \
                     (lower the stiffness or the obstacle factor, or the plant dt)",
        });
    }
    Ok(())
}

impl Plant {
    /// A plant for a parameter set. The vehicles start at rest at the origin; call
    /// [`Plant::reset`].
    pub fn new(params: &ParamSet, config: PlantConfig) -> Result<Self, ParamError> {
        params.validate()?;
        config.validate()?;
        check_contact_resolved(params, config.dt)?;
        let law = ContactLaw::from_params(&params.contact);
        let target_driveline = match config.target_gear {
            Gear::Neutral => None,
            Gear::Forward => Some(Driveline::new(&params.target).ok_or(ParamError::Missing {
                table: "target.powertrain".to_owned(),
                reason: "a target in gear needs its powertrain (or run it in neutral)",
            })?),
        };
        Ok(Self {
            config,
            chassis: [
                Chassis::new(&params.bullet, config.mu, config.dt, None),
                Chassis::new(&params.target, config.mu, config.dt, target_driveline),
            ],
            bodies: [VehicleBody::default(); 2],
            law,
            obstacle_law: law.stiffer(params.contact.obstacle_stiffness_factor),
            obstacles: Vec::new(),
            time: 0.0,
            steps: 0,
            contact: None,
            obstacle_contacts: [None; 2],
            accum: ContactAccumulator::default(),
        })
    }

    /// Replace the obstacles (allocates; call outside the real-time loop).
    pub fn set_obstacles(&mut self, obstacles: Vec<Obstacle>) {
        self.obstacles = obstacles;
    }

    #[must_use]
    pub fn obstacles(&self) -> &[Obstacle] {
        &self.obstacles
    }

    #[must_use]
    pub fn config(&self) -> &PlantConfig {
        &self.config
    }

    /// Change the road adhesion (e.g. a patch of ice).
    pub fn set_mu(&mut self, mu: f64) {
        self.config.mu = mu;
        for c in &mut self.chassis {
            c.mu_scale = c.tyre.mu_scale(mu);
        }
    }

    /// Put both vehicles at their initial conditions (suspension at rest, wheels rolling
    /// freely, actuators and commands at zero) and the clock at zero.
    pub fn reset(&mut self, bullet: &VehicleInit, target: &VehicleInit) {
        for (i, init) in [bullet, target].into_iter().enumerate() {
            let c = &self.chassis[i];
            let mut b = VehicleBody {
                pos: Vec2::new(init.x, init.y),
                yaw: init.yaw,
                vel: rotate(init.yaw, Vec2::new(init.vx, init.vy)),
                r: init.r,
                fz: c.fz_static,
                ..VehicleBody::default()
            };
            for (w, pos) in c.wheel_pos.iter().enumerate() {
                // Free rolling: wheel-frame longitudinal speed / R_w (no steer at reset).
                b.omega[w] = (init.vx - init.r * pos.y) / c.rw;
            }
            self.bodies[i] = b;
        }
        self.time = 0.0;
        self.steps = 0;
        self.contact = None;
        self.obstacle_contacts = [None; 2];
        self.accum = ContactAccumulator::default();
    }

    /// Bullet commands: road-wheel steer δ_f (rad) and drive torque T_r (N m).
    pub fn set_bullet_command(&mut self, delta: f64, t_r: f64) {
        let b = &mut self.bodies[Which::Bullet as usize];
        b.cmd_steer = finite_or_zero(delta);
        b.cmd_torque = finite_or_zero(t_r);
    }

    /// Bullet commands as the MPC plans them, `u_B = [δ_f, T_r]` with the rear-axle force
    /// `F_x,r = η_d i_g T_r / R_w`, realised the way a vehicle interface would: a positive
    /// T_r drives the rear axle, a negative one is blended into the service brakes (all four
    /// wheels, the vehicle's brake bias) with the same total force `−η_d i_g T_r / R_w`, so
    /// that braking while steering does not lock the driven axle alone.
    pub fn set_bullet_command_blended(&mut self, delta: f64, t_r: f64) {
        let gain = self.chassis[Which::Bullet as usize].drive_gain;
        let t_r = finite_or_zero(t_r);
        let (drive, brake) = if t_r >= 0.0 {
            (t_r, 0.0)
        } else {
            (0.0, -gain * t_r)
        };
        let b = &mut self.bodies[Which::Bullet as usize];
        b.cmd_steer = finite_or_zero(delta);
        b.cmd_torque = drive;
        b.cmd_brake = brake;
    }

    /// Target driver commands as the target models take them, `u_T = [δ, T_b]`: steer δ
    /// (rad) and the driver's longitudinal torque at the wheels (N m): `T_b ≥ 0` the total
    /// service-brake torque, `T_b < 0` the throttle, a drive torque `−T_b` at the driven
    /// axle (motor side `T_r = −T_b / (η_d i_g)`).
    pub fn set_target_command(&mut self, delta: f64, t_b: f64) {
        let gain = self.chassis[Which::Target as usize].drive_gain;
        let t_b = finite_or_zero(t_b);
        let b = &mut self.bodies[Which::Target as usize];
        b.cmd_steer = finite_or_zero(delta);
        b.cmd_brake = t_b.max(0.0);
        b.cmd_torque = (-t_b).max(0.0) / gain;
    }

    /// Drive-torque command T_r of either vehicle (N m, motor side; the target's driver is
    /// normally off the throttle, but tests and scripted drivers may hold its speed).
    pub fn set_drive(&mut self, which: Which, t_r: f64) {
        self.bodies[which as usize].cmd_torque = finite_or_zero(t_r);
    }

    /// Service-brake command of either vehicle (N m total at the wheels).
    pub fn set_brake(&mut self, which: Which, t_b: f64) {
        self.bodies[which as usize].cmd_brake = finite_or_zero(t_b);
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

    /// The contact averaged since the last call (impulse over the elapsed time, the normal
    /// and points weighted by the normal impulse), and restart averaging. `None` when the
    /// vehicles did not touch in that interval. This is what a 20 Hz logger records.
    pub fn take_contact_average(&mut self) -> Option<ContactReport> {
        let a = std::mem::take(&mut self.accum);
        if a.impulse_fn <= 0.0 || a.since <= 0.0 {
            return None;
        }
        let w = 1.0 / a.impulse_fn;
        Some(ContactReport {
            fc: Vec2::new(a.impulse_fn / a.since, a.impulse_ft / a.since),
            gamma: a.normal_weighted.y.atan2(a.normal_weighted.x),
            point_in_world: a.point_world * w,
            point_in_target: a.point_target * w,
            point_in_bullet: a.point_bullet * w,
            depth: a.depth_max,
        })
    }

    /// Footprints (bullet, target) now.
    #[must_use]
    pub fn footprints(&self) -> [Obb; 2] {
        [self.footprint(0), self.footprint(1)]
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

    /// The body rectangle at bumper height: it moves with the sprung mass, by
    /// `(h_b θ, (h_b − h_ra) φ)` relative to the roll/pitch axes.
    #[inline]
    fn footprint(&self, i: usize) -> Obb {
        let c = &self.chassis[i];
        let b = &self.bodies[i];
        let origin = b.pos + rotate(b.yaw, c.bumper_offset(b) - c.cg_offset(b));
        Obb::vehicle_footprint(
            &Pose2 {
                p_in_world: origin,
                yaw: b.yaw,
            },
            c.length,
            c.width,
            c.cg_to_front,
        )
    }

    /// Velocity of the body point at world position `p` at bumper height (rigid yaw plus
    /// the roll/pitch motion of the sprung mass relative to the c.g.).
    #[inline]
    fn body_point_velocity(&self, i: usize, p: Vec2) -> Vec2 {
        let c = &self.chassis[i];
        let b = &self.bodies[i];
        b.point_velocity(p) + rotate(b.yaw, c.bumper_rate(b) - c.cg_rate(b))
    }

    /// Apply an instantaneous planar impulse `impulse` (N s, world frame) at the world point
    /// `at` to one vehicle: its c.g. velocity changes by `J / m` and its yaw rate by
    /// `(at − c.g.) × J / I_z` (a rigid-body impulse; wheel spin, roll and pitch are left as
    /// they are). For idealised studies (`sim::oracle`); the plant's own contact never
    /// calls it. A non-finite impulse or point is ignored.
    pub fn apply_impulse(&mut self, which: Which, impulse: Vec2, at: Vec2) {
        if !(impulse.x.is_finite() && impulse.y.is_finite() && at.x.is_finite() && at.y.is_finite())
        {
            return;
        }
        let i = which as usize;
        let c = &self.chassis[i];
        let b = &mut self.bodies[i];
        b.vel += impulse * c.inv_m;
        b.r += cross(at - b.pos, impulse) * c.inv_iz;
    }

    /// Advance by `duration` (rounded to whole steps).
    pub fn advance(&mut self, duration: f64) {
        if !(duration.is_finite() && duration > 0.0) {
            return;
        }
        let n = (duration / self.config.dt).round() as u64;
        for _ in 0..n {
            self.step();
        }
    }

    /// One integration step.
    pub fn step(&mut self) {
        let dt = self.config.dt;
        let mut ext = [External::default(); 2];
        let fps = [self.footprint(0), self.footprint(1)];

        // Vehicle–vehicle contact.
        self.contact = None;
        if may_overlap(&fps[0], &fps[1]) {
            if let Some(geom) = obb_contact(&fps[0], &fps[1]) {
                let report = self.vehicle_contact(&geom, &mut ext);
                self.accumulate(&report, dt);
                self.contact = Some(report);
            }
        }
        // Obstacles.
        self.obstacle_contacts = [None; 2];
        for (k, obstacle) in self.obstacles.iter().enumerate() {
            let ofp = obstacle.footprint_at(self.time);
            let v_obs = Vec2::new(obstacle.vx, obstacle.vy);
            for i in 0..2 {
                if !may_overlap(&fps[i], &ofp) {
                    continue;
                }
                if let Some(geom) = obb_contact(&fps[i], &ofp) {
                    // Normal from the vehicle into the obstacle; the obstacle is body B.
                    let v_rel = v_obs - self.body_point_velocity(i, geom.point);
                    let fc = self.obstacle_law.force(
                        &geom,
                        v_rel,
                        [self.inertia_at(i, geom.point), (0.0, 0.0, Vec2::zeros())],
                    );
                    let f_world = rotate(geom.gamma(), fc);
                    ext[i].add(-f_world, geom.point, self.bodies[i].pos);
                    let stronger = self.obstacle_contacts[i].is_none_or(|c| c.normal_force < fc.x);
                    if stronger {
                        self.obstacle_contacts[i] = Some(ObstacleContact {
                            obstacle: k,
                            normal_force: fc.x,
                        });
                    }
                }
            }
        }
        let tyres = self.config.tyre_forces;
        for ((chassis, body), ext) in self.chassis.iter().zip(self.bodies.iter_mut()).zip(&ext) {
            integrate_vehicle(chassis, body, ext, dt, tyres);
        }
        self.steps += 1;
        self.time = self.steps as f64 * dt;
        self.accum.since += dt;
    }

    fn vehicle_contact(&self, geom: &ContactGeometry, ext: &mut [External; 2]) -> ContactReport {
        let (bullet, target) = (&self.bodies[0], &self.bodies[1]);
        let v_rel =
            self.body_point_velocity(1, geom.point) - self.body_point_velocity(0, geom.point);
        let fc = self.law.force(
            geom,
            v_rel,
            [
                self.inertia_at(0, geom.point),
                self.inertia_at(1, geom.point),
            ],
        );
        let gamma = geom.gamma();
        let f_world = rotate(gamma, fc);
        ext[1].add(f_world, geom.point, target.pos);
        ext[0].add(-f_world, geom.point, bullet.pos);
        ContactReport {
            fc,
            gamma,
            point_in_world: geom.point,
            point_in_target: rotate(-target.yaw, geom.point - target.pos),
            point_in_bullet: rotate(-bullet.yaw, geom.point - bullet.pos),
            depth: geom.depth,
        }
    }

    /// `(1/m, 1/I_z, arm from the c.g. to p)` of vehicle `i`, for the contact law.
    #[inline]
    fn inertia_at(&self, i: usize, p: Vec2) -> (f64, f64, Vec2) {
        let c = &self.chassis[i];
        (c.inv_m, c.inv_iz, p - self.bodies[i].pos)
    }

    fn accumulate(&mut self, r: &ContactReport, dt: f64) {
        let w = r.fc.x * dt;
        let a = &mut self.accum;
        a.impulse_fn += w;
        a.impulse_ft += r.fc.y * dt;
        a.normal_weighted += Vec2::new(r.gamma.cos(), r.gamma.sin()) * w;
        a.point_world += r.point_in_world * w;
        a.point_target += r.point_in_target * w;
        a.point_bullet += r.point_in_bullet * w;
        a.depth_max = a.depth_max.max(r.depth);
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

#[inline]
fn finite_or_zero(x: f64) -> f64 {
    if x.is_finite() {
        x
    } else {
        0.0
    }
}

/// Broad phase: bounding circles.
#[inline]
fn may_overlap(a: &Obb, b: &Obb) -> bool {
    let r = a.half.norm() + b.half.norm();
    (a.center - b.center).norm_squared() < r * r
}

/// Exact discretisation factor of a first-order lag: `1 − exp(−dt/τ)` (1 for τ = 0).
fn lag_factor(dt: f64, tau: f64) -> f64 {
    if tau <= 0.0 {
        1.0
    } else {
        1.0 - (-dt / tau).exp()
    }
}

/// Velocities of the four wheel centres (FL, FR, RL, RR) in their wheel frames (the front
/// wheels steered by δ, given as `sin δ`, `cos δ`).
#[inline]
fn wheel_velocities(c: &Chassis, b: &VehicleBody, sd: f64, cd: f64) -> [Vec2; 4] {
    let e = c.cg_offset(b);
    let e_dot = c.cg_rate(b);
    // Velocity of the chassis origin in the body frame.
    let v_o = b.vel_body() - e_dot - Vec2::new(-b.r * e.y, b.r * e.x);
    std::array::from_fn(|w| {
        let pos = c.wheel_pos[w];
        let v = Vec2::new(v_o.x - b.r * pos.y, v_o.y + b.r * pos.x);
        if w < 2 {
            Vec2::new(cd * v.x + sd * v.y, -sd * v.x + cd * v.y)
        } else {
            v
        }
    })
}

/// One semi-implicit Euler step of one vehicle.
#[allow(clippy::too_many_lines)]
fn integrate_vehicle(c: &Chassis, b: &mut VehicleBody, ext: &External, dt: f64, tyres: bool) {
    let (s, co) = b.yaw.sin_cos();
    let to_body = |v: Vec2| Vec2::new(co * v.x + s * v.y, -s * v.x + co * v.y);
    let to_world = |v: Vec2| Vec2::new(co * v.x - s * v.y, s * v.x + co * v.y);
    let e = c.cg_offset(b);
    let v_cg = to_body(b.vel);
    let (sd, cd) = b.steer.sin_cos();
    let v_wheel = wheel_velocities(c, b, sd, cd);

    // Wheel loads: static + pitch/roll suspension moments + unsprung / roll-centre terms
    // (with the last step's c.g. acceleration).
    let m_pitch = c.k_pitch * b.theta + c.c_pitch * b.q;
    let d_front = (m_pitch - c.long_transfer * b.acc_body.x) / c.wheelbase;
    let d_left: [f64; 2] = std::array::from_fn(|axle| {
        let m_roll = c.k_roll[axle] * b.phi + c.c_roll[axle] * b.p;
        m_roll / c.track[axle] - c.lat_transfer[axle] * b.acc_body.y
    });
    let fz = [
        (c.fz_static[0] + 0.5 * d_front + d_left[0]).max(0.0),
        (c.fz_static[1] + 0.5 * d_front - d_left[0]).max(0.0),
        (c.fz_static[2] - 0.5 * d_front + d_left[1]).max(0.0),
        (c.fz_static[3] - 0.5 * d_front - d_left[1]).max(0.0),
    ];

    // Tyre forces.
    let mut f_body = Vec2::zeros();
    let mut m_z = 0.0;
    let mut fx_wheel = [0.0; 4];
    let mut kx_over_v = [0.0; 4];
    if tyres {
        // Wheel-frame velocities (front wheels steered by δ), slips, then all four tyres.
        let mut kappa = [0.0; 4];
        let mut alpha = [0.0; 4];
        let mut denom = [0.0; 4];
        for w in 0..4 {
            let vw = v_wheel[w];
            denom[w] = vw.x.abs().max(V_LOW);
            kappa[w] = (b.omega[w] * c.rw - vw.x) / denom[w];
            alpha[w] = tan_slip(vw.x, vw.y);
        }
        let forces = combined_slip4(&c.tyre, c.mu_scale, &fz, &kappa, &alpha);
        for (w, f) in forces.iter().enumerate() {
            fx_wheel[w] = f.fx;
            kx_over_v[w] = f.kx / denom[w];
            let fb = if w < 2 {
                Vec2::new(cd * f.fx - sd * f.fy, sd * f.fx + cd * f.fy)
            } else {
                Vec2::new(f.fx, f.fy)
            };
            f_body += fb;
            m_z += cross(c.wheel_pos[w] - e, fb);
        }
    }
    // Aerodynamic drag at the c.g.
    if tyres {
        f_body -= v_cg * (c.drag * v_cg.norm());
    }

    // Planar motion of the c.g.
    let f_world = to_world(f_body) + ext.force;
    let acc_world = f_world * c.inv_m;
    let acc_body = to_body(acc_world);
    b.vel += acc_world * dt;
    b.r += (m_z + ext.moment) * c.inv_iz * dt;

    // Roll and pitch of the sprung mass, driven by the c.g. acceleration and by contact
    // forces acting at bumper height.
    let fc_body = to_body(ext.contact_force);
    let g = GRAVITY;
    let p_dot = (-c.ms * c.h_roll * acc_body.y + c.ms * g * c.h_roll * b.phi
        - (c.k_roll[0] + c.k_roll[1]) * b.phi
        - (c.c_roll[0] + c.c_roll[1]) * b.p
        + fc_body.y * c.h_bumper_roll)
        / c.roll_inertia;
    let q_dot = (-c.ms * c.h_pitch * acc_body.x + c.ms * g * c.h_pitch * b.theta
        - c.k_pitch * b.theta
        - c.c_pitch * b.q
        + fc_body.x * c.h_bumper)
        / c.pitch_inertia;
    b.p += p_dot * dt;
    b.q += q_dot * dt;
    b.phi += b.p * dt;
    b.theta += b.q * dt;
    b.yaw += b.r * dt;
    b.pos += b.vel * dt;

    // Wheel spin, implicit in the tyre's slip stiffness and solved together with the
    // chassis: the longitudinal force is linearised in the slip velocity ω R_w − v_x,
    // `F_x(t + dt) ≈ F_x + K (R_w Δω − Δv_x)` with `K = K_x / max(|v_x|, V_LOW)`, and the
    // wheel's ground speed change Δv_x over this step (the chassis has just been updated)
    // enters the balance. Without that term the wheel lags the decelerating chassis by
    // one step, which at low speed (large K) under-brakes by a time-step-dependent amount.
    // Then the Coulomb brake and rolling-resistance torque (stable to standstill).
    let v_wheel_new = if tyres {
        wheel_velocities(c, b, sd, cd)
    } else {
        v_wheel
    };
    // The powertrain on the driven wheels: the throttle's drive torque and closed-throttle
    // engine braking while the engine runs; once the axle has dragged it below its stall
    // speed, the stalled engine's hold, a Coulomb torque like a brake's.
    let (drive_wheel, hold_wheel) = match &c.driveline {
        Some(d) => {
            if !b.stalled && 0.5 * (b.omega[2] + b.omega[3]) < d.stall_axle_speed {
                b.stalled = true;
            }
            if b.stalled {
                (0.0, d.hold)
            } else {
                (0.5 * c.drive_gain * b.torque - d.drag, 0.0)
            }
        }
        None => (0.5 * c.drive_gain * b.torque, 0.0),
    };
    for w in 0..4 {
        let (drive, hold) = if w >= 2 {
            (drive_wheel, hold_wheel)
        } else {
            (0.0, 0.0)
        };
        let i_eff = c.iw + dt * c.rw * c.rw * kx_over_v[w];
        let ground = c.rw * kx_over_v[w] * (v_wheel_new[w].x - v_wheel[w].x);
        let omega_free = b.omega[w] + dt * (drive - c.rw * fx_wheel[w] + ground) / i_eff;
        let coulomb = c.brake_share[w] * b.brake + c.rolling_resistance * fz[w] * c.rw + hold;
        let cap = dt * coulomb / i_eff;
        b.omega[w] = if omega_free.abs() <= cap {
            0.0
        } else {
            omega_free - cap.copysign(omega_free)
        };
    }

    // Actuators.
    let steer_target = b.cmd_steer.clamp(-c.steer_max, c.steer_max);
    let step_max = c.steer_rate_max * dt;
    b.steer += ((steer_target - b.steer) * c.steer_lag).clamp(-step_max, step_max);
    b.torque +=
        (b.cmd_torque.clamp(c.torque_limits.0, c.torque_limits.1) - b.torque) * c.torque_lag;
    b.brake += (b.cmd_brake.clamp(0.0, c.brake_max) - b.brake) * c.torque_lag;

    b.fz = fz;
    b.acc_body = acc_body;
    flush_tiny(b);
}

/// Values that decay exponentially at rest (damped suspension, creeping velocity) would
/// reach subnormal numbers after minutes of simulated time, where arithmetic is ~100× slower.
/// Anything below 1e-150 is physically zero.
#[inline]
fn flush_tiny(b: &mut VehicleBody) {
    const TINY: f64 = 1e-150;
    let flush = |v: &mut f64| {
        if v.abs() < TINY {
            *v = 0.0;
        }
    };
    flush(&mut b.vel.x);
    flush(&mut b.vel.y);
    for v in [&mut b.r, &mut b.phi, &mut b.p, &mut b.theta, &mut b.q] {
        flush(v);
    }
}
