//! Parameter sets: vehicles, tyres and the contact law, loaded from TOML and validated.
//!
//! A parameter file has three tables, `[bullet]`, `[target]` (each a [`VehicleParams`] with
//! a `[*.tyre]` sub-table) and `[contact]` ([`ContactParams`]). Unknown fields are refused,
//! missing fields are refused, and every value is checked for range and finiteness; the
//! error names the field (`target.tyre.pdy1`). Two sets are built in and embedded in the
//! binary: `full_size` and `half_scale` (see `crates/dynamics/params/*.toml` for the
//! source of every value).

use crate::error::ParamError;
use crate::GRAVITY;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Magic Formula tyre coefficients (MF-Tyre naming, pure and combined slip), in the form
/// CommonRoad's multi-body model evaluates them (Althoff & Würsching, "CommonRoad: Vehicle
/// Models", 2020, tyre model from the ADAMS handbook): peak friction and slip stiffnesses
/// proportional to the load (`D = μ F_z`, `K_x = p_Kx1 F_z`, `K_y = p_Ky1 F_z`). Camber,
/// shifts and aligning moment are not modelled.
///
/// Sign convention: all stiffness and friction coefficients are given as positive
/// magnitudes; the model applies forces against the slip.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TyreParams {
    /// Longitudinal shape factor C_x.
    pub pcx1: f64,
    /// Longitudinal friction μ_x.
    pub pdx1: f64,
    /// Longitudinal curvature E_x.
    pub pex1: f64,
    /// Longitudinal slip stiffness K_x / F_z.
    pub pkx1: f64,
    /// Lateral shape factor C_y.
    pub pcy1: f64,
    /// Lateral friction μ_y.
    pub pdy1: f64,
    /// Lateral curvature E_y.
    pub pey1: f64,
    /// Cornering stiffness K_y / F_z (1/rad).
    pub pky1: f64,
    /// Combined slip: slope factor of the F_x reduction with α.
    pub rbx1: f64,
    /// Combined slip: variation of that slope with κ.
    pub rbx2: f64,
    /// Combined slip: shape factor of the F_x reduction.
    pub rcx1: f64,
    /// Combined slip: curvature factor of the F_x reduction.
    pub rex1: f64,
    /// Combined slip: slope factor of the F_y reduction with κ.
    pub rby1: f64,
    /// Combined slip: variation of that slope with α.
    pub rby2: f64,
    /// Combined slip: shape factor of the F_y reduction.
    pub rcy1: f64,
    /// Combined slip: curvature factor of the F_y reduction.
    pub rey1: f64,
}

