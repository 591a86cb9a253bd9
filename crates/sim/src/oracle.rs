//! The ideal-PIT bound: could *any* PIT succeed on a scenario?
//!
//! A physics ceiling for the closed-loop benchmark, independent of the controller. The target
//! runs alone on the plant under its driver (as in screening). At every candidate contact
//! time from the bullet's earliest arrival ([`crate::screen`]'s kinematic reach bound) on, on
//! either side, the target's rear quarter receives one instantaneous lateral shove — a
//! rigid-body impulse `J = m_T · Δv` ([`Plant::apply_impulse`]) at the PIT contact point
//! (`contact_back` behind the rear axle, on the body side, pointing inward) — and the plant
//! then runs on to `T_max` with the driver reacting to the "contact" as in an episode. The
//! scenario is *ideally feasible* if one shove ends in success by the benchmark's own test
//! ([`Monitor`]: reversed and at rest, or settled reversed at `T_max`; no boundary
//! violation or obstacle hit). The bullet itself is not simulated; only a side where it
//! fits beside the target at the contact, inside the road and clear of every obstacle, is
//! tried ([`OracleSettings::bullet_beside`]).
//!
//! The bound is optimistic about the bullet (it is at its pose at once, and leaves nothing
//! behind to hit) and restrictive about the push (one impulse, no sustained push or
//! follow-up). It measures how much of the dataset a PIT can save at all.

use crate::outcome::{FailureCause, Monitor, Observation, Outcome, Status};
use crate::scenario::{Scenario, ScenarioError};
use crate::screen::{reach_time, target_alone, ScreenSettings};
use dynamics::contact::obb_signed_distance;
use dynamics::geometry::{rotate, Obb, Pose2, Vec2};
use dynamics::plant::{Plant, Which};
use serde::{Deserialize, Serialize};

/// What the oracle tries (serde with defaults).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct OracleSettings {
    /// Shoves as a velocity change of the target's c.g., `J / m_T` (m/s).
    pub shoves: Vec<f64>,
    /// Spacing of the candidate contact times (s).
    pub time_step: f64,
    /// Contact point behind the rear axle (m).
    pub contact_back: f64,
    /// The last candidate time is `T_max − min_remaining` (s).
    pub min_remaining: f64,
    /// Try every shove instead of stopping at the first success (to count them).
    pub exhaustive: bool,
    /// Sides to try: +1 the target's left (pushed right), −1 its right.
    pub sides: Vec<f64>,
    /// Only contact times within `[from, to]` (s), if given (still from the reach bound on).
    pub window: Option<[f64; 2]>,
    /// Screening settings for the bullet's reach bound.
    pub screen: ScreenSettings,
    /// Only shoves from a side where a bullet fits: beside the target at the contact, parallel
    /// to it and flush against its side with its front at the contact point, its footprint
    /// inside the road and not overlapping any obstacle at that moment (the benchmark judges
    /// the bullet's footprint too). Without it a shove may come from where no bullet can be:
    /// beyond a road edge, or where a car stands in the lane beside the target.
    pub bullet_beside: bool,
}

impl Default for OracleSettings {
    fn default() -> Self {
        Self {
            shoves: vec![0.5, 1.0, 1.5, 2.0],
            time_step: 0.25,
            contact_back: 0.3,
            min_remaining: 1.0,
            exhaustive: false,
            sides: vec![1.0, -1.0],
            window: None,
            screen: ScreenSettings::default(),
            bullet_beside: true,
        }
    }
}

impl OracleSettings {
    /// # Errors
    /// [`ScenarioError::Field`] (line 0) naming the first bad setting.
    pub fn validate(&self) -> Result<(), ScenarioError> {
        let bad = |field: &str, message: String| {
            Err(ScenarioError::Field {
                line: 0,
                field: format!("oracle.{field}"),
                message,
            })
        };
        if self.shoves.is_empty() || self.shoves.iter().any(|v| !v.is_finite() || *v < 0.0) {
            return bad(
                "shoves",
                format!("{:?}: need at least one, each finite and ≥ 0", self.shoves),
            );
        }
        for (field, v) in [
            ("time_step", self.time_step),
            ("contact_back", self.contact_back),
            ("min_remaining", self.min_remaining),
        ] {
            if !v.is_finite() || v < 0.0 || (field == "time_step" && v == 0.0) {
                return bad(
                    field,
                    format!(
                        "{v}: must be finite and {}",
                        if field == "time_step" { "> 0" } else { "≥ 0" }
                    ),
                );
            }
        }
        if self.sides.is_empty() || self.sides.iter().any(|&v| v != 1.0 && v != -1.0) {
            return bad("sides", format!("{:?}: each must be +1 or −1", self.sides));
        }
        if let Some([from, to]) = self.window {
            if !(from.is_finite() && to.is_finite() && from <= to) {
                return bad(
                    "window",
                    format!("[{from}, {to}]: must be finite with from ≤ to"),
                );
            }
        }
        Ok(())
    }
}

