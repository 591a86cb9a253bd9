//! Settings of the coupled collision MPC: one serde struct with defaults, validated when the
//! controller is built, loadable from TOML.

use serde::{Deserialize, Serialize};
use thiserror::Error;

/// A setting that cannot be used; the message names the field.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum SettingsError {
    #[error("mpc settings: `{field}` {problem}")]
    Invalid { field: String, problem: String },
    #[error("mpc settings: {0}")]
    Parse(String),
}

fn invalid(field: &str, problem: impl Into<String>) -> SettingsError {
    SettingsError::Invalid {
        field: field.to_owned(),
        problem: problem.into(),
    }
}

/// How many sequential-convex-programming iterations one control step may take.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ScpMode {
    /// Real-time iteration: one QP per control step, the step always taken (the
    /// linearisation is refreshed at the next control step).
    Rti,
    /// Iterate (merit test, trust region) until the step is small, the iteration cap or the
    /// time budget.
    Converged,
}

/// Cost weights. Each is applied to a quantity in SI units divided by its scale (below), so
/// the weights are dimensionless and comparable.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Weights {
    /// w_T: weight of the target objective J_T (terminal heading and speed).
    pub target: f64,
    /// w_ψ inside J_T: terminal heading error (per rad²).
    pub target_heading: f64,
    /// w_v inside J_T: terminal target speed (per (m/s)²).
    pub target_speed: f64,
    /// w_e: relative-contact tracking, longitudinal and lateral position in the target frame
    /// (per m²).
    pub rel_long: f64,
    pub rel_lat: f64,
    /// Relative heading (per rad²).
    pub rel_heading: f64,
    /// Relative speed (per (m/s)²).
    pub rel_speed: f64,
    /// w_f: squared distance of f_c to the corridor C_F (per (force_scale)²).
    pub corridor: f64,
    /// w_u: input effort, steer (per rad²) and torque (per drive_torque_max²).
    pub steer: f64,
    pub torque: f64,
    /// Input rate (per (rad/step)² and (torque/step)², same scales).
    pub steer_rate: f64,
    pub torque_rate: f64,
    /// Exact-penalty weight of the soft constraints (per metre of violation, L1).
    pub penalty: f64,
    /// Proximal (Levenberg–Marquardt) weight on the step of every variable: keeps each QP
    /// strictly convex and the step inside the region where the linearisation holds.
    pub proximal: f64,
}

impl Default for Weights {
    fn default() -> Self {
        Self {
            target: 1.0,
            target_heading: 20.0,
            target_speed: 0.05,
            rel_long: 0.5,
            rel_lat: 4.0,
            rel_heading: 5.0,
            rel_speed: 2.0,
            corridor: 1.0,
            steer: 5.0,
            torque: 0.05,
            steer_rate: 50.0,
            torque_rate: 0.5,
            penalty: 1.0e4,
            proximal: 1.0e-3,
        }
    }
}

/// Contact treatment inside the prediction (see `docs/mpc.md`, "Forces and geometry").
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ContactSettings {
    /// Largest normal force the MPC may plan (N).
    pub force_max: f64,
    /// Gap (m) of the linearisation beyond which no force may be planned at a step (its
    /// bound is 0); nearer, the compliance band below ties the force to the predicted gap.
    pub gap_release: f64,
    /// The same gap before the bullet pushes (`CoupledMpc::set_pushing(false)`: the turn-in
    /// of a committed PIT), at least `gap_release`: a turn-in whose linearisation keeps the
    /// vehicles just beyond `gap_release` would otherwise never see that a force can be
    /// planned once they touch, and holds the bullet off the target.
    pub gap_engage: f64,
    /// Effective crush stiffness of the penetration law `F_n ≥ k (−gap)` (N/m): a planned
    /// overlap must be paid for with force.
    pub stiffness: f64,
    /// Body-panel friction μ_c of the friction cone |F_t| ≤ μ_c F_n.
    pub friction: f64,
    /// Width of the compliance band (m): near contact the planned normal force lies in
    /// `k·(−gap) ≤ F_n ≤ k·(band − gap)`, so a push must be paid for with crush and no
    /// force acts across a gap wider than `band`.
    pub band: f64,
}

impl Default for ContactSettings {
    fn default() -> Self {
        Self {
            force_max: 40_000.0,
            gap_release: 0.3,
            gap_engage: 0.4,
            stiffness: 2.0e5,
            friction: 0.3,
            band: 0.05,
        }
    }
}

