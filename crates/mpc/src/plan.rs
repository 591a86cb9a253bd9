//! A predicted trajectory of both vehicles with the inputs and contact forces that produce
//! it, the contact geometry along it and the Jacobians of every step.

use crate::geom::{pair_geometry, PairGeometry};
use dynamics::bullet::{BulletInput, BulletJacobians, BulletModel, BulletState};
use dynamics::geometry::{rotate, Obb, Pose2, Vec2};
use dynamics::params::VehicleParams;
use dynamics::{ContactInput, TargetInput, TargetJacobians, TargetModel, TargetState};

/// One plan over the horizon (all buffers sized at construction).
#[derive(Debug, Clone)]
pub struct Plan {
    /// Bullet inputs `u_0 … u_{N−1}`.
    pub u: Vec<BulletInput>,
    /// Contact forces on the target `f_0 … f_{N−1}` in the contact frame `[F_n, F_t]` (N),
    /// as applied in the prediction (clipped to the gap-dependent bound).
    pub f: Vec<Vec2>,
    /// Target states `x_0 … x_N`.
    pub xt: Vec<TargetState>,
    /// Bullet states `x_0 … x_N`.
    pub xb: Vec<BulletState>,
    /// Bullet–target gap geometry at `x_0 … x_N`.
    pub pair: Vec<PairGeometry>,
    /// The contact as each vehicle receives it over step k.
    pub ct: Vec<ContactInput>,
    pub cb: Vec<ContactInput>,
    /// Step Jacobians (filled by a rollout with Jacobians).
    pub jt: Vec<TargetJacobians>,
    pub jb: Vec<BulletJacobians>,
}

impl Plan {
    #[must_use]
    pub fn new(n: usize) -> Self {
        Self {
            u: vec![BulletInput::zeros(); n],
            f: vec![Vec2::zeros(); n],
            xt: vec![TargetState::zeros(); n + 1],
            xb: vec![BulletState::zeros(); n + 1],
            pair: vec![
                PairGeometry {
                    gap: f64::INFINITY,
                    normal: Vec2::new(1.0, 0.0),
                    point_a: Vec2::zeros(),
                    point_b: Vec2::zeros(),
                };
                n + 1
            ],
            ct: vec![ContactInput::none(); n],
            cb: vec![ContactInput::none(); n],
            jt: vec![TargetJacobians::default(); n],
            jb: vec![BulletJacobians::default(); n],
        }
    }

    /// Horizon length N.
    #[must_use]
    pub fn len(&self) -> usize {
        self.u.len()
    }

    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.u.is_empty()
    }

    /// Copy another plan's inputs, forces, states and contact geometry, not its Jacobians
    /// (no allocation).
    pub fn copy_trajectory_from(&mut self, other: &Self) {
        self.u.copy_from_slice(&other.u);
        self.f.copy_from_slice(&other.f);
        self.xt.copy_from_slice(&other.xt);
        self.xb.copy_from_slice(&other.xb);
        self.pair.copy_from_slice(&other.pair);
        self.ct.copy_from_slice(&other.ct);
        self.cb.copy_from_slice(&other.cb);
    }

    /// Copy another plan of the same horizon, Jacobians included (no allocation).
    pub fn copy_from(&mut self, other: &Self) {
        self.copy_trajectory_from(other);
        self.jt.clone_from_slice(&other.jt);
        self.jb.clone_from_slice(&other.jb);
    }

    /// Whether every input, force and state is finite.
    #[must_use]
    pub fn is_finite(&self) -> bool {
        self.u.iter().all(|v| v.iter().all(|x| x.is_finite()))
            && self.f.iter().all(|v| v.iter().all(|x| x.is_finite()))
            && self.xt.iter().all(|v| v.iter().all(|x| x.is_finite()))
            && self.xb.iter().all(|v| v.iter().all(|x| x.is_finite()))
    }
}

/// Footprints of both vehicles.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Shapes {
    pub bullet: (f64, f64, f64),
    pub target: (f64, f64, f64),
}

impl Shapes {
    pub(crate) fn new(bullet: &VehicleParams, target: &VehicleParams) -> Self {
        Self {
            bullet: (bullet.length, bullet.width, bullet.cg_to_front),
            target: (target.length, target.width, target.cg_to_front),
        }
    }

    pub(crate) fn bullet_obb(&self, xb: &BulletState) -> Obb {
        let (l, w, f) = self.bullet;
        Obb::vehicle_footprint(&Pose2::new(xb[0], xb[1], xb[2]), l, w, f)
    }

    pub(crate) fn target_obb(&self, xt: &TargetState) -> Obb {
        let (l, w, f) = self.target;
        Obb::vehicle_footprint(&Pose2::new(xt[6], xt[7], xt[2]), l, w, f)
    }

    pub(crate) fn pair(&self, xb: &BulletState, xt: &TargetState) -> PairGeometry {
        pair_geometry(&self.bullet_obb(xb), &self.target_obb(xt))
    }
}

/// The normal-force bound at a gap: `force_max` up to a gap of `release`, 0 beyond (no
/// force acts between vehicles that are apart).
#[inline]
#[must_use]
pub fn force_bound(gap: f64, force_max: f64, release: f64) -> f64 {
    if gap <= release {
        force_max
    } else {
        0.0
    }
}

/// What a rollout needs besides the plan.
pub(crate) struct RolloutCtx<'a> {
    pub bullet: &'a BulletModel,
    pub shapes: &'a Shapes,
    pub target_input: &'a TargetInput,
    pub force_max: f64,
    pub release: f64,
    pub friction: f64,
}

/// Roll the nonlinear models forward from `plan.xt[0]`, `plan.xb[0]` with `plan.u` and
/// `plan.f`; forces are first clipped to the corridor the geometry allows (so a rollout never
/// pushes through a gap). With `jac`, every step's Jacobians are stored too.
pub(crate) fn rollout(
    ctx: &RolloutCtx<'_>,
    target: &mut dyn TargetModel,
    plan: &mut Plan,
    jac: bool,
) {
    let n = plan.len();
    for k in 0..n {
        let (xt, xb) = (plan.xt[k], plan.xb[k]);
        let g = ctx.shapes.pair(&xb, &xt);
        plan.pair[k] = g;
        let fmax = force_bound(g.gap, ctx.force_max, ctx.release);
        let fn_ = plan.f[k].x.clamp(0.0, fmax);
        let ft = plan.f[k].y.clamp(-ctx.friction * fn_, ctx.friction * fn_);
        let fc = Vec2::new(fn_, ft);
        plan.f[k] = fc;
        let gamma = g.gamma();
        let ct = ContactInput {
            fc,
            gamma,
            point_in_body: rotate(-xt[2], g.point_b - Vec2::new(xt[6], xt[7])),
        };
        let cb = ContactInput {
            fc,
            gamma,
            point_in_body: rotate(-xb[2], g.point_a - Vec2::new(xb[0], xb[1])),
        };
        plan.ct[k] = ct;
        plan.cb[k] = cb;
        let u = plan.u[k];
        if jac {
            plan.xt[k + 1] = target.step_jac(&xt, ctx.target_input, &ct, &mut plan.jt[k]);
            plan.xb[k + 1] = ctx.bullet.step_jac(&xb, &u, &cb, &mut plan.jb[k]);
        } else {
            plan.xt[k + 1] = target.step(&xt, ctx.target_input, &ct);
            plan.xb[k + 1] = ctx.bullet.step(&xb, &u, &cb);
        }
    }
    plan.pair[n] = ctx.shapes.pair(&plan.xb[n], &plan.xt[n]);
}