/// The shove that worked.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
pub struct Shove {
    /// Contact time (s).
    pub time: f64,
    /// +1: on the target's left side (pushed to the right), −1: on its right.
    pub side: f64,
    /// `J / m_T` (m/s).
    pub dv: f64,
    /// When the test decided success (s).
    pub decided_at: f64,
    /// Whether it ended at rest (else settled reversed at `T_max`).
    pub at_rest: bool,
}

/// What the oracle found on one scenario.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct OracleReport {
    /// The earliest successful shove (`None`: no shove succeeds).
    pub feasible: Option<Shove>,
    /// Earliest time the bullet can be at the PIT pose (s).
    pub t_reach: f64,
    /// Number of shoves simulated.
    pub tried: usize,
    /// Number of them that succeeded (at most 1 unless `exhaustive`).
    pub successes: usize,
    /// When the target alone left the road or hit an obstacle, if it did by `T_max`.
    pub alone_fails_at: Option<f64>,
}

/// The target alone on the plant under its driver, judged by the benchmark's test.
#[derive(Clone)]
struct Alone {
    plant: Plant,
    driver: crate::scenario::TargetDriver,
    monitor: Monitor,
    road: dynamics::road::Road,
    first_contact: Option<f64>,
    /// A command held instead of the driver's law ([`DriverView::Held`]).
    held: Option<(f64, f64)>,
    steps_per: usize,
    k: usize,
}

const DT: f64 = 0.05;

impl Alone {
    /// One control period: driver command, plant steps, judge. The bullet is the target's
    /// twin for the judge (its footprint is the target's), so only the target is judged.
    fn period(&mut self) -> Status {
        let t = self.k as f64 * DT;
        let x = self.plant.target_state();
        let (steer, brake) = match self.held {
            Some(command) => command,
            None => self.driver.command(t, self.first_contact, &x, &self.road),
        };
        self.plant.set_target_command(steer, brake);
        let mut touched = false;
        for _ in 0..self.steps_per {
            self.plant.step();
            touched |= self.plant.obstacle_contacts()[1].is_some();
        }
        self.k += 1;
        let fp = self.plant.footprints()[1];
        self.monitor.observe(&Observation {
            time: self.k as f64 * DT,
            target: self.plant.target_state(),
            footprints: [fp, fp],
            vehicle_contact: false,
            closing_speed: 0.0,
            obstacle_contact: [touched, touched],
        })
    }

    fn time(&self) -> f64 {
        self.k as f64 * DT
    }

    /// Shove the rear quarter on `side` (+1 left, −1 right) inward by `dv · m_T`.
    fn shove(&mut self, side: f64, dv: f64, lr: f64, width: f64, back: f64) {
        let b = *self.plant.body(Which::Target);
        let at = b.pos + rotate(b.yaw, Vec2::new(-(lr + back), side * 0.5 * width));
        let j = rotate(
            b.yaw,
            Vec2::new(0.0, -side * dv * self.plant.mass(Which::Target)),
        );
        self.plant.apply_impulse(Which::Target, j, at);
        self.first_contact = Some(self.time());
    }
}

/// The target alone up to `T_max` (or its own failure): a snapshot at every candidate time
/// (`settings.time_step`) and the bullet's reach bound.
struct Snapshots {
    snaps: Vec<Alone>,
    t_reach: f64,
    alone_fails_at: Option<f64>,
    params: dynamics::params::ParamSet,
}

