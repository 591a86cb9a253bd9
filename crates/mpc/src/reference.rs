//! What the MPC tracks: the relative-contact reference e_ref, the force corridor C_F, the
//! bullet envelope C_B and the target's terminal heading, per step of the horizon.
//!
//! The upper layer (crates/planner) fills a [`Reference`] from its decision package through
//! h_ref; without it, [`DefaultPit`] gives the fixed default of the paper's
//! "without upper layer" ablation.

use dynamics::geometry::{rotate, Vec2};
use dynamics::params::ParamSet;

/// Which side of the target the bullet works on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Side {
    /// The bullet on the target's left (+y in the target frame): it pushes the target's
    /// rear to the right, and the target yaws counter-clockwise.
    Left,
    /// On the target's right: the target yaws clockwise.
    Right,
}

impl Side {
    /// +1 for left, −1 for right.
    #[must_use]
    pub fn sign(self) -> f64 {
        match self {
            Self::Left => 1.0,
            Self::Right => -1.0,
        }
    }

    /// The opposite side.
    #[must_use]
    pub fn other(self) -> Self {
        match self {
            Self::Left => Self::Right,
            Self::Right => Self::Left,
        }
    }
}

/// The reference at one step of the horizon.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StageReference {
    /// Desired bullet c.g. relative to the target c.g., in the target's body frame (m).
    pub rel_pos: Vec2,
    /// Desired ψ_B − ψ_T (rad).
    pub rel_heading: f64,
    /// Desired v_B − v_T (m/s, body-x speeds).
    pub rel_speed: f64,
    /// Scale of the tracking weights at this step (0 switches tracking off).
    pub track: f64,
    /// Force corridor C_F: F_n ∈ [fn_lo, fn_hi] (N); the friction cone always holds.
    pub fn_lo: f64,
    pub fn_hi: f64,
    /// Envelope C_B: largest lateral deviation of the bullet from `rel_pos.y` (m).
    pub envelope_lat: f64,
}

impl StageReference {
    /// Nothing to track, no force wanted, no envelope.
    #[must_use]
    pub fn idle() -> Self {
        Self {
            rel_pos: Vec2::new(-10.0, 0.0),
            rel_heading: 0.0,
            rel_speed: 0.0,
            track: 0.0,
            fn_lo: 0.0,
            fn_hi: 0.0,
            envelope_lat: 1.0e3,
        }
    }
}

/// The whole reference: one [`StageReference`] per predicted state `x_1 … x_N` (and per
/// force `f_0 … f_{N−1}`), plus the target objective.
#[derive(Debug, Clone, PartialEq)]
pub struct Reference {
    pub stages: Vec<StageReference>,
    /// ψ_T,rev: the reversed heading the target should end at (unwrapped, rad).
    pub target_heading: f64,
    /// Scale of w_T J_T (0 in chasing, 1 once the PIT is committed).
    pub target_weight: f64,
}

impl Reference {
    /// An idle reference for a horizon of `n` steps.
    #[must_use]
    pub fn new(n: usize) -> Self {
        Self {
            stages: vec![StageReference::idle(); n],
            target_heading: 0.0,
            target_weight: 0.0,
        }
    }
}

/// The default contact point's position along the target (its body x, m): `0.3 m` behind
/// the rear axle (the rear quarter panel), at least `0.2 m` ahead of the rear bumper.
#[must_use]
pub fn rear_quarter_x(params: &ParamSet) -> f64 {
    let t = &params.target;
    let rear_bumper = -(t.length - t.cg_to_front);
    (-t.lr - 0.3).max(rear_bumper + 0.2)
}

/// The contact pose of the PIT: the bullet's front corner on the target's side at the rear
/// quarter ([`rear_quarter_x`]), pushed `overlap` in.
#[must_use]
pub fn pit_stage(
    params: &ParamSet,
    side: Side,
    contact_angle: f64,
    overlap: f64,
    rel_speed: f64,
    fn_corridor: (f64, f64),
) -> StageReference {
    pit_stage_at(
        params,
        side,
        rear_quarter_x(params),
        contact_angle,
        overlap,
        rel_speed,
        fn_corridor,
    )
}