/// Clarabel settings exposed to the user.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct QpSettings {
    /// Interior-point iteration cap per QP.
    pub max_iter: u32,
    /// Relative and absolute duality-gap tolerances, and the feasibility tolerance.
    pub tol_gap: f64,
    pub tol_feas: f64,
    /// Clarabel's iterative refinement of each KKT solve.
    pub iterative_refinement: bool,
    /// Clarabel's Ruiz equilibration, computed once from the first real QP (the
    /// controller's warm-up) and reused by every in-place update.
    pub equilibrate: bool,
    /// Clarabel's own wall-clock limit per QP (s): a safety net under the SCP loop's
    /// `time_budget`, which is read from the injected clock.
    pub time_limit: f64,
    /// Carry the target's roll states (p, φ) in the coupled QP. `false` (the default)
    /// leaves them out of the QP's linearisation (their deviation from the linearisation
    /// trajectory is taken as zero), 17 instead of 19 columns per stage and a factor
    /// about half the size; the nonlinear rollouts and the merit keep the full model.
    /// Measured in `docs/mpc.md` ("The target's roll in the QP"). The planner's QPs, which
    /// share this struct, have no target states and ignore it.
    pub target_roll: bool,
}

impl Default for QpSettings {
    fn default() -> Self {
        Self {
            max_iter: 50,
            tol_gap: 1e-3,
            tol_feas: 1e-4,
            iterative_refinement: false,
            equilibrate: false,
            time_limit: 0.04,
            target_roll: false,
        }
    }
}

/// Every setting of the coupled MPC.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MpcSettings {
    /// Horizon N (steps).
    pub horizon: usize,
    /// Step length (s); must equal the target model's.
    pub dt: f64,
    pub mode: ScpMode,
    /// SCP iteration cap (converged mode).
    pub max_scp_iter: u32,
    /// Wall-clock budget of one control step (s); the SCP loop stops before starting an
    /// iteration it cannot finish, and Clarabel gets the rest as its time limit.
    pub time_budget: f64,
    /// Trust region on the inputs' step: steer (rad) and torque (fraction of the maximum).
    pub trust_steer: f64,
    pub trust_torque: f64,
    /// Converged mode stops when the input step is below this fraction of the trust region.
    pub step_tol: f64,
    /// Road-edge margin kept by both vehicles (m).
    pub road_margin: f64,
    /// Clearance to obstacles (m), d_safe.
    pub obstacle_clearance: f64,
    /// Share of the rear axle's static traction (μ m g l_f / L) the planned drive torque
    /// may use (the rest is left for cornering); see `CoupledMpc`.
    pub traction_fraction: f64,
    /// Share of the road's grip μ g the planned steer may ask for as steady lateral
    /// acceleration: at the bullet's speed v the steer is bounded by
    /// `(L / v² + K_us) · lateral_fraction · μ g` (the steady-turn steer, `K_us` the
    /// understeer gradient); see `CoupledMpc`.
    pub lateral_fraction: f64,
    /// The same share while the bullet pushes (`CoupledMpc::set_pushing`): the contact
    /// force turns the bullet too, so the steady-turn steer of the tyres alone is no bound
    /// for the push (a large value lifts the bound to `steer_max`).
    pub lateral_fraction_push: f64,
    pub weights: Weights,
    pub contact: ContactSettings,
    pub qp: QpSettings,
}

impl Default for MpcSettings {
    fn default() -> Self {
        Self {
            horizon: 20,
            dt: 0.05,
            mode: ScpMode::Rti,
            max_scp_iter: 5,
            time_budget: 0.04,
            trust_steer: 0.08,
            trust_torque: 0.5,
            step_tol: 0.02,
            road_margin: 0.2,
            obstacle_clearance: 0.5,
            traction_fraction: 0.85,
            lateral_fraction: 0.8,
            lateral_fraction_push: 100.0,
            weights: Weights::default(),
            contact: ContactSettings::default(),
            qp: QpSettings::default(),
        }
    }
}