impl Snapshots {
    fn new(sc: &Scenario, settings: &OracleSettings) -> Result<Self, ScenarioError> {
        settings.validate()?;
        let params = sc.params.load()?;
        let road = sc.build_road()?;
        let plant = target_alone(sc, &params, &road)?;
        let steps_per = (DT / plant.dt()).round().max(1.0) as usize;
        let mut base = Alone {
            plant,
            driver: sc.target_driver(&params),
            monitor: Monitor::for_scenario(sc)?,
            road: road.clone(),
            first_contact: None,
            held: None,
            steps_per,
            k: 0,
        };
        let n = (sc.t_max / DT).ceil() as usize;
        let every = ((settings.time_step / DT).round() as usize).max(1);
        let mut stations = vec![sc.target.s];
        let mut snaps = vec![base.clone()];
        let mut s_hint = sc.target.s;
        let mut alone_fails_at = None;
        for _ in 0..n {
            let status = base.period();
            let x = base.plant.target_state();
            let f = road.project_with_hint(Vec2::new(x[6], x[7]), s_hint);
            s_hint = f.s;
            stations.push(f.s);
            if let Status::Done(o) = status {
                if let Outcome::Failure {
                    cause: FailureCause::BoundaryViolation | FailureCause::SecondaryCollision,
                    time,
                } = o
                {
                    alone_fails_at = Some(time);
                }
                break;
            }
            if base.k % every == 0 {
                snaps.push(base.clone());
            }
        }
        let t_reach = reach_time(sc, &params, &stations, DT, &settings.screen);
        Ok(Self {
            snaps,
            t_reach,
            alone_fails_at,
            params,
        })
    }

    /// The snapshots at which a shove is a candidate: from the reach bound to
    /// `T_max − min_remaining`, inside `settings.window`, the target not yet judged.
    fn candidates<'a>(
        &'a self,
        sc: &Scenario,
        settings: &'a OracleSettings,
    ) -> impl Iterator<Item = &'a Alone> + 'a {
        let t_last = sc.t_max - settings.min_remaining;
        let t_reach = self.t_reach;
        self.snaps.iter().filter(move |snap| {
            let t = snap.time();
            let in_window = settings
                .window
                .is_none_or(|[from, to]| t + 1e-9 >= from && t <= to + 1e-9);
            t + 1e-9 >= t_reach
                && t <= t_last + 1e-9
                && snap.monitor.outcome().is_none()
                && in_window
        })
    }

    /// Whether a bullet beside the target of `snap` on `side` at the PIT contact (parallel to
    /// the target, flush against its side, its front at the contact point `back` behind the
    /// rear axle) has its footprint inside the road and clear of every obstacle.
    fn bullet_fits(&self, snap: &Alone, side: f64, back: f64) -> bool {
        let (pt, pb) = (&self.params.target, &self.params.bullet);
        let b = *snap.plant.body(Which::Target);
        let rel = Vec2::new(
            -(pt.lr + back) - pb.cg_to_front,
            side * 0.5 * (pt.width + pb.width),
        );
        let at = b.pos + rotate(b.yaw, rel);
        let fp = Obb::vehicle_footprint(
            &Pose2::new(at.x, at.y, b.yaw),
            pb.length,
            pb.width,
            pb.cg_to_front,
        );
        let t = snap.plant.time();
        snap.road.edge_distance(&fp) >= 0.0
            && snap
                .plant
                .obstacles()
                .iter()
                .all(|o| obb_signed_distance(&fp, &o.footprint_at(t)) >= 0.0)
    }

    /// Shove a copy of `snap` and run it to the verdict.
    fn try_shove(
        &self,
        snap: &Alone,
        side: f64,
        dv: f64,
        settings: &OracleSettings,
        view: DriverView,
    ) -> (Outcome, bool) {
        let pt = &self.params.target;
        if settings.bullet_beside && !self.bullet_fits(snap, side, settings.contact_back) {
            // No bullet can push from here: the shove fails as the bullet would, over the edge.
            return (
                Outcome::Failure {
                    cause: FailureCause::BoundaryViolation,
                    time: snap.time(),
                },
                false,
            );
        }
        let mut run = snap.clone();
        match view {
            DriverView::True => {}
            DriverView::Held => {
                let x = run.plant.target_state();
                let t = run.time();
                run.held = Some(run.driver.command(t, None, &x, &run.road));
            }
        }
        run.shove(side, dv, pt.lr, pt.width, settings.contact_back);
        let outcome = loop {
            if let Status::Done(o) = run.period() {
                break o;
            }
        };
        (outcome, run.monitor.metrics().at_rest)
    }
}

