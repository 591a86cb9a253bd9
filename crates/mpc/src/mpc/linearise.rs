//! The SCP's model side: the linearisation point and its rollouts, the QP's model error and
//! step size, the soft rows linearised at the rollout, the QP assembled from them, and the
//! nonlinear merit that accepts or rejects a step; the input's checks.

use super::*;

impl CoupledMpc {
    pub(super) fn init_linearisation(&mut self, input: &MpcInput<'_>) {
        let n = self.n;
        if self.have_prev {
            let (u_last, f_last) = (self.prev.u[n - 1], self.prev.f[n - 1]);
            self.lin.u[..n - 1].copy_from_slice(&self.prev.u[1..]);
            self.lin.f[..n - 1].copy_from_slice(&self.prev.f[1..]);
            self.lin.u[n - 1] = u_last;
            self.lin.f[n - 1] = f_last;
        } else {
            self.lin.u.fill(input.last_command);
            self.lin.f.fill(Vec2::zeros());
        }
        // Project onto the bounds and the steer-rate limit.
        let dmax = self.lim.steer_rate * self.settings.dt;
        let steer_max = self.lim.steer_at(input.bullet[dynamics::bullet::idx::VX]);
        let mut prev = input.last_command[0];
        for u in &mut self.lin.u {
            u[0] = u[0]
                .clamp(-steer_max, steer_max)
                .clamp(prev - dmax, prev + dmax);
            u[1] = u[1].clamp(self.lim.torque_min, self.lim.torque_max);
            prev = u[0];
        }
        self.lin.xt[0] = input.target;
        self.lin.xb[0] = input.bullet;
    }

    /// Roll `lin` (or, with `cand`, the candidate) forward through the nonlinear models from
    /// its first state, with Jacobians if `jac`.
    pub(super) fn roll(&mut self, cand: bool, target_input: &TargetInput, jac: bool) {
        let c = &self.settings.contact;
        let ctx = RolloutCtx {
            bullet: &self.bullet,
            shapes: &self.shapes,
            target_input,
            force_max: c.force_max,
            release: c.gap_release,
            friction: c.friction,
        };
        let plan = if cand { &mut self.cand } else { &mut self.lin };
        rollout(&ctx, self.target.as_mut(), plan, jac);
    }

    /// Inputs and forces of the QP solution around `lin`.
    pub(super) fn candidate_from_qp(&mut self) {
        let l = self.layout();
        let x = if self.coupled {
            self.qp_coupled.x()
        } else {
            self.qp_bullet.x()
        };
        for k in 0..self.n {
            let c = k * l.stage;
            self.cand.u[k] = BulletInput::new(
                self.lin.u[k][0] + x[c + l.o_u],
                self.lin.u[k][1] + self.lim.t_scale * x[c + l.o_u + 1],
            );
            self.cand.f[k] = if l.coupled {
                Vec2::new(
                    self.lim.f_scale * x[c + l.o_f],
                    self.lim.f_scale * x[c + l.o_f + 1],
                )
            } else {
                Vec2::zeros()
            };
        }
    }

    /// Largest |x_QP − x_rollout| over the horizon and both vehicles' states, for the last
    /// QP's step (∞-norm, SI units; positions in m, angles in rad, speeds in m/s).
    #[must_use]
    pub fn linearisation_error(&self) -> f64 {
        self.model_error
    }

    /// Per stage of the last QP: the largest |x_QP − x_rollout| and which state it was
    /// (0–7 target, 8–13 bullet).
    #[must_use]
    pub fn linearisation_error_by_stage(&self) -> &[(f64, usize)] {
        &self.stage_error
    }

    pub(super) fn qp_model_error(&mut self) -> f64 {
        let l = self.layout();
        let x = if self.coupled {
            self.qp_coupled.x()
        } else {
            self.qp_bullet.x()
        };
        let mut err: f64 = 0.0;
        for k in 0..self.n {
            let c0 = k * l.stage;
            let mut worst = (0.0, 0);
            for (qi, &i) in TQ.iter().enumerate() {
                let dx = if qi < l.nt { x[c0 + l.o_xt + qi] } else { 0.0 };
                let pred = self.lin.xt[k + 1][i] + dx;
                let e = (pred - self.cand.xt[k + 1][i]).abs();
                if e > worst.0 {
                    worst = (e, i);
                }
            }
            for i in 0..NB {
                let pred = self.lin.xb[k + 1][i] + x[c0 + l.o_xb + i];
                let e = (pred - self.cand.xb[k + 1][i]).abs();
                if e > worst.0 {
                    worst = (e, NT + i);
                }
            }
            self.stage_error[k] = worst;
            err = err.max(worst.0);
        }
        err
    }