/// One vehicle: mass and inertia, geometry, suspension, wheels, drivetrain, actuators, tyres.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VehicleParams {
    /// Free-text name (e.g. the source vehicle).
    pub name: String,
    /// Total mass m (kg).
    pub mass: f64,
    /// Sprung mass m_s (kg), ≤ m.
    pub sprung_mass: f64,
    /// Yaw inertia of the whole vehicle about its c.g. (kg m²).
    pub iz: f64,
    /// Roll inertia of the sprung mass about its own c.g. (kg m²).
    pub ix_sprung: f64,
    /// Pitch inertia of the sprung mass about its own c.g. (kg m²).
    pub iy_sprung: f64,
    /// c.g. to front axle (m).
    pub lf: f64,
    /// c.g. to rear axle (m).
    pub lr: f64,
    /// Front and rear track widths (m).
    pub track_front: f64,
    pub track_rear: f64,
    /// Height of the total c.g. above ground (m).
    pub h_cg: f64,
    /// Height of the sprung-mass c.g. above ground (m).
    pub h_sprung: f64,
    /// Height of the roll axis under the c.g. (m), below `h_sprung`.
    pub h_roll_axis: f64,
    /// Body length, width and height (m).
    pub length: f64,
    pub width: f64,
    pub height: f64,
    /// Distance from the c.g. forward to the front bumper (m); the rear bumper is at
    /// `length − cg_to_front` behind the c.g.
    pub cg_to_front: f64,
    /// Height of the bumper / contact line above ground (m).
    pub bumper_height: f64,
    /// Roll stiffness and damping per axle (N m/rad, N m s/rad).
    pub roll_stiffness_front: f64,
    pub roll_stiffness_rear: f64,
    pub roll_damping_front: f64,
    pub roll_damping_rear: f64,
    /// Pitch stiffness and damping (N m/rad, N m s/rad).
    pub pitch_stiffness: f64,
    pub pitch_damping: f64,
    /// Effective rolling radius R_w (m) and spin inertia of one wheel (kg m²).
    pub wheel_radius: f64,
    pub wheel_inertia: f64,
    /// Drivetrain efficiency η_d and gear ratio i_g from T_r to the driven (rear) axle.
    pub drive_efficiency: f64,
    pub gear_ratio: f64,
    /// Steering: |δ| ≤ steer_max (rad), |δ̇| ≤ steer_rate_max (rad/s), first-order lag (s).
    pub steer_max: f64,
    pub steer_rate_max: f64,
    pub steer_time_constant: f64,
    /// Drive torque T_r limits before the gear (N m): `drive_torque_min ≤ T_r ≤ drive_torque_max`
    /// (negative values brake through the drivetrain), and its first-order lag (s).
    pub drive_torque_max: f64,
    pub drive_torque_min: f64,
    pub torque_time_constant: f64,
    /// Service brake: total brake torque at the wheels (N m) and front share.
    pub brake_torque_max: f64,
    pub brake_bias_front: f64,
    /// Anti-lock brakes: the longitudinal wheel slip `|κ|` the ABS holds a braked wheel at
    /// (about its tyre's force peak) above [`crate::plant::ABS_MIN_SPEED`]; 0 (the default)
    /// for brakes without ABS, which lock a wheel once its brake torque exceeds what the
    /// tyre can take.
    #[serde(default)]
    pub abs_slip: f64,
    /// Rolling-resistance coefficient f_r (rolling-resistance torque f_r F_z R_w per wheel).
    pub rolling_resistance: f64,
    /// Aerodynamic drag area C_d A (m²); drag ½ ρ C_d A v².
    pub drag_area: f64,
    /// Tyres (all four alike).
    pub tyre: TyreParams,
    /// The engine and the engaged forward gear of a driver-controlled car (the target); a
    /// by-wire vehicle whose controller commands its axle torque directly (the bullet) has
    /// none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub powertrain: Option<PowertrainParams>,
}

/// The target's powertrain: an engine coupled to the driven (rear) axle through the engaged
/// forward gear, overall ratio [`VehicleParams::gear_ratio`] (engine speed
/// `ω_e = i_g · ω_axle`, the axle speed the mean of the two driven wheels).
///
/// * Running, throttle closed: the engine drags the axle with `i_g T_drag` (fuel cut-off
///   engine braking: friction and pumping). The driver's throttle `T_r` adds `η_d i_g T_r`.
/// * When the axle drags the engine below its stall speed (rolling forwards too slowly in
///   gear, or turned backwards by a spin) it stalls and stays stalled: the stalled engine
///   holds the axle with a Coulomb torque of up to `i_g T_stall` (its compression and
///   friction), which the tyres then have to overcome; beyond their grip the wheels slide.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PowertrainParams {
    /// T_drag: the closed-throttle drag torque at the engine (N m).
    pub engine_drag_torque: f64,
    /// Engine speed below which the engine stalls (rad/s); 0 for a drive that never stalls.
    pub stall_speed: f64,
    /// T_stall: the holding torque of the stalled engine at the engine (N m).
    pub stall_torque: f64,
}

/// The compliant contact law between two bodies ([`crate::contact::ContactLaw`]): a linear
/// crush spring with a damper set by the coefficient of restitution,
/// `F_n = max(0, k δ + 2 ζ(e) sqrt(k m_eff) δ̇)`, and regularised Coulomb friction
/// `F_t = −μ_c F_n tanh(v_t / v_s)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ContactParams {
    /// k (N/m).
    pub stiffness: f64,
    /// e: coefficient of restitution of a contact at any closing speed and mass, in [0.15, 1].
    pub restitution: f64,
    /// μ_c: body-panel friction.
    pub friction: f64,
    /// v_s (m/s): slip speed of the friction regularisation.
    pub slip_speed: f64,
    /// Stiffness multiplier for contact with obstacles (rigid barriers are stiffer).
    pub obstacle_stiffness_factor: f64,
}