/// Run the ideal-PIT search on one scenario.
///
/// # Errors
/// [`ScenarioError`] if the scenario's road or parameter set cannot be built, or a setting
/// is bad ([`OracleSettings::validate`]).
pub fn ideal_pit(sc: &Scenario, settings: &OracleSettings) -> Result<OracleReport, ScenarioError> {
    let snaps = Snapshots::new(sc, settings)?;
    let (t_reach, alone_fails_at) = (snaps.t_reach, snaps.alone_fails_at);
    let mut tried = 0;
    let mut successes = 0;
    let mut feasible = None;
    for snap in snaps.candidates(sc, settings) {
        let t = snap.time();
        for &dv in &settings.shoves {
            for &side in &settings.sides {
                tried += 1;
                let (outcome, at_rest) =
                    snaps.try_shove(snap, side, dv, settings, DriverView::True);
                if let Outcome::Success { time } = outcome {
                    successes += 1;
                    feasible.get_or_insert(Shove {
                        time: t,
                        side,
                        dv,
                        decided_at: time,
                        at_rest,
                    });
                    if !settings.exhaustive {
                        return Ok(OracleReport {
                            feasible,
                            t_reach,
                            tried,
                            successes,
                            alone_fails_at,
                        });
                    }
                }
            }
        }
    }
    Ok(OracleReport {
        feasible,
        t_reach,
        tried,
        successes,
        alone_fails_at,
    })
}

/// What the chooser of a shove knows about the target's driver.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum DriverView {
    /// The driver's own law, reacting to the contact: the truth.
    #[default]
    True,
    /// The driver's command at the moment of the shove, held to the end: all that a planner
    /// which sees the current command (and not the law behind it) can assume.
    Held,
}

/// Every shove of the grid `times × sides × shoves`, simulated: which succeed.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct ShoveGrid {
    /// Candidate contact times, ascending, spaced by `OracleSettings::time_step` (s).
    pub times: Vec<f64>,
    /// Sides (as [`OracleSettings::sides`]).
    pub sides: Vec<f64>,
    /// Shove sizes `J / m_T` (as [`OracleSettings::shoves`], in the order given) (m/s).
    pub shoves: Vec<f64>,
    /// `success[(i_time · sides + i_side) · shoves + i_shove]`.
    pub success: Vec<bool>,
    /// Earliest time the bullet can be at the PIT pose (s).
    pub t_reach: f64,
}

/// A shove of a [`ShoveGrid`] by its indices, with the number of successes in its box.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq)]
pub struct GridChoice {
    pub time: usize,
    pub side: usize,
    pub shove: usize,
    /// Successes in the box around it (the shove itself included).
    pub score: usize,
    /// Shoves in the box (`(2 r_t + 1)(2 r_v + 1)`; neighbours outside the grid count as
    /// failures).
    pub of: usize,
}

impl ShoveGrid {
    /// Whether shove `(time, side, shove)` succeeded; `false` outside the grid.
    #[must_use]
    pub fn get(&self, time: isize, side: usize, shove: isize) -> bool {
        let (nt, ns, nv) = (self.times.len(), self.sides.len(), self.shoves.len());
        if time < 0 || shove < 0 || time as usize >= nt || shove as usize >= nv || side >= ns {
            return false;
        }
        self.success[(time as usize * ns + side) * nv + shove as usize]
    }

    /// Successes in the box of `±radius_time` neighbouring times and `±radius_shove`
    /// neighbouring sizes (same side) around a shove: how much a timing or size error of
    /// that order forgives.
    #[must_use]
    pub fn box_score(
        &self,
        time: usize,
        side: usize,
        shove: usize,
        radius_time: usize,
        radius_shove: usize,
    ) -> usize {
        let (rt, rv) = (radius_time as isize, radius_shove as isize);
        let mut n = 0;
        for dt in -rt..=rt {
            for dv in -rv..=rv {
                n += usize::from(self.get(time as isize + dt, side, shove as isize + dv));
            }
        }
        n
    }

    /// The earliest successful shove (time first, then size in the grid's order, then side:
    /// the order of [`ideal_pit`]).
    #[must_use]
    pub fn earliest(&self) -> Option<GridChoice> {
        for it in 0..self.times.len() {
            for iv in 0..self.shoves.len() {
                for is in 0..self.sides.len() {
                    if self.get(it as isize, is, iv as isize) {
                        return Some(GridChoice {
                            time: it,
                            side: is,
                            shove: iv,
                            score: 1,
                            of: 1,
                        });
                    }
                }
            }
        }
        None
    }