impl MpcSettings {
    /// Parse and validate TOML (missing fields take their defaults).
    ///
    /// # Errors
    /// [`SettingsError::Parse`] for malformed TOML or unknown fields, [`SettingsError::Invalid`]
    /// naming the first bad value.
    pub fn from_toml_str(text: &str) -> Result<Self, SettingsError> {
        let s: Self = toml::from_str(text).map_err(|e| SettingsError::Parse(e.to_string()))?;
        s.validate()?;
        Ok(s)
    }

    /// The settings as TOML.
    #[must_use]
    pub fn to_toml_string(&self) -> String {
        toml::to_string(self).expect("settings serialise")
    }

    /// Check every field.
    ///
    /// # Errors
    /// [`SettingsError::Invalid`] naming the first bad field.
    pub fn validate(&self) -> Result<(), SettingsError> {
        if !(2..=200).contains(&self.horizon) {
            return Err(invalid("horizon", "must be in 2..=200"));
        }
        if self.max_scp_iter == 0 {
            return Err(invalid("max_scp_iter", "must be at least 1"));
        }
        if self.qp.max_iter == 0 {
            return Err(invalid("qp.max_iter", "must be at least 1"));
        }
        if self.contact.gap_engage < self.contact.gap_release {
            return Err(invalid(
                "contact.gap_engage",
                format!(
                    "must be at least contact.gap_release ({} < {})",
                    self.contact.gap_engage, self.contact.gap_release
                ),
            ));
        }
        let positive = [
            ("dt", self.dt),
            ("time_budget", self.time_budget),
            ("traction_fraction", self.traction_fraction),
            ("lateral_fraction", self.lateral_fraction),
            ("lateral_fraction_push", self.lateral_fraction_push),
            ("trust_steer", self.trust_steer),
            ("trust_torque", self.trust_torque),
            ("step_tol", self.step_tol),
            ("contact.force_max", self.contact.force_max),
            ("contact.gap_release", self.contact.gap_release),
            ("contact.gap_engage", self.contact.gap_engage),
            ("contact.stiffness", self.contact.stiffness),
            ("contact.band", self.contact.band),
            ("qp.tol_gap", self.qp.tol_gap),
            ("qp.tol_feas", self.qp.tol_feas),
            ("qp.time_limit", self.qp.time_limit),
            ("weights.penalty", self.weights.penalty),
            ("weights.proximal", self.weights.proximal),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(invalid(name, format!("must be finite and > 0 (got {v})")));
            }
        }
        let w = &self.weights;
        let non_negative = [
            ("road_margin", self.road_margin),
            ("obstacle_clearance", self.obstacle_clearance),
            ("contact.friction", self.contact.friction),
            ("weights.target", w.target),
            ("weights.target_heading", w.target_heading),
            ("weights.target_speed", w.target_speed),
            ("weights.rel_long", w.rel_long),
            ("weights.rel_lat", w.rel_lat),
            ("weights.rel_heading", w.rel_heading),
            ("weights.rel_speed", w.rel_speed),
            ("weights.corridor", w.corridor),
            ("weights.steer", w.steer),
            ("weights.torque", w.torque),
            ("weights.steer_rate", w.steer_rate),
            ("weights.torque_rate", w.torque_rate),
        ];
        for (name, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return Err(invalid(name, format!("must be finite and >= 0 (got {v})")));
            }
        }
        if self.trust_torque > 2.0 {
            return Err(invalid(
                "trust_torque",
                "is a fraction of the torque range: at most 2",
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_round_trip_through_toml() {
        let s = MpcSettings::default();
        let back = MpcSettings::from_toml_str(&s.to_toml_string()).unwrap();
        assert_eq!(s, back);
    }

    #[test]
    fn bad_values_name_their_field() {
        let e = MpcSettings::from_toml_str("horizon = 1").unwrap_err();
        assert!(e.to_string().contains("`horizon`"), "{e}");
        let e = MpcSettings::from_toml_str("[weights]\npenalty = -1.0").unwrap_err();
        assert!(e.to_string().contains("weights.penalty"), "{e}");
        let e = MpcSettings::from_toml_str("[contact]\nfriction = nan").unwrap_err();
        assert!(e.to_string().contains("contact.friction"), "{e}");
        let e = MpcSettings::from_toml_str("[contact]\ngap_engage = 0.2").unwrap_err();
        assert!(e.to_string().contains("contact.gap_engage"), "{e}");
        let e = MpcSettings::from_toml_str("horizn = 20").unwrap_err();
        assert!(e.to_string().contains("horizn"), "{e}");
    }
}
