//! Whether the bullet may chase beside the target: its way to its stand-off pose beside the
//! target's predicted path, and that pose until the push it is chasing for is over, must
//! stay clear of the obstacles; otherwise it holds back behind the target (a car parked in
//! the next lane that the target passes would be in its way). Road edges are not checked
//! here: the side with no room beside the target is not chased on (`Planner`'s side
//! choice), and holding back for an edge predicted seconds ahead on a curve was measured to
//! cost more chases than it saved.
//!
//! The target's path is the planner's free rollout (no force, the look-ahead of N steps)
//! and beyond it the last predicted state held: constant speed in the body frame and
//! constant yaw rate (a target on a curve keeps turning with it, a driverless one with its
//! fixed steer keeps drifting). Obstacles move at constant velocity, as everywhere in the
//! planner.

use dynamics::contact::obb_signed_distance;
use dynamics::geometry::{Obb, Pose2, Vec2};
use dynamics::params::ParamSet;
use dynamics::road::Obstacle;
use dynamics::target::idx;
use dynamics::TargetState;

/// How often along the predicted path the stand-off pose is checked (s).
const SAMPLE: f64 = 0.25;

/// How long after the push window the bullet is still beside the target, falling back (s).
pub(crate) const FALL_BACK: f64 = 0.5;

/// How long before its earliest arrival the bullet is already beside the target (s): the
/// stand-off pose is checked from then on.
pub(crate) const BESIDE: f64 = 1.0;

/// The longest the stand-off pose is checked ahead (s).
pub(crate) const LOOK: f64 = 5.0;

/// The stand-off pose on one side, in the target's frame: the bullet's c.g. and heading
/// relative to the target.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct StandOff {
    pub rel_pos: Vec2,
    pub rel_heading: f64,
}

/// The path to check: the free rollout `xs` (step `dt`, `xs[0]` now at `time`) and the
/// obstacles.
pub(crate) struct Path<'a> {
    pub xs: &'a [TargetState],
    pub dt: f64,
    pub time: f64,
    pub obstacles: &'a [Obstacle],
}

