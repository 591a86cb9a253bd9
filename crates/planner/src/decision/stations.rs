//! Where the bullet pushes and when it can: its contact poses along the target's rear
//! quarter, where it touches, its earliest arrival at a station (the approach profile),
//! which sides are open to it (room beside the target, obstacles along the stand-off pose,
//! holding back), and which side it works on (the inside of a curve, against a driverless
//! target's drift, the roomier side of a straight).

use super::*;

/// Radius (m, full size) below which the road counts as a curve for the side choice
/// ([`Planner::curve_side`]).
const CURVE_RADIUS: f64 = 1000.0;

/// How far ahead the side choice looks for a curve (s at the target's speed).
const CURVE_LOOK: f64 = 4.0;

/// Drift across a straight road (m, full size) over [`CURVE_LOOK`] beyond which the side
/// choice works against it ([`Planner::drift_side`]).
const DRIFT_MIN: f64 = 1.0;

/// How long (s) the target's steer must stay as it was at the first plan for the planner
/// to take it as held (a driver off the controls) and to work against its drift.
const DRIFT_WATCH: f64 = 0.9;

/// Difference (m, full size) between the road beyond the target on its two sides above
/// which the bullet works on the roomier side of a straight ([`Planner::roomier_side`]).
const ROOM_MIN: f64 = 3.0;

/// The side choice against the target's own drift ([`Planner::against_drift`]): decided
/// once per maneuver.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Drift {
    /// No plan yet.
    Unseen,
    /// The time and the target's steer at the first plan.
    Watching(f64, f64),
    Decided(Option<Side>),
}

impl Planner {
    /// The bullet's contact pose on `side` (target frame) at the current candidate's contact
    /// point.
    pub(super) fn contact_pose(&self, side: Side) -> mpc::StageReference {
        self.contact_pose_at(side, self.contact_x)
    }

    /// The bullet's contact pose on `side` (target frame) at the contact point's body x `x_c`.
    pub(super) fn contact_pose_at(&self, side: Side, x_c: f64) -> mpc::StageReference {
        let s = &self.settings;
        pit_stage_at(
            &self.params,
            side,
            x_c,
            s.contact_angle,
            s.overlap,
            s.push_speed,
            (0.0, self.force_max),
        )
    }

    /// The bullet's stand-off (m) beside the contact line on `side`: `outside_standoff` on
    /// the outside of the curve the target is on or coming to, where the road's adhesion is
    /// `outside_standoff_mu` or more; else `standoff`.
    pub(super) fn standoff(&self, side: Side) -> f64 {
        if self.curve.is_some_and(|c| c != side) && self.mu >= self.settings.outside_standoff_mu {
            self.settings.outside_standoff
        } else {
            self.settings.standoff
        }
    }

    /// The contact point's body x for offset `offset` from the rear quarter (clamped as
    /// [`Self::clamp_contact_x`]).
    pub(super) fn contact_x_at(&self, offset: f64) -> f64 {
        self.clamp_contact_x(rear_quarter_x(&self.params) + offset)
    }

    /// A contact point's body x clamped to the target's side, at least 0.2 m (full size;
    /// × the length scale) from either bumper.
    pub(super) fn clamp_contact_x(&self, x: f64) -> f64 {
        let t = &self.params.target;
        let clear = 0.2 * self.len_scale;
        x.clamp(-(t.length - t.cg_to_front) + clear, t.cg_to_front - clear)
    }

