//! The phase machine: chasing → PIT → stabilisation → done, abort from any active phase.

use crate::package::{Infeasible, Mode};
use crate::settings::PhaseSettings;

/// A phase of the maneuver.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Phase {
    /// Reach the planned relative pose.
    Chasing,
    /// Hold the contact corridor over the window.
    Pit,
    /// Separate, keep clear, let the target settle.
    Stabilising,
    /// The target has settled (or the stabilisation timed out): the maneuver is over.
    Done,
    /// Stopped: the bullet brakes to a halt.
    Aborted,
}

impl Phase {
    /// Whether the maneuver is still running (chasing or PIT).
    #[must_use]
    pub fn is_active(self) -> bool {
        matches!(self, Self::Chasing | Self::Pit)
    }
}

/// Why the maneuver was aborted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AbortReason {
    /// The upper layer found no feasible PIT decision while chasing.
    DecisionInfeasible(Infeasible),
    /// No contact within the chasing timeout.
    ChaseTimeout,
    /// The safety monitor: the bullet's yaw rate or side slip beyond its limit.
    BulletUnstable,
    /// The safety monitor: the bullet too close to an obstacle.
    BulletClearance,
}

/// What the phase machine observes each control step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhaseObservation {
    pub time: f64,
    /// Signed distance between the two footprints (m; negative = overlapping).
    pub gap: f64,
    /// The upper layer's mode and window, if it runs.
    pub mode: Option<Mode>,
    pub infeasible: Option<Infeasible>,
    pub window: Option<(f64, f64)>,
    /// Target speed (m/s) and yaw rate (rad/s).
    pub target_speed: f64,
    pub target_yaw_rate: f64,
    /// How far the target has turned since the push began (rad; 0 before it).
    pub target_turn: f64,
    /// Bullet speed (m/s), yaw rate (rad/s), side slip (rad) and least obstacle clearance (m).
    pub bullet_speed: f64,
    pub bullet_yaw_rate: f64,
    pub bullet_slip: f64,
    pub bullet_clearance: f64,
}

/// The phase machine with its timeouts and safety monitor.
#[derive(Debug, Clone, PartialEq)]
pub struct PhaseMachine {
    settings: PhaseSettings,
    phase: Phase,
    entered: f64,
    contacted: bool,
    apart_since: Option<f64>,
    abort: Option<AbortReason>,
    push_round: bool,
    /// Pushes that did nothing, tried again (`PhaseSettings::retries`).
    retried: u32,
    /// First touch of the current push.
    touched_at: Option<f64>,
    /// Chasing again after a push that did nothing: the next push begins only once the
    /// vehicles have come apart.
    await_apart: bool,
}

impl PhaseMachine {
    #[must_use]
    pub fn new(settings: PhaseSettings) -> Self {
        Self {
            settings,
            phase: Phase::Chasing,
            entered: 0.0,
            contacted: false,
            apart_since: None,
            abort: None,
            push_round: false,
            retried: 0,
            touched_at: None,
            await_apart: false,
        }
    }

    /// A push that turns the target round by itself (`PlannerSettings::push_round`): the
    /// PIT phase then ends only on its timeout (or as the controller decides on the turn),
    /// not when the bullet and the target come apart or the window is over.
    #[must_use]
    pub fn pushing_round(mut self, on: bool) -> Self {
        self.push_round = on;
        self
    }

    /// Start over in chasing at `time`.
    pub fn reset(&mut self, time: f64) {
        self.phase = Phase::Chasing;
        self.entered = time;
        self.contacted = false;
        self.apart_since = None;
        self.abort = None;
        self.retried = 0;
        self.touched_at = None;
        self.await_apart = false;
    }

    /// Chasing again after a push that did nothing, the vehicles not yet apart.
    #[must_use]
    pub fn awaiting_apart(&self) -> bool {
        self.phase == Phase::Chasing && self.await_apart
    }

    /// How many pushes that did nothing were tried again.
    #[must_use]
    pub fn retried(&self) -> u32 {
        self.retried
    }

    #[must_use]
    pub fn phase(&self) -> Phase {
        self.phase
    }

    /// Time the current phase was entered (s).
    #[must_use]
    pub fn entered(&self) -> f64 {
        self.entered
    }