/// The contact pose with the bullet's inner front corner at `x_c` along the target's side
/// (body x, m), turned into the target by `contact_angle`, pushed `overlap` in.
#[must_use]
pub fn pit_stage_at(
    params: &ParamSet,
    side: Side,
    x_c: f64,
    contact_angle: f64,
    overlap: f64,
    rel_speed: f64,
    fn_corridor: (f64, f64),
) -> StageReference {
    let t = &params.target;
    let b = &params.bullet;
    let s = side.sign();
    // Contact point on the target's side, in the target frame.
    let p_c = Vec2::new(x_c, s * (0.5 * t.width - overlap));
    // The bullet turned into the target by the contact angle; its inner front corner at p_c.
    let rel_heading = -s * contact_angle;
    let corner = Vec2::new(b.cg_to_front, -s * 0.5 * b.width);
    let rel_pos = p_c - rotate(rel_heading, corner);
    StageReference {
        rel_pos,
        rel_heading,
        rel_speed,
        track: 1.0,
        fn_lo: fn_corridor.0,
        fn_hi: fn_corridor.1,
        envelope_lat: 0.5 * b.width,
    }
}

/// The default h_ref when the upper layer is off (the paper's "PicoPINN + cMPC without upper
/// layer"): a fixed PIT geometry approached along a simple staged path computed from the
/// current relative pose. The bullet first closes longitudinally at `approach_speed` on a
/// stand-off line `standoff` metres outside the contact line, heading parallel to the
/// target; within `engage_distance` of the contact station it turns in to the contact pose
/// (the corner on the rear quarter, `contact_angle` into the target) and the force corridor
/// opens. Everything is in the target's frame, so it follows the target as it moves.
#[derive(Debug, Clone, PartialEq)]
pub struct DefaultPit {
    pub side: Side,
    pub contact_angle: f64,
    pub overlap: f64,
    pub standoff: f64,
    pub approach_speed: f64,
    pub push_speed: f64,
    pub engage_distance: f64,
    pub fn_corridor: (f64, f64),
    /// The contact pose (from [`pit_stage`]).
    contact: StageReference,
}

impl DefaultPit {
    #[must_use]
    pub fn new(params: &ParamSet, side: Side) -> Self {
        let contact_angle = 12f64.to_radians();
        let overlap = 0.05;
        let push_speed = 1.0;
        let fn_corridor = (2000.0, 15000.0);
        Self {
            side,
            contact_angle,
            overlap,
            standoff: 0.6,
            approach_speed: 2.0,
            push_speed,
            engage_distance: 1.5,
            fn_corridor,
            contact: pit_stage(
                params,
                side,
                contact_angle,
                overlap,
                push_speed,
                fn_corridor,
            ),
        }
    }

    /// Fill `r` for the current target state `xt` (`[vx, vy, ψ, r, p, φ, X, Y]`) and bullet
    /// state `xb` (`[X, Y, ψ, vx, vy, r]`); `dt` is the MPC step, `lane_heading` the road's
    /// heading at the target (the reversed heading is measured from it).
    pub fn fill(&self, r: &mut Reference, xt: &[f64], xb: &[f64], dt: f64, lane_heading: f64) {
        let (sn, cs) = xt[2].sin_cos();
        let d = Vec2::new(xb[0] - xt[6], xb[1] - xt[7]);
        let rel = Vec2::new(cs * d.x + sn * d.y, -sn * d.x + cs * d.y);
        let s = self.side.sign();
        let c = &self.contact;
        let stand_y = c.rel_pos.y + s * self.standoff;
        let engaged = (c.rel_pos.x - rel.x).abs() < self.engage_distance
            && (rel.y - c.rel_pos.y) * s < self.standoff + 1.0;
        for (k, st) in r.stages.iter_mut().enumerate() {
            let t = (k + 1) as f64 * dt;
            // Longitudinal station: close at the approach speed, never past the contact.
            let gap_x = c.rel_pos.x - rel.x;
            let x_ref = rel.x + gap_x.signum() * (self.approach_speed * t).min(gap_x.abs());
            let near = (c.rel_pos.x - x_ref).abs() < self.engage_distance;
            if engaged || near {
                *st = *c;
                if !engaged {
                    st.fn_lo = 0.0;
                }
            } else {
                *st = StageReference {
                    rel_pos: Vec2::new(x_ref, stand_y),
                    rel_heading: 0.0,
                    rel_speed: self.approach_speed * gap_x.signum(),
                    track: 1.0,
                    fn_lo: 0.0,
                    fn_hi: 0.0,
                    envelope_lat: 1.5,
                };
            }
        }
        r.target_heading = lane_heading + s * std::f64::consts::PI;
        r.target_weight = if engaged { 1.0 } else { 0.0 };
    }
}
