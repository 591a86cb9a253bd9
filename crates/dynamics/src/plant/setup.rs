//! Setting the plant up: validation of the settings and of the contact stiffness against
//! the step, construction, obstacles, road adhesion and reset to initial conditions.

use super::chassis::{Chassis, Driveline};
use super::contact::ContactAccumulator;
use super::{Gear, Plant, PlantConfig, VehicleBody, VehicleInit};
use crate::contact::ContactLaw;
use crate::error::ParamError;
use crate::geometry::{rotate, Vec2};
use crate::params::{ParamSet, VehicleParams};
use crate::road::Obstacle;

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
}