    /// Size of the QP's input step relative to the trust region (∞-norm).
    pub(super) fn step_size(&self) -> f64 {
        let l = self.layout();
        let x = self.qp().x();
        let mut s: f64 = 0.0;
        for k in 0..self.n {
            let c = k * l.stage;
            s = s
                .max(x[c + l.o_u].abs() / self.settings.trust_steer)
                .max(x[c + l.o_u + 1].abs() / self.settings.trust_torque);
        }
        s
    }

    /// Linearise the soft constraints along `lin` (states x_1 … x_N).
    pub(super) fn linearise_soft(&mut self, input: &MpcInput<'_>) {
        let s = &self.settings;
        let force_planned = input.reference.stages.iter().any(|st| st.fn_hi > 0.0);
        for k in 0..self.n {
            let (xt, xb) = (&self.lin.xt[k + 1], &self.lin.xb[k + 1]);
            let pt = Vec2::new(xt[6], xt[7]);
            let pb = Vec2::new(xb[0], xb[1]);
            let g = self.lin.pair[k + 1];
            let fb = self.shapes.bullet_obb(xb);
            let ft = self.shapes.target_obb(xt);
            let (gb, gt) = gap_gradient(&fb, &ft, pb, pt, &g);
            let gap_start = self.lin.pair[k].gap;
            let row = &mut self.soft[k];
            row.gap_b = gb;
            row.gap_t = gt;
            row.gap = g.gap;
            // A force only where the linearisation has the vehicles near, and only if the
            // reference plans one somewhere over the horizon: a reference that plans none
            // (a chase) keeps the bullet clear of the target (ramming its rear is no PIT).
            let release = if self.pushing {
                s.contact.gap_release
            } else {
                s.contact.gap_engage
            };
            let near = gap_start.min(g.gap) <= release && force_planned;
            row.fn_max = if near { s.contact.force_max } else { 0.0 };
            row.band = near;
            if let Some(road) = input.road {
                row.road_b = edge_row(road, &fb, pb, s.road_margin).into();
                row.road_t = edge_row(road, &ft, pt, s.road_margin).into();
            } else {
                row.road_b = EdgeRowC::default();
                row.road_t = EdgeRowC::default();
            }
            let t = input.time + (k + 1) as f64 * s.dt;
            row.obs_b = nearest_obstacle(&fb, pb, input.obstacles, t, s.obstacle_clearance);
            row.obs_t = nearest_obstacle(&ft, pt, input.obstacles, t, s.obstacle_clearance);
            let (sn, cs) = xt[2].sin_cos();
            let d = pb - pt;
            row.rel = Vec2Copy {
                x: cs * d.x + sn * d.y,
                y: -sn * d.x + cs * d.y,
            };
            let (ct, cb) = (self.lin.ct[k], self.lin.cb[k]);
            row.gamma = ct.gamma;
            row.point_target = Vec2Copy {
                x: ct.point_in_body.x,
                y: ct.point_in_body.y,
            };
            row.point_bullet = Vec2Copy {
                x: cb.point_in_body.x,
                y: cb.point_in_body.y,
            };
        }
    }

    /// The trajectory the last QP was linearised at: inputs, forces and both vehicles'
    /// states (the `pair` gaps too; Jacobians are not kept).
    #[must_use]
    pub fn linearisation_point(&self) -> &Plan {
        &self.lin_snapshot
    }

    /// The linearisation of stage `k` of the last control step's (last) QP.
    ///
    /// # Panics
    /// If `k` is not below the horizon.
    #[must_use]
    pub fn stage_linearisation(&self, k: usize) -> StageLinearisation {
        let r = &self.soft[k];
        let pair = |e: &EdgeRowC| (e.grad, e.rhs);
        StageLinearisation {
            gamma: r.gamma,
            point_target: Vec2::new(r.point_target.x, r.point_target.y),
            point_bullet: Vec2::new(r.point_bullet.x, r.point_bullet.y),
            gap: r.gap,
            gap_grad_bullet: r.gap_b,
            gap_grad_target: r.gap_t,
            fn_max: r.fn_max,
            band: r.band,
            road_bullet: pair(&r.road_b),
            road_target: pair(&r.road_t),
            obstacle_bullet: pair(&r.obs_b),
            obstacle_target: pair(&r.obs_t),
        }
    }

