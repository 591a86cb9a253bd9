//! Contact within the plant: the footprints at bumper height, the vehicle–vehicle and
//! obstacle contact forces of one step gathered per vehicle ([`External`]), and the
//! running average of the vehicle–vehicle contact a logger takes.

use super::{ContactReport, ObstacleContact, Plant};
use crate::contact::{obb_contact, ContactGeometry};
use crate::geometry::{cross, rotate, Obb, Pose2, Vec2};

/// External forces gathered for one vehicle during a step (world frame).
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct External {
    pub(super) force: Vec2,
    pub(super) moment: f64,
    /// Sum of contact forces (they act at bumper height, so they roll and pitch the body).
    pub(super) contact_force: Vec2,
}

impl External {
    #[inline]
    fn add(&mut self, f: Vec2, at: Vec2, cg: Vec2) {
        self.force += f;
        self.contact_force += f;
        self.moment += cross(at - cg, f);
    }
}

#[derive(Debug, Clone, Copy, Default)]
pub(super) struct ContactAccumulator {
    impulse_fn: f64,
    impulse_ft: f64,
    normal_weighted: Vec2,
    point_world: Vec2,
    point_target: Vec2,
    point_bullet: Vec2,
    depth_max: f64,
    pub(super) since: f64,
}

impl Plant {
    /// The contact forces of this step, per vehicle: the vehicle–vehicle contact (recorded
    /// and accumulated for the average) and every obstacle touch (the strongest recorded).
    pub(super) fn contact_forces(&mut self, dt: f64) -> [External; 2] {
        let mut ext = [External::default(); 2];
        let fps = [self.footprint(0), self.footprint(1)];

        // Vehicle–vehicle contact.
        self.contact = None;
        if may_overlap(&fps[0], &fps[1]) {
            if let Some(geom) = obb_contact(&fps[0], &fps[1]) {
                let report = self.vehicle_contact(&geom, &mut ext);
                self.accumulate(&report, dt);
                self.contact = Some(report);
            }
        }
        // Obstacles.
        self.obstacle_contacts = [None; 2];
        for (k, obstacle) in self.obstacles.iter().enumerate() {
            let ofp = obstacle.footprint_at(self.time);
            let v_obs = Vec2::new(obstacle.vx, obstacle.vy);
            for i in 0..2 {
                if !may_overlap(&fps[i], &ofp) {
                    continue;
                }
                if let Some(geom) = obb_contact(&fps[i], &ofp) {
                    // Normal from the vehicle into the obstacle; the obstacle is body B.
                    let v_rel = v_obs - self.body_point_velocity(i, geom.point);
                    let fc = self.obstacle_law.force(
                        &geom,
                        v_rel,
                        [self.inertia_at(i, geom.point), (0.0, 0.0, Vec2::zeros())],
                    );
                    let f_world = rotate(geom.gamma(), fc);
                    ext[i].add(-f_world, geom.point, self.bodies[i].pos);
                    let stronger = self.obstacle_contacts[i].is_none_or(|c| c.normal_force < fc.x);
                    if stronger {
                        self.obstacle_contacts[i] = Some(ObstacleContact {
                            obstacle: k,
                            normal_force: fc.x,
                        });
                    }
                }
            }
        }
        ext
    }

    /// The contact averaged since the last call (impulse over the elapsed time, the normal
    /// and points weighted by the normal impulse), and restart averaging. `None` when the
    /// vehicles did not touch in that interval. This is what a 20 Hz logger records.
    pub fn take_contact_average(&mut self) -> Option<ContactReport> {
        let a = std::mem::take(&mut self.accum);
        if a.impulse_fn <= 0.0 || a.since <= 0.0 {
            return None;
        }
        let w = 1.0 / a.impulse_fn;
        Some(ContactReport {
            fc: Vec2::new(a.impulse_fn / a.since, a.impulse_ft / a.since),
            gamma: a.normal_weighted.y.atan2(a.normal_weighted.x),
            point_in_world: a.point_world * w,
            point_in_target: a.point_target * w,
            point_in_bullet: a.point_bullet * w,
            depth: a.depth_max,
        })
    }

    /// Footprints (bullet, target) now.
    #[must_use]
    pub fn footprints(&self) -> [Obb; 2] {
        [self.footprint(0), self.footprint(1)]
    }

    /// The body rectangle at bumper height: it moves with the sprung mass, by
    /// `(h_b θ, (h_b − h_ra) φ)` relative to the roll/pitch axes.
    #[inline]
    fn footprint(&self, i: usize) -> Obb {
        let c = &self.chassis[i];
        let b = &self.bodies[i];
        let origin = b.pos + rotate(b.yaw, c.bumper_offset(b) - c.cg_offset(b));
        Obb::vehicle_footprint(
            &Pose2 {
                p_in_world: origin,
                yaw: b.yaw,
            },
            c.length,
            c.width,
            c.cg_to_front,
        )
    }

    /// Velocity of the body point at world position `p` at bumper height (rigid yaw plus
    /// the roll/pitch motion of the sprung mass relative to the c.g.).
    #[inline]
    fn body_point_velocity(&self, i: usize, p: Vec2) -> Vec2 {
        let c = &self.chassis[i];
        let b = &self.bodies[i];
        b.point_velocity(p) + rotate(b.yaw, c.bumper_rate(b) - c.cg_rate(b))
    }

    fn vehicle_contact(&self, geom: &ContactGeometry, ext: &mut [External; 2]) -> ContactReport {
        let (bullet, target) = (&self.bodies[0], &self.bodies[1]);
        let v_rel =
            self.body_point_velocity(1, geom.point) - self.body_point_velocity(0, geom.point);
        let fc = self.law.force(
            geom,
            v_rel,
            [
                self.inertia_at(0, geom.point),
                self.inertia_at(1, geom.point),
            ],
        );
        let gamma = geom.gamma();
        let f_world = rotate(gamma, fc);
        ext[1].add(f_world, geom.point, target.pos);
        ext[0].add(-f_world, geom.point, bullet.pos);
        ContactReport {
            fc,
            gamma,
            point_in_world: geom.point,
            point_in_target: rotate(-target.yaw, geom.point - target.pos),
            point_in_bullet: rotate(-bullet.yaw, geom.point - bullet.pos),
            depth: geom.depth,
        }
    }

    /// `(1/m, 1/I_z, arm from the c.g. to p)` of vehicle `i`, for the contact law.
    #[inline]
    fn inertia_at(&self, i: usize, p: Vec2) -> (f64, f64, Vec2) {
        let c = &self.chassis[i];
        (c.inv_m, c.inv_iz, p - self.bodies[i].pos)
    }

    fn accumulate(&mut self, r: &ContactReport, dt: f64) {
        let w = r.fc.x * dt;
        let a = &mut self.accum;
        a.impulse_fn += w;
        a.impulse_ft += r.fc.y * dt;
        a.normal_weighted += Vec2::new(r.gamma.cos(), r.gamma.sin()) * w;
        a.point_world += r.point_in_world * w;
        a.point_target += r.point_in_target * w;
        a.point_bullet += r.point_in_bullet * w;
        a.depth_max = a.depth_max.max(r.depth);
    }
}

/// Broad phase: bounding circles.
#[inline]
fn may_overlap(a: &Obb, b: &Obb) -> bool {
    let r = a.half.norm() + b.half.norm();
    (a.center - b.center).norm_squared() < r * r
}
