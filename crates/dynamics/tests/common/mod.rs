//! Shared set-up of the model tests: the step, adhesion and seed, parameter sets without
//! powertrain or resistances, random states.

#![allow(dead_code)]

use dynamics::params::{ParamSet, VehicleParams};
use dynamics::TargetState;
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use std::f64::consts::PI;

pub const DT: f64 = 0.05;
pub const MU: f64 = 0.9;
pub const SEED: u64 = 0x5EED_0001;

/// The target of a set without its powertrain (the driver's torque acts alone): the model
/// in neutral.
pub fn neutral(p: &VehicleParams) -> VehicleParams {
    VehicleParams {
        powertrain: None,
        ..p.clone()
    }
}

/// The target without rolling resistance and drag, so that closed forms hold exactly.
pub fn frictionless(p: &VehicleParams) -> VehicleParams {
    VehicleParams {
        rolling_resistance: 0.0,
        drag_area: 0.0,
        ..p.clone()
    }
}

pub fn sets() -> Vec<(&'static str, ParamSet)> {
    ParamSet::BUILTIN
        .iter()
        .map(|&n| (n, ParamSet::builtin(n).unwrap()))
        .collect()
}

pub fn uniform(rng: &mut ChaCha8Rng, lo: f64, hi: f64) -> f64 {
    rng.random_range(lo..hi)
}

/// Speed 2–30 m/s, sideslip up to ±0.5 rad, yaw rate up to ±1 rad/s, unwrapped heading.
pub fn random_planar(rng: &mut ChaCha8Rng) -> (f64, f64, f64, f64, f64, f64) {
    let speed = uniform(rng, 2.0, 30.0);
    let beta = uniform(rng, -0.5, 0.5);
    (
        speed * beta.cos(),
        speed * beta.sin(),
        uniform(rng, -2.0 * PI, 2.0 * PI),
        uniform(rng, -1.0, 1.0),
        uniform(rng, -100.0, 100.0),
        uniform(rng, -100.0, 100.0),
    )
}

pub fn target_state(vx: f64, vy: f64, psi: f64, r: f64) -> TargetState {
    TargetState::from([vx, vy, psi, r, 0.0, 0.0, 0.0, 0.0])
}
