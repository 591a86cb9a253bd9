//! Judging a push without optimising it: the feasibility test of a candidate, a given
//! push on the plan's criteria (diagnostics), the free motion (no force) and the closed
//! loop's test whether the push under way has done its work.

use super::*;

impl Planner {
    /// The feasibility test of a candidate: terminal heading within `heading_tol`, road and
    /// stopping-point margins and obstacle clearance within `violation_tol`.
    pub(super) fn acceptable(&self, heading_error: f64, margins: [f64; 2], clearance: f64) -> bool {
        let tol = self.settings.violation_tol;
        heading_error <= self.settings.heading_tol
            && margins.iter().all(|&m| m >= -tol)
            && clearance >= self.settings.obstacle_clearance - tol
    }

    /// Judge a given push on the plan's criteria, without optimising it: the forces
    /// `forces[j] = [F_n, F_t]` (N) act over plan steps `start + j` (at most the window's
    /// steps; the rest of the window is free) on `side` at the rear-quarter point, the
    /// target's driver as the settings say. The planner's package is left as it was. For
    /// diagnostics (`examples/oracle_surrogate`: which single shoves the upper layer would
    /// call feasible).
    ///
    /// # Errors
    /// [`PlanError`] for bad input, and [`PlanError::TooManyForces`] for more forces than
    /// the window has steps, or a window past the look-ahead.
    pub fn judge(
        &mut self,
        input: &PlannerInput<'_>,
        side: Side,
        start: usize,
        forces: &[Vec2],
    ) -> Result<Judgement, PlanError> {
        check_input(input)?;
        if forces.iter().any(|f| !f.x.is_finite() || !f.y.is_finite()) {
            return Err(PlanError::NonFiniteState);
        }
        if forces.len() > self.w || start + self.w > self.n {
            return Err(PlanError::TooManyForces);
        }
        let lane = self.begin(input);
        self.setup_candidate(side, start, lane);
        self.forces.iter_mut().for_each(|f| *f = Vec2::zeros());
        self.forces[..forces.len()].copy_from_slice(forces);
        self.rollout(Some(input.road), &input.target, false, false);
        self.linearise_rows(input.road, input.obstacles);
        let (_, _, road_margin, clearance, stop_margin) = self.merit(false);
        let heading_error =
            projected_heading_error(&self.xs[self.n], self.yaw_decay(), self.psi_rev);
        Ok(Judgement {
            heading_error,
            road_margin,
            clearance,
            stop_margin,
            feasible: self.acceptable(heading_error, [road_margin, stop_margin], clearance),
        })
    }

    /// The free prediction (no force) from `input`, judged: whether the target, left alone
    /// now, reaches the terminal set (reversed heading, inside the road, clear of the
    /// obstacles). Leaves `self.xs` the free prediction and `self.inside` the side the
    /// bullet works on: inside the curve ahead, or on a straight against the target's own
    /// drift ([`Self::against_drift`]); the package is not touched.
    pub(super) fn free_rollout_reverses(&mut self, input: &PlannerInput<'_>, lane: f64) -> bool {
        let curve = self.curve;
        self.inside = curve.filter(|&side| self.side_open(side, input));
        let reverses = self.free_rollout_within(input, lane, self.settings.heading_tol, true);
        if self.inside.is_none() {
            self.inside = self.against_drift(input);
        }
        if self.inside.is_none() && curve.is_none() {
            self.inside = self.roomier_side(input);
        }
        reverses
    }

    /// As [`Self::free_rollout_reverses`] with the terminal heading within `heading_tol`;
    /// the stopping point beyond the look-ahead is judged only `with_stop`.
    fn free_rollout_within(
        &mut self,
        input: &PlannerInput<'_>,
        lane: f64,
        heading_tol: f64,
        with_stop: bool,
    ) -> bool {
        let side = input.side.unwrap_or_else(|| self.bullet_side(input));
        self.setup_candidate(side, self.n, lane);
        self.forces.iter_mut().for_each(|f| *f = Vec2::zeros());
        self.rollout(Some(input.road), &input.target, false, false);
        self.linearise_rows(input.road, input.obstacles);
        let (_, heading_error, road_margin, clearance, stop_margin) = self.merit(false);
        let stop_margin = if with_stop {
            stop_margin
        } else {
            f64::INFINITY
        };
        heading_error <= heading_tol
            && self.acceptable(heading_error, [road_margin, stop_margin], clearance)
    }

    /// Whether the push under way has done its work: the target, left alone from now,
    /// reaches the reversed heading inside the road and clear of the obstacles over the
    /// look-ahead (the test the plan begins with, but for the stopping point beyond it). The
    /// closed loop of the push: the controller asks it every step in contact and lets go the
    /// first time it holds, instead of pushing on to the next replan. The package is not
    /// touched.
    ///
    /// A free rollout that ends slower than `release.rest_speed` needs its heading within
    /// `release.rest_heading_tol` ([`Release`]).
    ///
    /// The stopping point is left out because pushing on cannot bring it back: a push whose
    /// heading is done only turns the target further, and a push held until the stopping
    /// point came inside the road over-rotated the target instead (full-size scenes, paired:
    /// 27 saved and 3 lost of 1913 by leaving it out, docs/RESULTS.md).
    ///
    /// # Errors
    /// [`PlanError`] for bad input (a non-finite state, too many obstacles).
    pub fn push_done(
        &mut self,
        input: &PlannerInput<'_>,
        release: &Release,
    ) -> Result<bool, PlanError> {
        check_input(input)?;
        let lane = self.begin(input);
        if !self.free_rollout_within(input, lane, release.heading_tol, false) {
            return Ok(false);
        }
        let xn = &self.xs[self.n];
        let at_rest = xn[idx::VX].hypot(xn[idx::VY]) < release.rest_speed;
        Ok(!at_rest
            || projected_heading_error(xn, self.yaw_decay(), self.psi_rev)
                <= release.rest_heading_tol)
    }
}
