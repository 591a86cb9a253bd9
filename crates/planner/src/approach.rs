//! The bullet's approach along the target: a minimum-time relative motion from the current
//! relative position and speed to a goal station, at rest relative to the target there, with
//! the relative acceleration bounded by `accel` and the relative speed by `speed_cap`
//! (bang-bang with a cruise). The upper layer's earliest arrival and the MPC reference of the
//! approach both use it, so the window the plan promises is one the bullet can keep: a
//! bullet that is already past its station, or still closing fast, first brakes, and never
//! arrives faster than it can stop. The MPC reference of the approach may brake up to
//! [`BRAKE_MARGIN`] times harder to stop on the station when it is a little late
//! ([`Profile::with_brake_margin`]); the earliest arrival does not count on that.

/// How much harder than its acceleration the MPC reference of the approach may brake to stop
/// on its station rather than run past it and come back ([`Profile::with_brake_margin`]).
/// A bullet that follows the bang-bang profile a little late (a few tenths of a metre per
/// second too fast where the braking begins: the drive torque takes time to turn round)
/// would otherwise be planned past its station and back, seconds later.
pub const BRAKE_MARGIN: f64 = 1.5;

/// A planned 1-D relative motion: up to five constant-acceleration segments.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Profile {
    x0: f64,
    v0: f64,
    /// `(duration, acceleration)` of each segment.
    segments: [(f64, f64); 5],
    count: usize,
}

impl Profile {
    /// The minimum-time motion from `(x0, v0)` to rest at `goal`, `|a| ≤ accel`,
    /// `|v| ≤ speed_cap` (a start above the cap first slows to it).
    #[must_use]
    pub fn new(x0: f64, v0: f64, goal: f64, accel: f64, speed_cap: f64) -> Self {
        Self::with_brake_margin(x0, v0, goal, accel, speed_cap, 1.0)
    }

    /// As [`Self::new`], but a motion that would overrun the goal braking at `accel` brakes
    /// harder, at up to `brake_margin · accel`, when that stops it on the goal.
    #[must_use]
    pub fn with_brake_margin(
        x0: f64,
        v0: f64,
        goal: f64,
        accel: f64,
        speed_cap: f64,
        brake_margin: f64,
    ) -> Self {
        let a = accel.max(1e-6);
        let cap = speed_cap.max(1e-6);
        let mut p = Self {
            x0,
            v0,
            segments: [(0.0, 0.0); 5],
            count: 0,
        };
        let d = goal - x0;
        // Work in the frame where the goal lies ahead (s = ±1).
        let s = if d != 0.0 {
            d.signum()
        } else if v0 != 0.0 {
            v0.signum()
        } else {
            return p;
        };
        let (mut d, mut v) = (s * d, s * v0);
        let mut push = |t: f64, acc: f64| {
            if t > 0.0 {
                p.segments[p.count] = (t, s * acc);
                p.count += 1;
            }
        };
        if v < 0.0 {
            // Moving away: stop first.
            push(-v / a, a);
            d += v * v / (2.0 * a);
            v = 0.0;
        }
        if v > cap {
            push((v - cap) / a, -a);
            d -= (v * v - cap * cap) / (2.0 * a);
            v = cap;
        }
        let stop = v * v / (2.0 * a);
        if stop > d && stop <= brake_margin * d {
            // A little late: brake harder, at v²/(2d), to stop on the goal.
            push(2.0 * d / v, -v * v / (2.0 * d));
        } else if stop > d {
            // Past the goal by the time it has stopped: stop, then come back from rest.
            push(v / a, -a);
            rest_to_rest(stop - d, a, cap, -1.0, &mut push);
        } else {
            let peak = (a * d + 0.5 * v * v).sqrt();
            if peak <= cap {
                push((peak - v) / a, a);
                push(peak / a, -a);
            } else {
                let cruise = d - (cap * cap - v * v) / (2.0 * a) - cap * cap / (2.0 * a);
                push((cap - v) / a, a);
                push(cruise / cap, 0.0);
                push(cap / a, -a);
            }
        }
        p
    }

    /// Duration of the whole motion (s).
    #[must_use]
    pub fn time(&self) -> f64 {
        self.segments[..self.count].iter().map(|(t, _)| t).sum()
    }

    /// Relative position and speed `t` seconds in (held at the goal afterwards).
    #[must_use]
    pub fn at(&self, t: f64) -> (f64, f64) {
        let (mut x, mut v) = (self.x0, self.v0);
        let mut left = t.max(0.0);
        for &(dt, a) in &self.segments[..self.count] {
            let h = dt.min(left);
            x += v * h + 0.5 * a * h * h;
            v += a * h;
            left -= h;
            if left <= 0.0 {
                break;
            }
        }
        (x, if t >= self.time() { 0.0 } else { v })
    }
}