    /// The successful shove whose box holds the most successes (the one that forgives the
    /// most); ties go to the earliest, then the first size and side.
    #[must_use]
    pub fn most_robust(&self, radius_time: usize, radius_shove: usize) -> Option<GridChoice> {
        let of = (2 * radius_time + 1) * (2 * radius_shove + 1);
        let mut best: Option<GridChoice> = None;
        for it in 0..self.times.len() {
            for iv in 0..self.shoves.len() {
                for is in 0..self.sides.len() {
                    if !self.get(it as isize, is, iv as isize) {
                        continue;
                    }
                    let score = self.box_score(it, is, iv, radius_time, radius_shove);
                    if best.is_none_or(|b| score > b.score) {
                        best = Some(GridChoice {
                            time: it,
                            side: is,
                            shove: iv,
                            score,
                            of,
                        });
                    }
                }
            }
        }
        best
    }
}

/// Simulate every shove of the grid on one scenario, with the driver as `view` says.
///
/// The snapshots are the truth in both views (the state at the shove is what it is); with
/// [`DriverView::Held`] the driver's command at the shove is held from then on, so the grid
/// is what a chooser who does not know the driver's law would believe.
///
/// # Errors
/// As [`ideal_pit`].
pub fn shove_grid(
    sc: &Scenario,
    settings: &OracleSettings,
    view: DriverView,
) -> Result<ShoveGrid, ScenarioError> {
    let snaps = Snapshots::new(sc, settings)?;
    let mut grid = ShoveGrid {
        times: Vec::new(),
        sides: settings.sides.clone(),
        shoves: settings.shoves.clone(),
        success: Vec::new(),
        t_reach: snaps.t_reach,
    };
    for snap in snaps.candidates(sc, settings) {
        grid.times.push(snap.time());
        for &side in &settings.sides {
            for &dv in &settings.shoves {
                let (outcome, _) = snaps.try_shove(snap, side, dv, settings, view);
                grid.success
                    .push(matches!(outcome, Outcome::Success { .. }));
            }
        }
    }
    Ok(grid)
}

/// The tiers of [`oracle_tiers`], in the order of [`TierReport::tiers`].
pub const TIERS: [&str; 8] = [
    "ideal",
    "robust-t",
    "robust-v",
    "robust-tv",
    "ideal-exp",
    "held-first",
    "held-robust",
    "held-exp",
];

/// How much of the ideal-PIT bound a controller could reach, in tiers of what it knows and
/// how precisely it acts ([`oracle_tiers`]).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct TierReport {
    /// Per tier of [`TIERS`], the chance of success: 0 or 1, or the share of a box that
    /// succeeds (the `-exp` tiers).
    pub tiers: [f64; 8],
    /// Share of the grid's shoves that succeed in the truth.
    pub true_share: f64,
    /// Share that succeed with the driver's command held from the shove on.
    pub held_share: f64,
    /// Earliest time the bullet can be at the PIT pose (s).
    pub t_reach: f64,
    /// Shoves per grid.
    pub shoves: usize,
}

/// The tiers of one scenario from its two grids, each choice made in its world and judged
/// in the truth (`truth`: the driver's own law; `held`: its command held from the shove on):
///
/// * `ideal`: some shove succeeds (the ideal-PIT bound);
/// * `robust-t`, `robust-v`, `robust-tv`: some shove succeeds together with its neighbours
///   ±1 time step, ±1 size step, or both (a 3 × 3 box): the bound for a controller whose
///   push lands that far off;
/// * `ideal-exp`: the best expected success if the push lands anywhere in the 3 × 3 box of
///   the chosen shove, equally likely, the choice made with the truth;
/// * `held-first`: the earliest shove that succeeds under the held command, judged true;
/// * `held-robust`: the shove with the most successes in its 3 × 3 box under the held
///   command, judged true;
/// * `held-exp`: that choice's expected true success when the push lands anywhere in its box.
#[must_use]
pub fn tiers(truth: &ShoveGrid, held: &ShoveGrid) -> [f64; 8] {
    let whole = |rt: usize, rv: usize| {
        f64::from(u8::from(
            truth.most_robust(rt, rv).is_some_and(|c| c.score == c.of),
        ))
    };
    let at = |c: Option<GridChoice>| {
        f64::from(u8::from(c.is_some_and(|c| {
            truth.get(c.time as isize, c.side, c.shove as isize)
        })))
    };
    let expected = |c: Option<GridChoice>| {
        c.map_or(0.0, |c| {
            truth.box_score(c.time, c.side, c.shove, 1, 1) as f64 / 9.0
        })
    };
    let pick = held.most_robust(1, 1);
    let best = truth.most_robust(1, 1);
    [
        at(truth.earliest()),
        whole(1, 0),
        whole(0, 1),
        f64::from(u8::from(best.is_some_and(|c| c.score == c.of))),
        best.map_or(0.0, |c| c.score as f64 / c.of as f64),
        at(held.earliest()),
        at(pick),
        expected(pick),
    ]
}

