//! h_ref(Π, x_T, x_B, C_F, C_B) → e_ref: the MPC's reference from the decision package.

use crate::approach::Profile;
use crate::package::{DecisionPackage, Mode};
use crate::settings::PlannerSettings;
use dynamics::bullet::BulletState;
use dynamics::geometry::{rotate, Pose2, Vec2};
use dynamics::target::idx;
use dynamics::TargetState;
use mpc::{Reference, StageReference};

/// How far behind its contact station (m, full size; × the length scale) a bullet drops
/// back: fully behind the target's rear bumper, where the target's own lane is its path.
pub const HOLD_BACK: f64 = 2.5;

/// The bullet's position relative to the target, in the target's frame.
#[must_use]
pub fn relative_position(xt: &TargetState, xb: &BulletState) -> Vec2 {
    Pose2::new(xt[idx::X], xt[idx::Y], xt[idx::PSI]).body_from_world(Vec2::new(xb[0], xb[1]))
}

/// The rate of [`relative_position`]: the bullet's c.g. velocity relative to the target's
/// body frame (which turns at the target's yaw rate), in that frame.
#[must_use]
pub fn relative_velocity(xt: &TargetState, xb: &BulletState) -> Vec2 {
    let rel = relative_position(xt, xb);
    let vb = rotate(xb[2] - xt[idx::PSI], Vec2::new(xb[3], xb[4]));
    let r = xt[idx::R];
    vb - Vec2::new(xt[idx::VX], xt[idx::VY]) - Vec2::new(-r * rel.y, r * rel.x)
}

/// When the reference is for: the control step's time, the MPC's step, and the target's
/// heading when the push began (the PIT phase's frame; `None` before it); and the
/// vehicles' length scale (`crate::length_scale`: 1 at full size), which scales the
/// reference's built-in lengths (and its fall-back speed by the square root); and whether
/// the bullet is to back off first (a push that did nothing, tried again: it falls back
/// as in stabilisation until the vehicles are apart).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Timing {
    pub time: f64,
    pub dt: f64,
    pub pit_frame: Option<f64>,
    pub length_scale: f64,
    pub back_off: bool,
}

/// Fill the MPC reference for the control step at `time` (stage k refers to
/// `time + (k + 1)·dt`).
///
/// * PIT: close in on the stand-off line beside the contact station so as to arrive
///   `turn_in` before the window, turn in to the contact pose (C_B), hold it over the
///   window T_c with the planned force corridor C_F, then fall back behind and outside.
///   Over the window the contact pose is fixed in the target's frame at the start of the
///   push (`pit_frame`, its heading then; `None` takes the plan's heading at the window's
///   start), relative to the target's c.g. or, with `push_round`, to its rear-quarter
///   contact point (which turns with the target: the bullet keeps pushing the tail round).
///   The target objective tracks the planned heading at the end of the MPC's horizon
///   (the virtual rollout's prediction), so the MPC pushes as much as the plan needs.
/// * Chase (and abort, while the controller's patience lasts): close in to the stand-off
///   line beside the contact station and wait there, no force.
/// * Stabilise: fall back, no force, no target objective.
pub fn fill_reference(
    pkg: &DecisionPackage,
    s: &PlannerSettings,
    r: &mut Reference,
    xt: &TargetState,
    xb: &BulletState,
    at: Timing,
) {
    let Timing {
        time,
        dt,
        pit_frame,
        length_scale: ls,
        back_off,
    } = at;
    let rel = relative_position(xt, xb);
    let psi_now = xt[idx::PSI];
    let side = pkg.side.sign();
    let contact = StageReference {
        rel_pos: pkg.contact_rel_pos,
        rel_heading: pkg.contact_rel_heading,
        rel_speed: pkg.push_speed,
        track: 1.0,
        fn_lo: 0.0,
        fn_hi: 0.0,
        envelope_lat: pkg.envelope_lat,
    };
    let stand = Vec2::new(contact.rel_pos.x, contact.rel_pos.y + side * pkg.standoff);
    // Fully behind the target's rear bumper (the contact station is at its rear quarter).
    let behind_x = contact.rel_pos.x - HOLD_BACK * ls;
    let back = StageReference {
        rel_pos: Vec2::new(
            contact.rel_pos.x - 3.0 * ls,
            contact.rel_pos.y + side * (pkg.standoff + 1.0 * ls),
        ),
        rel_heading: 0.0,
        rel_speed: -2.0 * ls.sqrt(),
        track: 0.3,
        fn_lo: 0.0,
        fn_hi: 0.0,
        envelope_lat: 1.0e3,
    };
    let n = r.stages.len();
    let horizon_end = time + n as f64 * dt;
    if back_off {
        r.stages.iter_mut().for_each(|st| *st = back);
        r.target_heading = pkg.terminal.heading;
        r.target_weight = 0.0;
        return;
    }
    match pkg.mode {
        Mode::Pit => {
            let (t0, t1) = pkg.window;
            let approach = Approach::new(pkg, rel, stand, time, behind_x, ls);
            for (k, st) in r.stages.iter_mut().enumerate() {
                let tau = time + (k + 1) as f64 * dt;
                *st = if tau < t0 - s.turn_in {
                    approach.stage(tau)
                } else if tau <= t1 {
                    let (lo, hi) = pkg.step_at(tau.max(t0)).map_or((0.0, 0.0), |p| p.corridor);
                    // The contact pose is held in the target's frame as it was when the
                    // push began (`pit_frame`): the bullet follows the target's c.g. but
                    // not its rotation, so it keeps its heading and pushes on while the
                    // rear quarter swings away, as a driver does in a PIT (`push_round`: it
                    // follows the rear quarter instead and pushes it round). Stage k refers
                    // the pose to the target's heading predicted by the plan.
                    let psi0 = pit_frame.unwrap_or_else(|| pkg.heading_at(t0).unwrap_or(psi_now));
                    let psi_tau = psi_now + pkg.heading_at(tau).unwrap_or(0.0)
                        - pkg.heading_at(time).unwrap_or(0.0);
                    let anchor = if s.push_round {
                        pkg.contact_point
                    } else {
                        Vec2::zeros()
                    };
                    let rel_world = rotate(psi0, contact.rel_pos - anchor);
                    StageReference {
                        rel_pos: anchor + rotate(-psi_tau, rel_world),
                        rel_heading: psi0 + contact.rel_heading - psi_tau,
                        fn_lo: if tau >= t0 { lo } else { 0.0 },
                        fn_hi: hi,
                        ..contact
                    }
                } else {
                    back
                };
            }
            r.target_heading = pkg.heading_at(horizon_end).unwrap_or(pkg.terminal.heading);
            r.target_weight = if horizon_end >= t0 { 1.0 } else { 0.0 };
        }
        // An infeasible decision while chasing: keep station behind (the controller aborts
        // after its patience).
        Mode::Chase | Mode::Abort => {
            // Held back (the stand-off pose is blocked ahead): behind the target, on its
            // line, moving across only once behind it.
            let goal = if pkg.hold_back {
                Vec2::new(behind_x, 0.0)
            } else {
                stand
            };
            let mut approach = Approach::new(pkg, rel, goal, time, behind_x, ls);
            approach.across_behind = pkg.hold_back;
            for (k, st) in r.stages.iter_mut().enumerate() {
                let tau = time + (k + 1) as f64 * dt;
                *st = approach.stage(tau);
            }
            r.target_heading = pkg.terminal.heading;
            r.target_weight = 0.0;
        }
        Mode::Stabilise => {
            r.stages.iter_mut().for_each(|st| *st = back);
            r.target_heading = pkg.terminal.heading;
            r.target_weight = 0.0;
        }
    }
}