    /// The merit (cost + penalty · violations, on the nonlinear models and geometry) and the
    /// largest violation of the plan that `u` and `f` produce from the input's states: the
    /// one yardstick for comparing plans, e.g. picopit's against a peer solver's. Forces are
    /// clipped as in every rollout. Overwrites the internal candidate buffer (not the plan).
    ///
    /// # Errors
    /// Non-finite input, or `u`/`f` not of the horizon's length.
    pub fn evaluate(
        &mut self,
        input: &MpcInput<'_>,
        u: &[BulletInput],
        f: &[Vec2],
    ) -> Result<(f64, f64), SolveError> {
        check_input(input, self.n)?;
        if u.len() != self.n || f.len() != self.n {
            return Err(SolveError::Reference);
        }
        self.cand.u.copy_from_slice(u);
        self.cand.f.copy_from_slice(f);
        self.cand.xt[0] = input.target;
        self.cand.xb[0] = input.bullet;
        self.roll(true, &input.target_input, false);
        Ok(self.merit(&self.cand, input))
    }

    pub(super) fn assemble(&mut self, input: &MpcInput<'_>, trust: f64) {
        let view = AssemblyView {
            layout: self.layout(),
            s: &self.settings,
            lin: &self.lin,
            soft: &self.soft,
            reference: input.reference,
            last_command: input.last_command,
            lim: self.lim,
        };
        let qp = if self.coupled {
            &mut self.qp_coupled
        } else {
            &mut self.qp_bullet
        };
        let mut e = Emitter::values(&qp.p_slots, &mut qp.p_val, true);
        view.cost(&mut e, &mut qp.q);
        e.finish();
        let mut e = Emitter::values(&qp.a_slots, &mut qp.a_val, false);
        view.constraints_trust(&mut e, &mut qp.b, trust);
        e.finish();
    }

    /// The QP objective at the linearisation point: zero steps, the forces of `lin`, each
    /// slack at the largest linearised violation of its stage (the same rows the assembly
    /// writes, evaluated at a zero step).
    pub(super) fn objective_at_lin(&mut self, reference: &Reference) -> f64 {
        let l = self.layout();
        let c = &self.settings.contact;
        let qp = if self.coupled {
            &mut self.qp_coupled
        } else {
            &mut self.qp_bullet
        };
        qp.z.fill(0.0);
        for k in 0..self.n {
            let c0 = k * l.stage;
            let row = &self.soft[k];
            let f = self.lin.f[k];
            let f_over_k = if l.coupled { f.x / c.stiffness } else { 0.0 };
            if l.coupled {
                qp.z[c0 + l.o_f] = f.x / self.lim.f_scale;
                qp.z[c0 + l.o_f + 1] = f.y / self.lim.f_scale;
            }
            let st = &reference.stages[k];
            let dev = row.rel.y - st.rel_pos.y;
            let mut s: f64 = 0.0;
            s = s.max(-row.gap - f_over_k);
            s = s.max(-row.road_b.rhs).max(-row.obs_b.rhs);
            s = s.max(dev.abs() - st.envelope_lat);
            if l.coupled {
                s = s.max(-row.road_t.rhs).max(-row.obs_t.rhs);
                if row.band {
                    s = s.max(f_over_k + row.gap - c.band);
                }
            }
            qp.z[c0 + l.o_s] = s.max(0.0);
        }
        qp.objective_at_z()
    }

    /// Merit of a plan: smooth cost + penalty · Σ_k (largest soft violation at step k).
    /// Returns (merit, largest violation).
    pub(super) fn merit(&self, plan: &Plan, input: &MpcInput<'_>) -> (f64, f64) {
        let (smooth, pen, viol) = self.merit_parts(plan, input);
        (smooth + self.settings.weights.penalty * pen, viol)
    }