/// Rest-to-rest over `r` ≥ 0 in direction `dir` (±1).
fn rest_to_rest(r: f64, a: f64, cap: f64, dir: f64, push: &mut impl FnMut(f64, f64)) {
    if r <= 0.0 {
        return;
    }
    if r >= cap * cap / a {
        push(cap / a, dir * a);
        push((r - cap * cap / a) / cap, 0.0);
        push(cap / a, -dir * a);
    } else {
        let t = (r / a).sqrt();
        push(t, dir * a);
        push(t, -dir * a);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Integrate the profile finely and check it ends at rest on the goal, within the
    /// bounds, at `time()`.
    fn check(x0: f64, v0: f64, goal: f64, a: f64, cap: f64) -> f64 {
        let p = Profile::new(x0, v0, goal, a, cap);
        let t = p.time();
        let (x, v) = p.at(t);
        assert!((x - goal).abs() < 1e-9, "{x0} {v0} → {goal}: ends at {x}");
        assert_eq!(v, 0.0);
        let mut last = p.at(0.0);
        assert!((last.0 - x0).abs() < 1e-12 && (last.1 - v0).abs() < 1e-12);
        let n = 2000;
        for i in 1..=n {
            let s = p.at(t * f64::from(i) / f64::from(n));
            let h = t / f64::from(n);
            if i < n {
                assert!((s.1 - last.1).abs() <= a * h + 1e-9, "accel bound");
                assert!(s.1.abs() <= cap.max(v0.abs()) + 1e-9, "speed bound");
            }
            last = s;
        }
        t
    }

    #[test]
    fn profiles_reach_the_goal_at_rest_within_the_bounds() {
        for (x0, v0, goal) in [
            (-10.0, 0.0, -4.0),
            (-10.0, 2.5, -4.0),
            (-4.5, 2.0, -4.0),
            (-3.0, 2.0, -4.0),
            (-3.0, -1.0, -4.0),
            (-6.0, -1.0, -4.0),
            (-40.0, 3.0, -4.0),
            (2.0, 9.0, -4.0),
            (-4.0, 0.0, -4.0),
        ] {
            check(x0, v0, goal, 2.0, 8.0);
        }
    }

    #[test]
    fn times_match_the_closed_forms() {
        // From rest: triangle 2 sqrt(d/a), or trapezoid d/cap + cap/a beyond cap²/a.
        assert!((check(0.0, 0.0, 8.0, 2.0, 8.0) - 2.0 * 2f64.sqrt() * 2.0f64.sqrt()).abs() < 1e-9);
        assert!((check(0.0, 0.0, 100.0, 2.0, 8.0) - (100.0 / 8.0 + 4.0)).abs() < 1e-9);
        // Already closing at v: braking just in time takes v/a when d = v²/(2a).
        assert!((check(0.0, 4.0, 4.0, 2.0, 8.0) - 2.0).abs() < 1e-9);
        // Past the station and still closing: stop (v/a), then come back.
        let t = check(0.0, 2.0, -1.0, 2.0, 8.0);
        assert!(
            (t - (1.0 + 2.0 * (2.0f64 / 2.0).sqrt())).abs() < 1e-9,
            "{t}"
        );
        // A little late (braking at a overruns by 0.5 m): with the margin, brake at
        // v²/(2d) ≤ 1.5 a and stop on the goal in 2d/v; without it, stop and come back.
        let p = Profile::with_brake_margin(0.0, 4.0, 3.5, 2.0, 8.0, BRAKE_MARGIN);
        assert!((p.time() - 1.75).abs() < 1e-9 && p.at(1.75) == (3.5, 0.0));
        assert!((p.at(1.0).1 - (4.0 - 16.0 / 7.0)).abs() < 1e-9);
        let back = 2.0 + 2.0 * (0.5f64 / 2.0).sqrt();
        assert!((check(0.0, 4.0, 3.5, 2.0, 8.0) - back).abs() < 1e-9);
        // Too late even for the margin (v²/(2d) = 2 a): stop, then come back.
        let p = Profile::with_brake_margin(0.0, 4.0, 2.0, 2.0, 8.0, BRAKE_MARGIN);
        assert!((p.time() - 4.0).abs() < 1e-9 && p.at(4.0) == (2.0, 0.0));
        // At rest on the goal: nothing to do.
        assert_eq!(Profile::new(1.0, 0.0, 1.0, 2.0, 8.0).time(), 0.0);
    }
}