/// A complete parameter set for a two-vehicle PIT simulation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParamSet {
    pub bullet: VehicleParams,
    pub target: VehicleParams,
    pub contact: ContactParams,
}

const FULL_SIZE: &str = include_str!("../params/full_size.toml");
const HALF_SCALE: &str = include_str!("../params/half_scale.toml");

impl ParamSet {
    /// Names of the built-in sets.
    pub const BUILTIN: [&'static str; 2] = ["full_size", "half_scale"];

    /// A built-in set by name (`full_size` or `half_scale`).
    pub fn builtin(name: &str) -> Result<Self, ParamError> {
        match name {
            "full_size" => Self::from_toml_str(FULL_SIZE, "full_size"),
            "half_scale" => Self::from_toml_str(HALF_SCALE, "half_scale"),
            other => Err(ParamError::UnknownSet(other.to_owned())),
        }
    }

    /// The TOML source of a built-in set.
    pub fn builtin_source(name: &str) -> Result<&'static str, ParamError> {
        match name {
            "full_size" => Ok(FULL_SIZE),
            "half_scale" => Ok(HALF_SCALE),
            other => Err(ParamError::UnknownSet(other.to_owned())),
        }
    }

    /// A built-in set name or a path to a TOML file.
    pub fn load(name_or_path: &str) -> Result<Self, ParamError> {
        if Self::BUILTIN.contains(&name_or_path) {
            Self::builtin(name_or_path)
        } else {
            Self::from_file(Path::new(name_or_path))
        }
    }

    /// Parse and validate a TOML file.
    pub fn from_file(path: &Path) -> Result<Self, ParamError> {
        let text = std::fs::read_to_string(path).map_err(|e| ParamError::Io {
            path: path.display().to_string(),
            message: e.to_string(),
        })?;
        Self::from_toml_str(&text, &path.display().to_string())
    }

    /// Parse and validate TOML text; `source_name` appears in error messages.
    pub fn from_toml_str(text: &str, source_name: &str) -> Result<Self, ParamError> {
        let set: Self = toml::from_str(text).map_err(|e| ParamError::Parse {
            source_name: source_name.to_owned(),
            message: e.to_string().trim_end().to_owned(),
        })?;
        set.validate()?;
        Ok(set)
    }

    /// Serialise to TOML (round-trips through [`ParamSet::from_toml_str`]).
    #[must_use]
    pub fn to_toml_string(&self) -> String {
        toml::to_string(self).expect("parameter sets always serialise")
    }

    /// Check every field; the error names the first offending field.
    pub fn validate(&self) -> Result<(), ParamError> {
        self.bullet.validate("bullet")?;
        self.target.validate("target")?;
        self.contact.validate("contact")
    }
}

/// Range rules for one numeric field of a user-supplied file (parameters, roads, scenarios).
#[derive(Debug, Clone, Copy)]
pub(crate) enum Rule {
    Positive,
    NonNegative,
    Finite,
    Fraction,
    AtMostOne,
    /// `|value| · scale < 1` (e.g. a curvature times the road's half width).
    AbsBelowInverse {
        scale: f64,
        reason: &'static str,
    },
}

impl Rule {
    /// Why `value` breaks the rule, or `None` when it is admissible. Non-finite values
    /// always break it.
    pub(crate) fn violation(self, value: f64) -> Option<&'static str> {
        if !value.is_finite() {
            return Some("must be finite");
        }
        match self {
            Rule::Positive if value <= 0.0 => Some("must be positive"),
            Rule::NonNegative if value < 0.0 => Some("must not be negative"),
            Rule::Fraction if !(0.0..=1.0).contains(&value) => Some("must lie in [0, 1]"),
            Rule::AtMostOne if value > 1.0 => Some("must be at most 1 (Magic Formula curvature)"),
            Rule::AbsBelowInverse { scale, reason } if value.abs() * scale >= 1.0 => Some(reason),
            _ => None,
        }
    }
}

fn check(prefix: &str, name: &str, value: f64, rule: Rule) -> Result<(), ParamError> {
    match rule.violation(value) {
        Some(reason) => Err(ParamError::Invalid {
            field: format!("{prefix}.{name}"),
            value,
            reason,
        }),
        None => Ok(()),
    }
}