    /// Earliest time (s from now) the bullet can be at a contact pose on `side`, and the
    /// contact point's body x there. The contact point is the one of the band the planner
    /// tries (`contact_offsets` from the rear quarter) nearest to where the bullet would come
    /// to rest relative to the target if it braked now: a bullet waiting a little behind the
    /// rear-quarter station, or one that will stop a little short of it, is already at a
    /// station. The time is the approach along the target ([`Profile`], from the bullet's
    /// relative position and speed, arriving at rest relative to the target; nothing for a
    /// bullet waiting within `ARRIVAL_TOL` of the band, and only its stop for one drifting
    /// away from its station that would come to rest within it), moving across
    /// at the crossing speed ([`Self::crossing_speed`]) at the same time, plus a settling
    /// time; crossing behind the target to the other side first drops back behind its rear
    /// bumper.
    pub(super) fn earliest_arrival(
        &self,
        side: Side,
        road: &Road,
        xt: &TargetState,
        xb: &BulletState,
    ) -> (f64, f64) {
        let s = &self.settings;
        let x0 = self.contact_x_at(0.0);
        let (lo, hi) = s
            .contact_offsets
            .iter()
            .map(|&o| self.contact_x_at(o))
            .fold((x0, x0), |(lo, hi), x| (lo.min(x), hi.max(x)));
        let c = self.contact_pose_at(side, x0);
        let rel = crate::href::relative_position(xt, xb);
        let rel_vel = crate::href::relative_velocity(xt, xb);
        let (a, cap) = (s.approach_accel(self.mu), s.approach_speed);
        let stop = rel.x + rel_vel.x * rel_vel.x.abs() / (2.0 * a);
        let x_c = (x0 + stop - c.rel_pos.x).clamp(lo, hi);
        let goal = c.rel_pos.x + x_c - x0;
        let dx = (goal - rel.x).abs();
        // The stand-off beyond the built-in one is closed by the turn-in, not the approach.
        let extra = self.standoff(side) - s.standoff;
        let off_line = (c.rel_pos.y - rel.y).abs();
        let dy = (off_line - extra).max(0.0);
        let k = self.len_scale;
        // A bullet waiting within `ARRIVAL_TOL` of the band (the MPC holds it a few tenths of
        // a metre off its station, swaying at a few tenths of a metre per second) has
        // arrived along the target: the turn-in closes the rest. Neither closing that gap
        // first nor stopping the sway is an approach: at the approach's gentle acceleration
        // on low adhesion either would take longer than the look-ahead leaves for a window,
        // plan after plan. One still closing in has not arrived.
        let tol = ARRIVAL_TOL * k;
        let (band_lo, band_hi) = (c.rel_pos.x + lo - x0 - tol, c.rel_pos.x + hi - x0 + tol);
        let in_band = |x: f64| (band_lo..=band_hi).contains(&x);
        let waiting = rel_vel.x.abs() < WAITING_SPEED * k.sqrt();
        let arrived = waiting && in_band(rel.x);
        // Nor is one in the band drifting away from its station that would come to rest in
        // the band: it arrives when it has stopped (|v|/a), where it would be waiting.
        // Brought back to the station first, a bullet running 0.65 m/s past the band on a
        // slippery road was 1.7 s from it, no window fitted, and the chase's braking left it
        // metres behind (`picopit trace sc-00093`). One closing in on its station keeps its
        // approach: committed early, it struck nearer the target's centre of mass, harder,
        // and lost textbook pushes.
        let drifting_off = rel_vel.x * (goal - rel.x) < 0.0;
        let stops_in_band = drifting_off && in_band(rel.x) && in_band(stop);
        // Touching counts on the side the bullet is on only: a bullet pressing on the
        // target's right has not arrived on its left (a plan in contact that was not yet
        // committed to a side took the far side's push for one under way).
        let own_side = side.sign() * rel.y >= 0.0;
        // At the contact pose by the bullet's true offset: the width taken off `dy` is
        // still to be crossed.
        if dx.hypot(off_line) < 0.3 * k || (own_side && self.gap(xt, xb) < 0.1 * k) {
            // At the contact pose, or touching already: a PIT under way.
            return (0.0, x_c);
        }
        let along = if !own_side {
            // On the other side: drop back behind the target's rear first.
            let behind = -(self.params.target.length - self.params.target.cg_to_front)
                - self.params.bullet.cg_to_front
                - 0.5 * k;
            // Level with the band already: back to where it would have stopped, in the band.
            let goal_along = if arrived {
                stop.clamp(band_lo, band_hi)
            } else {
                goal
            };
            Profile::new(rel.x, rel_vel.x, behind.min(rel.x), a, cap).time()
                + Profile::new(behind.min(rel.x), 0.0, goal_along, a, cap).time()
        } else if arrived {
            0.0
        } else if stops_in_band {
            rel_vel.x.abs() / a
        } else {
            Profile::new(rel.x, rel_vel.x, goal, a, cap).time()
        };
        let lateral = self.crossing_speed(side, road, xt, xb);
        (s.settle_time + along.max(dy / lateral), x_c)
    }