/// The approach: along the target by the package's [`Profile`] (planned when the package
/// was, arriving at rest relative to the target at the contact station: the reference is a
/// trajectory in time, so the MPC cannot put off braking by re-planning it from wherever
/// the bullet has got to), across from the current relative position `rel` (at `time`) to
/// `goal` at no more than the package's `lateral_speed`, and kept behind `behind_x`
/// while it is more than a metre (full size; × `length_scale`) off the goal's line (so that
/// a bullet changing lanes behind the target does not close in on its rear first), then
/// held.
#[derive(Debug, Clone, Copy)]
struct Approach {
    rel: Vec2,
    goal: Vec2,
    time: f64,
    along: Profile,
    /// When `along` starts (the package's planning time).
    along_from: f64,
    lateral_speed: f64,
    behind_x: f64,
    length_scale: f64,
    /// Hold the current lateral position until the bullet is behind `behind_x`.
    across_behind: bool,
}

impl Approach {
    fn new(
        pkg: &DecisionPackage,
        rel: Vec2,
        goal: Vec2,
        time: f64,
        behind_x: f64,
        length_scale: f64,
    ) -> Self {
        Self {
            rel,
            goal,
            time,
            along: pkg.approach,
            along_from: pkg.time,
            lateral_speed: pkg.lateral_speed,
            behind_x,
            length_scale,
            across_behind: false,
        }
    }

    /// The stage at time `tau`.
    fn stage(&self, tau: f64) -> StageReference {
        let (rel, goal) = (self.rel, self.goal);
        let reach = if self.across_behind && rel.x > self.behind_x {
            0.0
        } else {
            self.lateral_speed * (tau - self.time).max(0.0)
        };
        let y = rel.y + (goal.y - rel.y).clamp(-reach, reach);
        let (mut x, mut v) = self.along.at(tau - self.along_from);
        if (goal.y - y).abs() > self.length_scale {
            let cap = self.behind_x.max(rel.x);
            if x > cap {
                // Held behind the rear bumper until the bullet is on the goal's line: no
                // closing speed there either (it would drive the bullet into the target's
                // rear against the position it is held at).
                x = cap;
                v = v.min(0.0);
            }
        }
        StageReference {
            rel_pos: Vec2::new(x, y),
            rel_heading: 0.0,
            rel_speed: v,
            track: 1.0,
            fn_lo: 0.0,
            fn_hi: 0.0,
            envelope_lat: 1.5 * self.length_scale,
        }
    }
}