/// The whole grid of single shoves on one scenario, simulated with the driver's true law and
/// with its command held ([`shove_grid`] in both [`DriverView`]s), and the [`tiers`].
///
/// # Errors
/// As [`ideal_pit`].
pub fn oracle_tiers(sc: &Scenario, settings: &OracleSettings) -> Result<TierReport, ScenarioError> {
    let truth = shove_grid(sc, settings, DriverView::True)?;
    let held = shove_grid(sc, settings, DriverView::Held)?;
    let share = |g: &ShoveGrid| {
        g.success.iter().filter(|&&b| b).count() as f64 / g.success.len().max(1) as f64
    };
    Ok(TierReport {
        tiers: tiers(&truth, &held),
        true_share: share(&truth),
        held_share: share(&held),
        t_reach: truth.t_reach,
        shoves: truth.success.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 4-time × 1-side × 3-size grid from rows of `'x'` (success) and `'.'`.
    fn grid(rows: [&str; 4]) -> ShoveGrid {
        ShoveGrid {
            times: vec![1.0, 1.1, 1.2, 1.3],
            sides: vec![1.0],
            shoves: vec![1.0, 1.25, 1.6],
            success: rows
                .iter()
                .flat_map(|r| r.chars().map(|c| c == 'x'))
                .collect(),
            t_reach: 1.0,
        }
    }

    #[test]
    fn box_scores_count_neighbours_and_nothing_outside_the_grid() {
        let g = grid(["..x", "xxx", "xxx", "x.."]);
        assert_eq!(g.box_score(1, 0, 1, 1, 1), 7);
        assert_eq!(
            g.box_score(0, 0, 0, 1, 1),
            2,
            "the corner's box is half outside"
        );
        assert_eq!(g.box_score(2, 0, 1, 0, 0), 1);
        assert!(!g.get(-1, 0, 0) && !g.get(4, 0, 0) && !g.get(0, 0, 3) && !g.get(0, 1, 0));
    }

    #[test]
    fn the_most_robust_shove_is_the_one_with_the_fullest_box_and_the_earliest_on_ties() {
        let g = grid(["..x", "xxx", "xxx", "x.."]);
        assert_eq!(g.earliest().map(|c| (c.time, c.shove)), Some((0, 2)));
        let c = g.most_robust(1, 1).unwrap();
        assert_eq!((c.time, c.shove, c.score, c.of), (1, 1, 7, 9));
        let c = g.most_robust(1, 0).unwrap();
        assert_eq!(
            (c.time, c.shove, c.score, c.of),
            (1, 2, 3, 3),
            "the earliest full column"
        );
        assert!(grid(["...", "...", "...", "..."])
            .most_robust(1, 1)
            .is_none());
    }

    #[test]
    fn tiers_judge_each_choice_in_the_truth() {
        let truth = grid(["..x", "xxx", "xxx", "x.."]);
        // The held view believes only the last time's first size works, which is true.
        let held = grid(["...", "...", "...", "x.."]);
        let t = tiers(&truth, &held);
        // ideal; robust-t (the last size, times 0-2), robust-v (a full row), robust-tv
        // (no full 3 x 3 box: 7 of 9 at best); ideal-exp 7/9; held-first true; held-robust
        // the same shove; its box (times 2-3, sizes 0-1, outside counted as failing) 3/9.
        assert_eq!(t[..4], [1.0, 1.0, 1.0, 0.0]);
        assert!((t[4] - 7.0 / 9.0).abs() < 1e-12);
        assert_eq!(t[5..7], [1.0, 1.0]);
        assert!((t[7] - 3.0 / 9.0).abs() < 1e-12, "{t:?}");
        // A held view that picks a shove failing in truth scores nothing.
        let wrong = grid(["x..", "...", "...", "..."]);
        assert_eq!(tiers(&truth, &wrong)[5..], [0.0, 0.0, 2.0 / 9.0]);
    }
}