    /// How fast (m/s) the bullet's approach moves across relative to the target towards
    /// `side`: `lateral_speed` on its own side; `crossing_speed` plus the target's own
    /// drift across the road towards the bullet when the bullet crosses to the far side (a
    /// target drifting out of its lane passes in front of a bullet that holds its line: the
    /// bullet crosses behind it by keeping its course). The drift is the relative lateral speed of a bullet running
    /// along the road at its speed, in the target's frame. The crossing is no faster than
    /// the approach's relative speed cap `approach_speed` (a target heading straight across
    /// the road would otherwise ask for the bullet's whole speed sideways).
    #[must_use]
    pub fn crossing_speed(
        &self,
        side: Side,
        road: &Road,
        xt: &TargetState,
        xb: &BulletState,
    ) -> f64 {
        let s = &self.settings;
        let rel = crate::href::relative_position(xt, xb);
        if side.sign() * rel.y >= 0.0 {
            return s.lateral_speed;
        }
        let road_heading = road.project(Vec2::new(xt[idx::X], xt[idx::Y])).heading;
        let holding = rotate(
            road_heading - xt[idx::PSI],
            Vec2::new(xb[3].hypot(xb[4]), 0.0),
        );
        let drift = side.sign() * (holding.y - xt[idx::VY]);
        let cross = s.crossing_speed.max(s.lateral_speed);
        (cross + drift.max(0.0)).min(s.approach_speed.max(cross))
    }

    /// Lateral room (m) the bullet has on `side` at its stand-off pose beside the target's
    /// rear quarter: the road margin of that pose's outer edge (negative: over the edge).
    pub(super) fn side_room(&self, side: Side, input: &PlannerInput<'_>) -> f64 {
        let c = self.contact_pose(side);
        let pose = Pose2::new(
            input.target[idx::X],
            input.target[idx::Y],
            input.target[idx::PSI],
        );
        let outer =
            c.rel_pos.y + side.sign() * (self.settings.standoff + 0.5 * self.params.bullet.width);
        let p = pose.world_from_body(Vec2::new(c.rel_pos.x, outer));
        input.road.half_width() - input.road.project(p).d.abs()
    }

    /// Whether the bullet's stand-off pose on `side` beside the predicted target
    /// (`self.xs`: the free prediction) would come within the obstacle clearance of an
    /// obstacle while the bullet is beside the target: from [`chase::BESIDE`] before its
    /// earliest arrival until the push it chases for is over (the window and
    /// [`chase::FALL_BACK`] after the arrival, at most [`chase::LOOK`] ahead); or whether
    /// the bullet would, on its way there until then (along the target by the package's
    /// approach, across at its lateral speed): a stopped car in the bullet's lane that the
    /// target passes before the bullet is beside it is still in the bullet's way. Called
    /// after `fill_package`.
    pub(super) fn stand_off_blocked(&self, side: Side, input: &PlannerInput<'_>) -> bool {
        let s = &self.settings;
        let (t_arr, x_c) = self.earliest_arrival(side, input.road, &input.target, &input.bullet);
        let horizon = (t_arr + self.w as f64 * s.dt + chase::FALL_BACK).min(chase::LOOK);
        let c = self.contact_pose_at(side, x_c);
        let path = chase::Path {
            xs: &self.xs,
            dt: s.dt,
            time: input.time,
            obstacles: input.obstacles,
        };
        let stand = chase::StandOff {
            rel_pos: Vec2::new(c.rel_pos.x, c.rel_pos.y + side.sign() * self.standoff(side)),
            rel_heading: 0.0,
        };
        let from = (t_arr - chase::BESIDE).clamp(0.0, horizon);
        if path
            .blocked_at(&self.params, stand, (from, horizon), s.obstacle_clearance)
            .is_some()
        {
            return true;
        }
        // On its way there: along the target by the package's approach, across at its
        // lateral speed.
        let rel = crate::href::relative_position(&input.target, &input.bullet);
        let (along, lat) = (self.package.approach, self.package.lateral_speed);
        let route = |t: f64| chase::StandOff {
            rel_pos: Vec2::new(
                along.at(t).0,
                rel.y + (stand.rel_pos.y - rel.y).clamp(-lat * t, lat * t),
            ),
            rel_heading: 0.0,
        };
        path.route_blocked_at(&self.params, route, (0.0, from), s.obstacle_clearance)
            .is_some()
    }