/// `value` within the physical range `[lo, hi]` (in `unit`), checked after its sign rule.
fn within(prefix: &str, name: &str, value: f64, (lo, hi, unit): Range) -> Result<(), ParamError> {
    if (lo..=hi).contains(&value) {
        Ok(())
    } else {
        Err(ParamError::OutOfRange {
            field: format!("{prefix}.{name}"),
            value,
            lo,
            hi,
            unit,
        })
    }
}

/// A physical range `(lo, hi, unit)`.
type Range = (f64, f64, &'static str);

macro_rules! ranges {
    ($prefix:expr, $s:expr, { $($field:ident : $range:expr),* $(,)? }) => {{
        $( within($prefix, stringify!($field), $s.$field, $range)?; )*
    }};
}

macro_rules! rules {
    ($prefix:expr, $s:expr, { $($field:ident : $rule:ident),* $(,)? }) => {{
        $( check($prefix, stringify!($field), $s.$field, Rule::$rule)?; )*
    }};
}

impl TyreParams {
    pub fn validate(&self, prefix: &str) -> Result<(), ParamError> {
        rules!(prefix, self, {
            pcx1: Positive, pdx1: Positive, pex1: AtMostOne, pkx1: Positive, pcy1: Positive,
            pdy1: Positive, pey1: AtMostOne, pky1: Positive, rbx1: Positive, rbx2: Finite,
            rcx1: Positive, rex1: AtMostOne, rby1: Positive, rby2: Finite, rcy1: Positive,
            rey1: AtMostOne,
        });
        // Magic Formula coefficients of passenger-car and light-truck tyres (Pacejka 2012,
        // ch. 4; the CommonRoad/ADAMS sets) lie well inside these bounds.
        let shape = (0.5, 3.0, "");
        let peak = (0.1, 3.0, "");
        let curvature = (-10.0, 1.0, "");
        let slip_stiffness = (1.0, 100.0, "per unit slip and load");
        let weighting = (-100.0, 100.0, "");
        ranges!(prefix, self, {
            pcx1: shape, pdx1: peak, pex1: curvature, pkx1: slip_stiffness, pcy1: shape,
            pdy1: peak, pey1: curvature, pky1: slip_stiffness, rbx1: weighting, rbx2: weighting,
            rcx1: shape, rex1: curvature, rby1: weighting, rby2: weighting, rcy1: shape,
            rey1: curvature,
        });
        Ok(())
    }

    /// Peak friction scale so that the lateral peak at nominal load equals the road μ.
    #[inline]
    #[must_use]
    pub fn mu_scale(&self, road_mu: f64) -> f64 {
        road_mu / self.pdy1
    }

    /// Cornering stiffness K_y(F_z) = p_Ky1 F_z (N/rad) of one tyre.
    #[inline]
    #[must_use]
    pub fn cornering_stiffness(&self, fz: f64) -> f64 {
        self.pky1 * fz
    }
}

impl VehicleParams {
    pub fn validate(&self, prefix: &str) -> Result<(), ParamError> {
        rules!(prefix, self, {
            mass: Positive, sprung_mass: Positive, iz: Positive, ix_sprung: Positive,
            iy_sprung: Positive, lf: Positive, lr: Positive, track_front: Positive,
            track_rear: Positive, h_cg: Positive, h_sprung: Positive, h_roll_axis: NonNegative,
            length: Positive, width: Positive, height: Positive, cg_to_front: Positive,
            bumper_height: Positive, roll_stiffness_front: Positive, roll_stiffness_rear: Positive,
            roll_damping_front: NonNegative, roll_damping_rear: NonNegative,
            pitch_stiffness: Positive, pitch_damping: NonNegative, wheel_radius: Positive,
            wheel_inertia: Positive, drive_efficiency: Fraction, gear_ratio: Positive,
            steer_max: Positive, steer_rate_max: Positive, steer_time_constant: NonNegative,
            drive_torque_max: NonNegative, drive_torque_min: Finite,
            torque_time_constant: NonNegative, brake_torque_max: NonNegative,
            brake_bias_front: Fraction, rolling_resistance: NonNegative, drag_area: NonNegative,
            abs_slip: NonNegative,
        });
        // Every road vehicle from a 1:5 scale model (~10 kg) to a heavy truck (~40 t).
        let inertia = (1e-2, 1e6, "kg m^2");
        let axle = (0.05, 10.0, "m");
        let height = (0.02, 3.0, "m");
        let roll_stiffness = (1.0, 1e7, "N m/rad");
        let roll_damping = (0.0, 1e6, "N m s/rad");
        let torque = (0.0, 1e5, "N m");
        let lag = (0.0, 2.0, "s");
        ranges!(prefix, self, {
            mass: (10.0, 4e4, "kg"), sprung_mass: (5.0, 4e4, "kg"), iz: inertia,
            ix_sprung: inertia, iy_sprung: inertia, lf: axle, lr: axle,
            track_front: (0.1, 3.0, "m"), track_rear: (0.1, 3.0, "m"), h_cg: height,
            h_sprung: height, h_roll_axis: (0.0, 2.0, "m"), length: (0.2, 25.0, "m"),
            width: (0.1, 3.0, "m"), height: (0.1, 5.0, "m"), cg_to_front: (0.1, 20.0, "m"),
            bumper_height: (0.02, 1.5, "m"), roll_stiffness_front: roll_stiffness,
            roll_stiffness_rear: roll_stiffness, roll_damping_front: roll_damping,
            roll_damping_rear: roll_damping, pitch_stiffness: (1.0, 1e8, "N m/rad"),
            pitch_damping: (0.0, 1e7, "N m s/rad"), wheel_radius: (0.02, 1.5, "m"),
            wheel_inertia: (1e-4, 200.0, "kg m^2"), drive_efficiency: (0.3, 1.0, ""),
            gear_ratio: (0.5, 50.0, ""), steer_rate_max: (0.01, 10.0, "rad/s"),
            steer_time_constant: lag, drive_torque_max: torque,
            drive_torque_min: (-1e5, 0.0, "N m"), torque_time_constant: lag,
            brake_torque_max: torque, rolling_resistance: (0.0, 0.1, ""),
            drag_area: (0.0, 20.0, "m^2"), abs_slip: (0.0, 0.5, ""),
        });
        let invalid = |field: &str, value: f64, reason: &'static str| {
            Err(ParamError::Invalid {
                field: format!("{prefix}.{field}"),
                value,
                reason,
            })
        };
        if self.sprung_mass > self.mass {
            return invalid("sprung_mass", self.sprung_mass, "must not exceed mass");
        }
        if self.drive_torque_min > 0.0 {
            return invalid(
                "drive_torque_min",
                self.drive_torque_min,
                "must not be positive",
            );
        }
        if self.h_roll_axis >= self.h_sprung {
            return invalid("h_roll_axis", self.h_roll_axis, "must lie below h_sprung");
        }
        if self.cg_to_front >= self.length {
            return invalid(
                "cg_to_front",
                self.cg_to_front,
                "must be shorter than length",
            );
        }
        if self.cg_to_front < self.lf {
            return invalid(
                "cg_to_front",
                self.cg_to_front,
                "the front axle must lie inside the body",
            );
        }
        if self.length - self.cg_to_front < self.lr {
            return invalid(
                "length",
                self.length,
                "the rear axle must lie inside the body",
            );
        }
        if self.steer_max >= 1.4 {
            return invalid("steer_max", self.steer_max, "must be below 1.4 rad");
        }
        // The roll and pitch modes must be statically stable (spring beats gravity).
        let ms_g_h_roll = self.sprung_mass * GRAVITY * (self.h_sprung - self.h_roll_axis);
        if self.roll_stiffness_front + self.roll_stiffness_rear <= ms_g_h_roll {
            return invalid(
                "roll_stiffness_front",
                self.roll_stiffness_front,
                "total roll stiffness must exceed m_s g h (statically unstable roll)",
            );
        }
        if self.pitch_stiffness <= self.sprung_mass * GRAVITY * self.h_sprung {
            return invalid(
                "pitch_stiffness",
                self.pitch_stiffness,
                "must exceed m_s g h_sprung",
            );
        }
        if let Some(pt) = &self.powertrain {
            pt.validate(&format!("{prefix}.powertrain"))?;
        }
        self.tyre.validate(&format!("{prefix}.tyre"))
    }

    /// Wheelbase L = l_f + l_r (m).
    #[inline]
    #[must_use]
    pub fn wheelbase(&self) -> f64 {
        self.lf + self.lr
    }

    /// Static axle loads (front, rear) in N.
    #[must_use]
    pub fn static_axle_loads(&self) -> (f64, f64) {
        let w = self.mass * GRAVITY;
        let l = self.wheelbase();
        (w * self.lr / l, w * self.lf / l)
    }

    /// Rear-axle longitudinal force per unit drive torque: η_d i_g / R_w (1/m).
    #[inline]
    #[must_use]
    pub fn drive_force_gain(&self) -> f64 {
        self.drive_efficiency * self.gear_ratio / self.wheel_radius
    }

    /// The wheel torque at the driven axle (N m) that holds a steady speed `v` straight
    /// ahead on a level road: closed-throttle engine braking through the engaged gear (with a
    /// powertrain), rolling resistance and aerodynamic drag. As a target input it is the
    /// throttle `T_b = −cruise_wheel_torque(v)`.
    #[must_use]
    pub fn cruise_wheel_torque(&self, v: f64) -> f64 {
        let engine = self
            .powertrain
            .as_ref()
            .map_or(0.0, |pt| self.gear_ratio * pt.engine_drag_torque);
        let resist = self.rolling_resistance * self.mass * GRAVITY
            + 0.5 * crate::plant::AIR_DENSITY * self.drag_area * v * v;
        engine + self.wheel_radius * resist
    }

    /// Roll arm: sprung c.g. above the roll axis (m).
    #[inline]
    #[must_use]
    pub fn roll_arm(&self) -> f64 {
        self.h_sprung - self.h_roll_axis
    }
}