    pub(super) fn merit_parts(&self, plan: &Plan, input: &MpcInput<'_>) -> (f64, f64, f64) {
        let s = &self.settings;
        let w = &s.weights;
        let r = input.reference;
        let mut cost = 0.0;
        let mut pen = 0.0;
        let mut worst: f64 = 0.0;
        let mut u_prev = input.last_command;
        for k in 0..self.n {
            let (xt, xb) = (&plan.xt[k + 1], &plan.xb[k + 1]);
            let st = &r.stages[k];
            // Tracking.
            let (sn, cs) = xt[2].sin_cos();
            let d = Vec2::new(xb[0] - xt[6], xb[1] - xt[7]);
            let rel = Vec2::new(cs * d.x + sn * d.y, -sn * d.x + cs * d.y);
            let e = [
                rel.x - st.rel_pos.x,
                rel.y - st.rel_pos.y,
                xb[2] - xt[2] - st.rel_heading,
                xb[3] - xt[0] - st.rel_speed,
            ];
            let we = [w.rel_long, w.rel_lat, w.rel_heading, w.rel_speed];
            for i in 0..4 {
                cost += st.track * we[i] * e[i] * e[i];
            }
            // Corridor.
            let f = plan.f[k];
            let dist = (f.x - f.x.clamp(st.fn_lo, st.fn_hi)) / self.lim.f_scale;
            cost += w.corridor * dist * dist;
            // Effort and rate.
            let u = plan.u[k];
            let tn = u[1] / self.lim.t_scale;
            cost += w.steer * u[0] * u[0] + w.torque * tn * tn;
            let du = u - u_prev;
            let dtn = du[1] / self.lim.t_scale;
            cost += w.steer_rate * du[0] * du[0] + w.torque_rate * dtn * dtn;
            u_prev = u;
            // Soft constraints (nonlinear geometry).
            let g = plan.pair[k + 1].gap;
            let f_over_k = f.x / s.contact.stiffness;
            let mut v: f64 = (-g - f_over_k).max(0.0);
            if f.x > 0.0 {
                v = v.max(f_over_k + g - s.contact.band);
            }
            let fb = self.shapes.bullet_obb(xb);
            let ft = self.shapes.target_obb(xt);
            if let Some(road) = input.road {
                v = v.max(s.road_margin - road.edge_distance(&fb));
                v = v.max(s.road_margin - road.edge_distance(&ft));
            }
            let t = input.time + (k + 1) as f64 * s.dt;
            for o in input.obstacles {
                let of = o.footprint_at(t);
                v = v.max(s.obstacle_clearance - obb_signed_distance(&fb, &of));
                v = v.max(s.obstacle_clearance - obb_signed_distance(&ft, &of));
            }
            v = v.max((rel.y - st.rel_pos.y).abs() - st.envelope_lat);
            let v = v.max(0.0);
            pen += v;
            worst = worst.max(v);
        }
        // Target objective at x_N.
        let xt = &plan.xt[self.n];
        let eh = xt[2] - r.target_heading;
        cost += w.target
            * r.target_weight
            * (w.target_heading * eh * eh + w.target_speed * (xt[0] * xt[0] + xt[1] * xt[1]));
        (cost, pen, worst)
    }
}

pub(super) fn nearest_obstacle(
    fp: &dynamics::geometry::Obb,
    cg: Vec2,
    obstacles: &[Obstacle],
    t: f64,
    clearance: f64,
) -> EdgeRowC {
    let mut best = f64::INFINITY;
    let mut which = None;
    for (i, o) in obstacles.iter().enumerate() {
        let d = obb_signed_distance(fp, &o.footprint_at(t));
        if d < best {
            best = d;
            which = Some(i);
        }
    }
    match which {
        Some(i) => {
            let of = obstacles[i].footprint_at(t);
            let g = pair_geometry(fp, &of);
            let (gv, _) = gap_gradient(fp, &of, cg, of.center, &g);
            // gap ≥ clearance − s  ⇔  −∇gap·δ − s ≤ gap − clearance.
            EdgeRowC {
                grad: [-gv[0], -gv[1], -gv[2]],
                rhs: g.gap - clearance,
            }
        }
        None => EdgeRowC::default(),
    }
}

pub(super) fn check_input(input: &MpcInput<'_>, n: usize) -> Result<(), SolveError> {
    let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
    if !finite(input.target.as_slice()) {
        return Err(SolveError::TargetState);
    }
    if !finite(input.bullet.as_slice()) {
        return Err(SolveError::BulletState);
    }
    if !finite(input.target_input.as_slice()) {
        return Err(SolveError::TargetInput);
    }
    if !finite(input.last_command.as_slice()) {
        return Err(SolveError::LastCommand);
    }
    let r = input.reference;
    let ok = r.stages.len() == n
        && r.target_heading.is_finite()
        && r.target_weight.is_finite()
        && r.stages.iter().all(|s| {
            s.rel_pos.iter().all(|v| v.is_finite())
                && s.rel_heading.is_finite()
                && s.rel_speed.is_finite()
                && s.track.is_finite()
                && s.track >= 0.0
                && s.fn_lo.is_finite()
                && s.fn_hi.is_finite()
                && s.envelope_lat.is_finite()
        });
    if ok {
        Ok(())
    } else {
        Err(SolveError::Reference)
    }
}