    /// Make the package's chase hold back behind the target: its approach goes to
    /// [`crate::href::HOLD_BACK`] behind the contact station, and it crosses to the
    /// target's line at least at `crossing_speed` (an obstacle ahead is on its way).
    pub(super) fn hold_back(&mut self, input: &PlannerInput<'_>) {
        let s = &self.settings;
        let p = &mut self.package;
        p.hold_back = true;
        p.lateral_speed = p.lateral_speed.max(s.crossing_speed);
        p.approach = Profile::with_brake_margin(
            crate::href::relative_position(&input.target, &input.bullet).x,
            crate::href::relative_velocity(&input.target, &input.bullet).x,
            p.contact_rel_pos.x - crate::href::HOLD_BACK * self.len_scale,
            s.approach_accel(self.mu),
            s.approach_speed,
            BRAKE_MARGIN,
        );
    }

    /// On a curve, the side of the target towards the curve's centre, where the bullet
    /// pushes from when it has room there: its push turns the target's nose into the
    /// curve, so that its path bends with the road while it spins (pushed from the outside,
    /// the nose turns out and the spin carries it over the outer edge). The curve is the
    /// sharpest stretch of road the target reaches within [`CURVE_LOOK`] at its speed;
    /// `None` on a straight (radius beyond [`CURVE_RADIUS`]).
    pub(super) fn curve_side(&self, input: &PlannerInput<'_>) -> Option<Side> {
        let x = &input.target;
        let f = input.road.project(Vec2::new(x[idx::X], x[idx::Y]));
        let reach = x[idx::VX].hypot(x[idx::VY]) * CURVE_LOOK;
        let step = 5.0 * self.len_scale;
        let kappa = input
            .road
            .sharpest_curvature(f.s, step, 0..=(reach / step).floor() as i64);
        if kappa.abs() * CURVE_RADIUS * self.len_scale < 1.0 {
            return None;
        }
        Some(if kappa > 0.0 { Side::Left } else { Side::Right })
    }

    /// On a straight road, the side of the target with the more road beyond it, where the
    /// target will be at the end of the free prediction (`self.xs`): a rear-quarter push
    /// bends the spinning target's path towards the bullet's side, so the spin needs room
    /// there. `None` when the two sides' room differs by less than [`ROOM_MIN`], or when
    /// the bullet has no room beside the target on the roomier side.
    pub(super) fn roomier_side(&self, input: &PlannerInput<'_>) -> Option<Side> {
        let xn = &self.xs[self.n];
        let d = input.road.project(Vec2::new(xn[idx::X], xn[idx::Y])).d;
        // Room to the left edge is half_width − d, to the right half_width + d.
        if d.abs() < 0.5 * ROOM_MIN * self.len_scale {
            return None;
        }
        let side = if d < 0.0 { Side::Left } else { Side::Right };
        self.side_open(side, input).then_some(side)
    }

    /// The side against the target's drift, decided once per maneuver: at the first plan
    /// at least [`DRIFT_WATCH`] after the first, if the target's steer has not moved since
    /// (a driver off the controls holds it, so the free prediction that holds it is the
    /// target's path; a driver who steers, a lane keeper, is not predicted by a held
    /// command and keeps the bullet's side), by [`Self::drift_side`] then. `None` until
    /// decided, or when the bullet has no room on the chosen side now.
    pub(super) fn against_drift(&mut self, input: &PlannerInput<'_>) -> Option<Side> {
        let steer = input.target_input[0];
        match self.drift {
            Drift::Unseen => self.drift = Drift::Watching(input.time, steer),
            Drift::Watching(t0, s0) if input.time - t0 >= DRIFT_WATCH => {
                let held = (steer - s0).abs() < 1e-6;
                self.drift = Drift::Decided(if held { self.drift_side(input) } else { None });
            }
            _ => {}
        }
        match self.drift {
            Drift::Decided(Some(side)) => self.side_open(side, input).then_some(side),
            _ => None,
        }
    }

