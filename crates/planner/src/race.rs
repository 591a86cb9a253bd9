//! The race between the bullet and the target's failure: when the target's free motion (the
//! planner's no-force rollout) leaves the road or runs into an obstacle before the bullet
//! can begin any push, no PIT can turn it in time and the decision is infeasible now —
//! chasing on would only follow it into the failure (the paper's "decision infeasible in
//! chasing").

use crate::package::Infeasible;

/// How the free motion fails first, and at which rollout step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Failure {
    pub step: usize,
    pub reason: Infeasible,
}

/// The first step `k ≥ 1` of a rollout at which the target is over a road edge by more than
/// `tol` or touches an obstacle, from the rows' right-hand sides at that rollout: `road[k]`
/// the road-edge margin beyond the planner's road margin, `obstacle[k]` the obstacle gap
/// beyond the clearance `clearance` (both m, negative: violated).
pub(crate) fn first_failure(
    road: &[([f64; 3], f64)],
    obstacle: &[([f64; 3], f64)],
    road_margin: f64,
    clearance: f64,
    tol: f64,
) -> Option<Failure> {
    (1..road.len().min(obstacle.len())).find_map(|k| {
        if obstacle[k].1 + clearance < 0.0 {
            Some(Failure {
                step: k,
                reason: Infeasible::ObstacleClearance,
            })
        } else if road[k].1 + road_margin < -tol {
            Some(Failure {
                step: k,
                reason: Infeasible::RoadBoundary,
            })
        } else {
            None
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rows(rhs: &[f64]) -> Vec<([f64; 3], f64)> {
        rhs.iter().map(|&r| ([0.0; 3], r)).collect()
    }

    #[test]
    fn the_first_violated_row_is_the_failure() {
        // Step 0 (now) is not judged; the clearance and the road margin are added back.
        let road = rows(&[-9.0, 1.0, 0.5, -0.02, -0.3, -1.0]);
        let obstacle = rows(&[-9.0, 2.0, 1.0, 0.2, -0.2, -0.6]);
        assert_eq!(
            first_failure(&road, &obstacle, 0.0, 0.5, 0.05),
            Some(Failure {
                step: 4,
                reason: Infeasible::RoadBoundary
            })
        );
        assert_eq!(
            first_failure(&road, &obstacle, 0.0, 0.1, 0.05),
            Some(Failure {
                step: 4,
                reason: Infeasible::ObstacleClearance
            })
        );
        assert_eq!(first_failure(&road, &obstacle, 1.0, 1.0, 0.05), None);
    }
}