impl Path<'_> {
    /// The target's predicted pose `t` seconds from now (`t` ≥ 0): the rollout's, and past
    /// its end the last state moved on at constant body velocity and yaw rate.
    fn target_pose(&self, t: f64) -> Pose2 {
        let n = self.xs.len() - 1;
        let k = (t / self.dt).floor();
        if k < n as f64 {
            let k = k as usize;
            let (a, b) = (&self.xs[k], &self.xs[k + 1]);
            let w = t / self.dt - k as f64;
            let lerp = |i: usize| a[i] + w * (b[i] - a[i]);
            return Pose2::new(lerp(idx::X), lerp(idx::Y), lerp(idx::PSI));
        }
        let x = &self.xs[n];
        let left = t - n as f64 * self.dt;
        let (vx, vy, r) = (x[idx::VX], x[idx::VY], x[idx::R]);
        let psi0 = x[idx::PSI];
        // Exact integration of a constant body velocity under a constant yaw rate.
        let psi1 = psi0 + r * left;
        let (dx, dy) = if r.abs() < 1e-6 {
            let (s, c) = psi0.sin_cos();
            ((vx * c - vy * s) * left, (vx * s + vy * c) * left)
        } else {
            let (s0, c0) = psi0.sin_cos();
            let (s1, c1) = psi1.sin_cos();
            (
                (vx * (s1 - s0) + vy * (c1 - c0)) / r,
                (-vx * (c1 - c0) + vy * (s1 - s0)) / r,
            )
        };
        Pose2::new(x[idx::X] + dx, x[idx::Y] + dy, psi1)
    }

    /// The first time (s from now, sampled every [`SAMPLE`] from `from` to `to`) at which the
    /// bullet at `stand` beside the predicted target would have its footprint within
    /// `clearance` of an obstacle; `None` if it stays clear.
    pub fn blocked_at(
        &self,
        params: &ParamSet,
        stand: StandOff,
        span: (f64, f64),
        clearance: f64,
    ) -> Option<f64> {
        self.route_blocked_at(params, |_| stand, span, clearance)
    }

    /// [`Path::blocked_at`] for a bullet moving relative to the target: `route(t)` is its
    /// pose in the target's frame `t` seconds from now (its approach to the stand-off pose).
    pub fn route_blocked_at(
        &self,
        params: &ParamSet,
        route: impl Fn(f64) -> StandOff,
        (from, to): (f64, f64),
        clearance: f64,
    ) -> Option<f64> {
        let b = &params.bullet;
        let steps = ((to - from) / SAMPLE).ceil().max(0.0) as usize;
        (0..=steps)
            .map(|i| (from + i as f64 * SAMPLE).min(to))
            .find(|&t| {
                let pose = self.target_pose(t);
                let stand = route(t);
                let c = pose.world_from_body(stand.rel_pos);
                let fp = Obb::vehicle_footprint(
                    &Pose2::new(c.x, c.y, pose.yaw + stand.rel_heading),
                    b.length,
                    b.width,
                    b.cg_to_front,
                );
                self.obstacles
                    .iter()
                    .any(|o| obb_signed_distance(&fp, &o.footprint_at(self.time + t)) < clearance)
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn straight_state(v: f64, psi: f64, r: f64) -> TargetState {
        let mut x = TargetState::zeros();
        x[idx::VX] = v;
        x[idx::PSI] = psi;
        x[idx::R] = r;
        x
    }

    #[test]
    fn the_path_past_the_rollout_keeps_speed_and_yaw_rate() {
        let (v, r, dt) = (15.0, 0.1, 0.05);
        // A rollout of a steady turn, then its continuation must stay on the same circle.
        let xs: Vec<TargetState> = (0..=40)
            .map(|k| {
                let t = k as f64 * dt;
                let mut x = straight_state(v, r * t, r);
                x[idx::X] = v / r * (r * t).sin();
                x[idx::Y] = v / r * (1.0 - (r * t).cos());
                x
            })
            .collect();
        let path = Path {
            xs: &xs,
            dt,
            time: 0.0,
            obstacles: &[],
        };
        for t in [0.0, 0.73, 2.0, 3.5] {
            let p = path.target_pose(t);
            assert!((p.yaw - r * t).abs() < 1e-9, "heading at {t}");
            let (ex, ey) = (v / r * (r * t).sin(), v / r * (1.0 - (r * t).cos()));
            assert!(
                (p.p_in_world.x - ex).abs() < 1e-3 && (p.p_in_world.y - ey).abs() < 1e-3,
                "{t}: {p:?} vs ({ex}, {ey})"
            );
        }
    }

    #[test]
    fn a_stand_off_pose_is_blocked_when_it_reaches_a_parked_car() {
        let params = ParamSet::builtin("full_size").unwrap();
        let (v, dt) = (15.0, 0.05);
        let xs: Vec<TargetState> = (0..=40)
            .map(|k| {
                let mut x = straight_state(v, 0.0, 0.0);
                x[idx::X] = 100.0 + v * k as f64 * dt;
                x
            })
            .collect();
        // A car parked in the left lane 25 m ahead of the target.
        let parked = [Obstacle {
            x: 125.0,
            y: 3.5,
            heading: 0.0,
            vx: 0.0,
            vy: 0.0,
            length: 4.5,
            width: 1.8,
        }];
        let path = |obstacles| Path {
            xs: &xs,
            dt,
            time: 0.0,
            obstacles,
        };
        let left = StandOff {
            rel_pos: Vec2::new(-4.0, 3.5),
            rel_heading: 0.0,
        };
        // The bullet's front reaches the car's rear (minus the clearance) after ~1.4 s.
        let t = path(&parked)
            .blocked_at(&params, left, (0.0, 4.0), 0.5)
            .unwrap();
        assert!((1.0..=2.0).contains(&t), "blocked at {t}");
        assert_eq!(
            path(&parked).blocked_at(&params, left, (0.0, 1.0), 0.5),
            None
        );
        assert_eq!(path(&[]).blocked_at(&params, left, (0.0, 4.0), 0.5), None);
        // On the other side, the parked car is never in the way.
        let right = StandOff {
            rel_pos: Vec2::new(-4.0, -3.5),
            rel_heading: 0.0,
        };
        assert_eq!(
            path(&parked).blocked_at(&params, right, (0.0, 4.0), 0.5),
            None
        );
        // A bullet 30 m behind the target in the left lane, closing at 5 m/s: it reaches the
        // car (55 m ahead of it, 5 m behind its stand-off pose's pass) after about 3.2 s,
        // which the pose beside the target never does; crossing to the target's line at
        // 2 m/s from the start, it passes the car in the middle lane.
        let closing = |t: f64| StandOff {
            rel_pos: Vec2::new(-30.0 + 5.0 * t, 3.5),
            rel_heading: 0.0,
        };
        let t = path(&parked)
            .route_blocked_at(&params, closing, (0.0, 5.0), 0.5)
            .unwrap();
        assert!((2.5..=3.5).contains(&t), "route blocked at {t}");
        let crossing = |t: f64| StandOff {
            rel_pos: Vec2::new(-30.0 + 5.0 * t, (3.5 - 2.0 * t).max(0.0)),
            rel_heading: 0.0,
        };
        assert_eq!(
            path(&parked).route_blocked_at(&params, crossing, (0.0, 5.0), 0.5),
            None
        );
    }
}