    /// On a straight road, the side away from the target's own drift across it: the free
    /// prediction (`self.xs`, the driver's command held) carried on along its arc (its
    /// course off the road's heading and its yaw rate) to [`CURVE_LOOK`] from now. A target
    /// that drifts more than [`DRIFT_MIN`] to one side is pushed from the other, so that its
    /// nose turns away from the edge it drifts to and its path bends back onto the road
    /// while it spins (the curve rule's reason, with the target's own curve in place of the
    /// road's). `None` when it drifts less, or when the bullet has no room on that side.
    pub(super) fn drift_side(&self, input: &PlannerInput<'_>) -> Option<Side> {
        let x0 = &input.target;
        let xn = &self.xs[self.n];
        let road = input.road;
        let d0 = road.project(Vec2::new(x0[idx::X], x0[idx::Y])).d;
        let f = road.project(Vec2::new(xn[idx::X], xn[idx::Y]));
        let v = xn[idx::VX].hypot(xn[idx::VY]);
        if v < 1.0 {
            return None;
        }
        let course = wrap(xn[idx::PSI] + xn[idx::VY].atan2(xn[idx::VX]) - f.heading);
        let kappa = xn[idx::R] / v - f.curvature;
        let t = (CURVE_LOOK - self.n as f64 * self.settings.dt).max(0.0);
        let drift = f.d + v * t * course.sin() + 0.5 * kappa * (v * t).powi(2) - d0;
        if drift.abs() < DRIFT_MIN * self.len_scale {
            return None;
        }
        let side = if drift > 0.0 { Side::Right } else { Side::Left };
        self.side_open(side, input).then_some(side)
    }

    /// Whether the bullet can line up on `side` inside the road (with the road margin).
    pub(super) fn side_open(&self, side: Side, input: &PlannerInput<'_>) -> bool {
        self.side_room(side, input) >= self.settings.road_margin
    }

    /// The side the bullet works on when no candidate decides it: the side it is on, unless
    /// the road leaves no room there and does on the other side.
    pub(super) fn bullet_side(&self, input: &PlannerInput<'_>) -> Side {
        let rel = Pose2::new(
            input.target[idx::X],
            input.target[idx::Y],
            input.target[idx::PSI],
        )
        .body_from_world(Vec2::new(input.bullet[0], input.bullet[1]));
        let own = if rel.y >= 0.0 {
            Side::Left
        } else {
            Side::Right
        };
        let other = own.other();
        if !self.side_open(own, input) && self.side_open(other, input) {
            other
        } else {
            own
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dynamics::target4dof::FourDofTarget;

    /// A bullet pressing on the target's right has arrived there, and only there: on the
    /// left it still has to drop back behind the target and cross. (Counting the touch on
    /// both sides let a plan in contact, not yet committed to a side, push from the far
    /// side: `sc-01226` was planned from the left while the bullet pushed on the right.)
    #[test]
    fn touching_the_target_is_an_arrival_on_its_own_side_only() {
        let params = ParamSet::builtin("full_size").unwrap();
        let s = PlannerSettings::default();
        let model = Box::new(FourDofTarget::new(&params.target, 0.9, s.dt));
        let p = Planner::new(&params, 0.9, model, s).unwrap();
        let road = Road::straight(3000.0, 3, 3.5, 1.0);
        let mut xt = TargetState::zeros();
        xt[idx::VX] = 20.0;
        xt[idx::X] = 100.0;
        // The bullet's inner front corner 2 cm into the target's right side, turned in by
        // 12° (the contact pose of `mpc::reference`).
        let x_touch = mpc::reference::rear_quarter_x(&params) + 0.9;
        let pose = mpc::reference::pit_stage_at(
            &params,
            Side::Right,
            x_touch,
            12f64.to_radians(),
            0.02,
            1.0,
            (0.0, 1.0),
        );
        let xb = dynamics::bullet::BulletState::from_column_slice(&[
            xt[idx::X] + pose.rel_pos.x,
            xt[idx::Y] + pose.rel_pos.y,
            pose.rel_heading,
            20.5,
            0.0,
            0.0,
        ]);
        assert!(p.gap(&xt, &xb) < 0.1, "touching: gap {}", p.gap(&xt, &xb));
        let (own, _) = p.earliest_arrival(Side::Right, &road, &xt, &xb);
        assert_eq!(own, 0.0, "in contact on its own side");
        let (far, _) = p.earliest_arrival(Side::Left, &road, &xt, &xb);
        assert!(far > 1.0, "the far side is a crossing away, not {far} s");
    }
}