impl PowertrainParams {
    pub fn validate(&self, prefix: &str) -> Result<(), ParamError> {
        rules!(prefix, self, {
            engine_drag_torque: NonNegative, stall_speed: NonNegative, stall_torque: NonNegative,
        });
        ranges!(prefix, self, {
            engine_drag_torque: (0.0, 2000.0, "N m"), stall_speed: (0.0, 500.0, "rad/s"),
            stall_torque: (0.0, 1e4, "N m"),
        });
        Ok(())
    }
}

impl ContactParams {
    pub fn validate(&self, prefix: &str) -> Result<(), ParamError> {
        rules!(prefix, self, {
            stiffness: Positive, restitution: Positive, friction: NonNegative,
            slip_speed: Positive, obstacle_stiffness_factor: Positive,
        });
        // A PIT push's contact stiffness is 2–7e5 N/m at full size (REFERENCES.md, impact
        // mechanics); the plant step must also resolve the contact (`Plant::new`).
        ranges!(prefix, self, {
            stiffness: (1e3, 1e8, "N/m"), friction: (0.0, 2.0, ""),
            slip_speed: (1e-3, 1.0, "m/s"), obstacle_stiffness_factor: (0.1, 100.0, ""),
        });
        if !(0.15..=1.0).contains(&self.restitution) {
            return Err(ParamError::Invalid {
                field: format!("{prefix}.restitution"),
                value: self.restitution,
                reason: "must lie in [0.15, 1] (a damped linear spring gives no less)",
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builtin_sets_load_and_validate() {
        for name in ParamSet::BUILTIN {
            let set = ParamSet::builtin(name).unwrap();
            set.validate().unwrap();
            let back = ParamSet::from_toml_str(&set.to_toml_string(), "roundtrip").unwrap();
            assert_eq!(set, back);
        }
    }

    #[test]
    fn unknown_set_is_refused() {
        assert!(matches!(
            ParamSet::builtin("monster_truck"),
            Err(ParamError::UnknownSet(_))
        ));
    }

    fn replace_line(src: &str, table: &str, key: &str, new_line: Option<&str>) -> String {
        // Replace (or delete) `key = …` inside `[table]`.
        let mut out = String::new();
        let mut current = String::new();
        for line in src.lines() {
            let t = line.trim();
            if t.starts_with('[') {
                current = t.trim_matches(|c| c == '[' || c == ']').to_owned();
            }
            let is_key = t.split('=').next().map(str::trim) == Some(key) && t.contains('=');
            if current == table && is_key {
                if let Some(n) = new_line {
                    out.push_str(n);
                    out.push('\n');
                }
                continue;
            }
            out.push_str(line);
            out.push('\n');
        }
        out
    }

    /// Every `(table, key)` of a parameter file whose value is a number.
    fn numeric_fields(src: &str) -> Vec<(String, String)> {
        let mut table = String::new();
        let mut out = Vec::new();
        for line in src.lines() {
            let t = line.trim();
            if t.starts_with('[') {
                table = t.trim_matches(|c| c == '[' || c == ']').to_owned();
                continue;
            }
            let Some((key, value)) = t.split_once('=') else {
                continue;
            };
            let value = value.split('#').next().unwrap().trim();
            if value.replace('_', "").parse::<f64>().is_ok() {
                out.push((table.clone(), key.trim().to_owned()));
            }
        }
        out
    }

    /// Sets every numeric field of both built-in sets to each of `bads` in turn and asserts
    /// the error names exactly that field.
    fn every_numeric_field_refuses(bads: &[&str]) {
        for set in ParamSet::BUILTIN {
            let src = ParamSet::builtin_source(set).unwrap();
            let fields = numeric_fields(src);
            assert!(fields.len() > 80, "{set}: only {} fields", fields.len());
            for (table, key) in &fields {
                for bad in bads {
                    let text = replace_line(src, table, key, Some(&format!("{key} = {bad}")));
                    let err = ParamSet::from_toml_str(&text, "prop.toml")
                        .unwrap_err()
                        .to_string();
                    let field = format!("{table}.{key}");
                    assert!(
                        err.starts_with(&field),
                        "{set}: {field} = {bad} gave {err:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn every_numeric_field_refuses_nan_and_names_itself() {
        // Property over the whole schema: any numeric field set to NaN (or inf) is refused
        // with an error that names exactly that field, in every table, for both sets.
        every_numeric_field_refuses(&["nan", "inf", "-inf"]);
    }

    #[test]
    fn every_numeric_field_refuses_absurd_magnitudes_and_names_itself() {
        // Finite but absurd: ±1e308 in any field is outside its physical range, refused with
        // an error naming exactly that field.
        every_numeric_field_refuses(&["1e308", "-1e308"]);
    }

    #[test]
    fn the_issues_absurd_values_are_refused_with_their_range() {
        let src = ParamSet::builtin_source("full_size").unwrap();
        let cases = [
            ("target", "mass", "mass = 1e308", "target.mass", "kg"),
            ("bullet", "iz", "iz = 1e-9", "bullet.iz", "kg m^2"),
            (
                "contact",
                "stiffness",
                "stiffness = 1e15",
                "contact.stiffness",
                "N/m",
            ),
            (
                "target.tyre",
                "pdy1",
                "pdy1 = 1e308",
                "target.tyre.pdy1",
                "range",
            ),
        ];
        for (table, key, line, field, unit) in cases {
            let text = replace_line(src, table, key, Some(line));
            let err = ParamSet::from_toml_str(&text, "test.toml").unwrap_err();
            assert!(matches!(err, ParamError::OutOfRange { .. }), "{err:?}");
            let msg = err.to_string();
            assert!(
                msg.starts_with(field) && msg.contains("physical range") && msg.contains(unit),
                "{msg}"
            );
        }
    }

    #[test]
    fn bad_fields_are_named() {
        let src = ParamSet::builtin_source("full_size").unwrap();
        let cases = [
            ("target", "mass", None, "mass"),
            ("target", "mass", Some("mass = -3.0"), "target.mass"),
            ("bullet", "iz", Some("iz = nan"), "bullet.iz"),
            (
                "bullet.tyre",
                "pdy1",
                Some("pdy1 = inf"),
                "bullet.tyre.pdy1",
            ),
            (
                "contact",
                "restitution",
                Some("restitution = -1.0\nwobble = 2.0"),
                "wobble",
            ),
            (
                "target",
                "brake_bias_front",
                Some("brake_bias_front = 1.5"),
                "target.brake_bias_front",
            ),
            (
                "bullet",
                "abs_slip",
                Some("abs_slip = 0.9"),
                "bullet.abs_slip = 0.9: outside the physical range",
            ),
        ];
        for (table, key, line, expect) in cases {
            let text = replace_line(src, table, key, line);
            let err = ParamSet::from_toml_str(&text, "test.toml")
                .unwrap_err()
                .to_string();
            assert!(
                err.contains(expect),
                "error for {table}.{key} was {err:?}, wanted {expect:?}"
            );
        }
    }
}