    #[must_use]
    pub fn abort_reason(&self) -> Option<AbortReason> {
        self.abort
    }

    /// Whether the bullet has touched the target in this maneuver.
    #[must_use]
    pub fn contacted(&self) -> bool {
        self.contacted
    }

    fn enter(&mut self, phase: Phase, time: f64) {
        self.phase = phase;
        self.entered = time;
    }

    /// Abort now, from an active phase (ignored once the maneuver is over).
    pub fn abort(&mut self, reason: AbortReason, time: f64) {
        if self.phase.is_active() {
            self.abort = Some(reason);
            self.enter(Phase::Aborted, time);
        }
    }

    /// End the push now, from an active phase: the upper layer predicts the target
    /// reverses without it.
    pub fn stabilise(&mut self, time: f64) {
        if self.phase.is_active() {
            self.enter(Phase::Stabilising, time);
        }
    }

    /// Advance on an observation; returns whether the phase changed.
    pub fn update(&mut self, o: &PhaseObservation) -> bool {
        let s = &self.settings;
        let before = self.phase;
        let in_phase = o.time - self.entered;
        if o.gap <= s.contact_gap && !self.awaiting_apart() {
            self.contacted = true;
            self.touched_at.get_or_insert(o.time);
        }
        if self.phase.is_active() {
            let unstable = o.bullet_yaw_rate.abs() > s.bullet_yaw_rate_max
                || (o.bullet_speed > s.monitor_speed && o.bullet_slip.abs() > s.bullet_slip_max);
            if unstable {
                self.abort(AbortReason::BulletUnstable, o.time);
                return true;
            }
            if o.bullet_clearance < s.bullet_clearance_min {
                self.abort(AbortReason::BulletClearance, o.time);
                return true;
            }
        }
        match self.phase {
            Phase::Chasing | Phase::Pit if o.mode == Some(Mode::Stabilise) => {
                // The upper layer predicts the target reverses without further push.
                self.enter(Phase::Stabilising, o.time);
            }
            Phase::Chasing => {
                // (An infeasible decision aborts through `abort`, after the controller's
                // patience: the observation's mode alone does not.)
                if o.gap > s.release_gap {
                    self.await_apart = false;
                }
                if o.gap <= s.contact_gap && !self.await_apart {
                    self.enter(Phase::Pit, o.time);
                } else if in_phase > s.chase_timeout {
                    self.abort(AbortReason::ChaseTimeout, o.time);
                }
            }
            Phase::Pit => {
                let window_over = o.window.is_some_and(|(_, t1)| o.time > t1 + 0.25);
                // Released: apart by more than `release_gap` for `release_dwell` after a
                // contact (a bouncing push does not count; a spinning target is not touched
                // again: the next touch would be a rebound).
                if self.contacted && o.gap > s.release_gap {
                    self.apart_since.get_or_insert(o.time);
                } else {
                    self.apart_since = None;
                }
                let released = self
                    .apart_since
                    .is_some_and(|t| o.time - t >= s.release_dwell - 1e-9);
                let apart = released || (window_over && o.gap > s.contact_gap);
                let idle = o.target_turn.abs() < s.retry_turn
                    && o.target_yaw_rate.abs() < s.retry_yaw_rate;
                // Stalled: `retry_after` since the first touch without turning the target
                // (its rear tyres hold the push).
                let stalled = self
                    .touched_at
                    .is_some_and(|t| o.time - t >= s.retry_after - 1e-9);
                if (apart || stalled) && !self.push_round && idle && self.retried < s.retries {
                    // The push did nothing: chase again for another one.
                    self.retried += 1;
                    self.contacted = false;
                    self.apart_since = None;
                    self.touched_at = None;
                    self.await_apart = true;
                    self.enter(Phase::Chasing, o.time);
                } else if (apart && !self.push_round) || in_phase > s.pit_timeout {
                    self.enter(Phase::Stabilising, o.time);
                }
            }
            Phase::Stabilising => {
                let settled =
                    o.target_speed < s.settle_speed && o.target_yaw_rate.abs() < s.settle_yaw_rate;
                if settled || in_phase > s.stabilise_timeout {
                    self.enter(Phase::Done, o.time);
                }
            }
            Phase::Done | Phase::Aborted => {}
        }
        self.phase != before
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn obs(time: f64, gap: f64) -> PhaseObservation {
        PhaseObservation {
            time,
            gap,
            mode: Some(Mode::Pit),
            infeasible: None,
            window: Some((1.0, 1.6)),
            target_speed: 15.0,
            target_yaw_rate: 0.0,
            // The push has turned the target (a push that did nothing is tried again).
            target_turn: 1.0,
            bullet_speed: 16.0,
            bullet_yaw_rate: 0.0,
            bullet_slip: 0.0,
            bullet_clearance: 10.0,
        }
    }

    #[test]
    fn a_maneuver_runs_through_its_phases() {
        let mut m = PhaseMachine::new(PhaseSettings::default());
        m.reset(0.0);
        assert!(!m.update(&obs(0.5, 1.0)));
        assert_eq!(m.phase(), Phase::Chasing);
        assert!(m.update(&obs(1.0, 0.0)));
        assert_eq!(m.phase(), Phase::Pit);
        assert!(!m.update(&obs(1.3, -0.02)));
        // Apart, but not for long enough: a bouncing push.
        assert!(!m.update(&obs(1.35, 0.8)));
        assert!(!m.update(&obs(1.4, 0.0)));
        assert!(!m.update(&obs(1.45, 0.8)));
        assert!(m.update(&obs(1.45 + PhaseSettings::default().release_dwell, 0.8)));
        assert_eq!(m.phase(), Phase::Stabilising);
        let mut o = obs(3.0, 5.0);
        o.target_speed = 0.2;
        o.target_yaw_rate = 0.05;
        assert!(m.update(&o));
        assert_eq!(m.phase(), Phase::Done);
        assert_eq!(m.abort_reason(), None);
    }

    /// A push that did nothing (the target not turned, not yawing) goes back to chasing,
    /// once: after a brush that came apart, or after `retry_after` of contact (the rear
    /// tyres held); the next push begins only once the vehicles have been apart.
    #[test]
    fn a_push_that_did_nothing_is_tried_again_once() {
        let s = PhaseSettings::default();
        let idle = |t, gap| PhaseObservation {
            target_turn: 0.0,
            ..obs(t, gap)
        };
        let mut m = PhaseMachine::new(s.clone());
        m.reset(0.0);
        assert!(m.update(&idle(1.0, 0.0)));
        m.update(&idle(1.05, 0.8));
        assert!(m.update(&idle(1.05 + s.release_dwell, 0.8)));
        assert_eq!(m.phase(), Phase::Chasing);
        assert_eq!(m.retried(), 1);
        assert!(!m.contacted());
        // The second push (once apart); it does nothing either, and there is no third.
        assert!(!m.update(&idle(1.5, 0.8)));
        assert!(m.update(&idle(2.0, 0.0)));
        assert_eq!(m.phase(), Phase::Pit);
        m.update(&idle(2.05, 0.8));
        m.update(&idle(2.05 + s.release_dwell, 0.8));
        assert_eq!(m.phase(), Phase::Stabilising);
        assert_eq!(m.retried(), 1);

        // Stalled in contact: back to chasing after `retry_after`, backing off (no new push
        // while still touching) until apart.
        let mut m = PhaseMachine::new(s.clone());
        m.reset(0.0);
        m.update(&idle(1.0, 0.0));
        assert!(!m.update(&idle(1.0 + s.retry_after - 0.05, -0.01)));
        assert!(m.update(&idle(1.0 + s.retry_after, -0.01)));
        assert_eq!(m.phase(), Phase::Chasing);
        assert!(m.awaiting_apart());
        assert!(!m.update(&idle(1.7, 0.0)), "still touching: no new push");
        assert!(!m.update(&idle(1.8, s.release_gap + 0.1)));
        assert!(!m.awaiting_apart());
        assert!(m.update(&idle(2.5, 0.0)));
        assert_eq!(m.phase(), Phase::Pit);

        // A push that turned the target, or set it yawing, is not tried again.
        for (turn, rate) in [(s.retry_turn + 0.05, 0.0), (0.0, s.retry_yaw_rate + 0.1)] {
            let mut m = PhaseMachine::new(s.clone());
            m.reset(0.0);
            m.update(&idle(1.0, 0.0));
            let mut o = idle(1.05, 0.8);
            o.target_turn = turn;
            o.target_yaw_rate = rate;
            m.update(&o);
            o.time = 1.05 + s.release_dwell;
            assert!(m.update(&o));
            assert_eq!(m.phase(), Phase::Stabilising, "turn {turn}, rate {rate}");
        }
        // Nor without retries, nor a push round.
        let none = PhaseSettings {
            retries: 0,
            ..s.clone()
        };
        let mut m = PhaseMachine::new(none);
        m.reset(0.0);
        m.update(&idle(1.0, 0.0));
        m.update(&idle(1.05, 0.8));
        m.update(&idle(1.05 + s.release_dwell, 0.8));
        assert_eq!(m.phase(), Phase::Stabilising);
    }

    /// A push that turns the target round goes on when the bullet and the target come
    /// apart and past the window's end (window 1.0–1.6 s); only its timeout ends it.
    #[test]
    fn a_push_round_ends_on_its_timeout_only() {
        let s = PhaseSettings::default();
        let mut m = PhaseMachine::new(s.clone()).pushing_round(true);
        m.reset(0.0);
        assert!(m.update(&obs(1.0, 0.0)));
        assert_eq!(m.phase(), Phase::Pit);
        for k in 1..=30 {
            let t = 1.0 + 0.05 * f64::from(k);
            assert!(!m.update(&obs(t, 0.8)), "apart at {t} s");
        }
        assert_eq!(m.phase(), Phase::Pit);
        assert!(m.update(&obs(1.05 + s.pit_timeout, 0.8)));
        assert_eq!(m.phase(), Phase::Stabilising);
        // The same push without it ends once the bullet has been apart for the dwell.
        let mut m = PhaseMachine::new(s.clone());
        m.reset(0.0);
        m.update(&obs(1.0, 0.0));
        m.update(&obs(1.1, 0.8));
        assert!(m.update(&obs(1.1 + s.release_dwell, 0.8)));
        assert_eq!(m.phase(), Phase::Stabilising);
    }

    #[test]
    fn every_phase_times_out_and_the_monitor_aborts() {
        let s = PhaseSettings::default();
        let mut m = PhaseMachine::new(s.clone());
        m.reset(0.0);
        m.update(&obs(s.chase_timeout + 0.1, 2.0));
        assert_eq!(m.phase(), Phase::Aborted);
        assert_eq!(m.abort_reason(), Some(AbortReason::ChaseTimeout));

        m.reset(0.0);
        m.update(&obs(0.1, 0.0));
        let mut o = obs(0.2, 0.0);
        o.window = None;
        m.update(&o);
        assert_eq!(m.phase(), Phase::Pit);
        let mut o = obs(0.2 + s.pit_timeout, 0.0);
        o.window = None;
        m.update(&o);
        assert_eq!(m.phase(), Phase::Stabilising);
        m.update(&obs(0.3 + s.pit_timeout + s.stabilise_timeout, 5.0));
        assert_eq!(m.phase(), Phase::Done);

        m.reset(0.0);
        let mut o = obs(0.5, 1.0);
        o.bullet_yaw_rate = s.bullet_yaw_rate_max + 0.1;
        m.update(&o);
        assert_eq!(m.abort_reason(), Some(AbortReason::BulletUnstable));

        m.reset(0.0);
        let mut o = obs(0.5, 1.0);
        o.mode = Some(Mode::Abort);
        o.infeasible = Some(Infeasible::RoadBoundary);
        m.update(&o);
        assert_eq!(
            m.phase(),
            Phase::Chasing,
            "an infeasible package alone does not abort"
        );
        m.abort(
            AbortReason::DecisionInfeasible(Infeasible::RoadBoundary),
            0.6,
        );
        assert_eq!(
            m.abort_reason(),
            Some(AbortReason::DecisionInfeasible(Infeasible::RoadBoundary))
        );
        // Over is over: no abort after the maneuver ended.
        m.abort(AbortReason::ChaseTimeout, 1.0);
        assert_eq!(
            m.abort_reason(),
            Some(AbortReason::DecisionInfeasible(Infeasible::RoadBoundary))
        );
    }
}
