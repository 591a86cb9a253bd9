//! A candidate's convex program: the soft rows linearised at the rollout, the nonlinear
//! merit, the SCP over one Clarabel QP in the forces (evaluate), its starting point, the QP's
//! assembly (one routine writes the pattern at construction and the values at every solve),
//! and the package filled from the chosen candidate.

use super::*;

impl Planner {
    /// Linearise the soft rows at the current rollout.
    pub(super) fn linearise_rows(&mut self, road: &Road, obstacles: &[Obstacle]) {
        let s = &self.settings;
        for k in 1..=self.n {
            let x = self.xs[k];
            let fp = self.footprint(&x);
            let cg = Vec2::new(x[idx::X], x[idx::Y]);
            let r = edge_row(road, &fp, cg, s.road_margin);
            self.road_rows[k] = (r.grad, r.rhs);
            let t = self.time + k as f64 * s.dt;
            let mut row = ([0.0; 3], FAR);
            for o in obstacles {
                let ofp = o.footprint_at(t);
                let g = pair_geometry(&ofp, &fp);
                let rhs = g.gap - s.obstacle_clearance;
                if rhs < row.1 {
                    let (_, gb) = gap_gradient(&ofp, &fp, ofp.center, cg, &g);
                    row = ([-gb[0], -gb[1], -gb[2]], rhs);
                }
            }
            self.obs_rows[k] = row;
        }
        // The stopping point: its road row, chained through the stop pose's Jacobian
        // (central differences of a closed-form map).
        let xn = self.xs[self.n];
        let sp = self.stop_pose(road, &xn);
        let fp = Obb::vehicle_footprint(
            &Pose2::new(sp[0], sp[1], sp[2]),
            self.params.target.length,
            self.params.target.width,
            self.params.target.cg_to_front,
        );
        let r = edge_row(road, &fp, Vec2::new(sp[0], sp[1]), s.road_margin);
        let mut coeff = [0.0; 8];
        for (i, c) in coeff.iter_mut().enumerate() {
            let h = 1e-6 * (1.0 + xn[i].abs());
            let mut xp = xn;
            xp[i] += h;
            let mut xm = xn;
            xm[i] -= h;
            let (p, m) = (self.stop_pose(road, &xp), self.stop_pose(road, &xm));
            *c = (0..3).map(|d| r.grad[d] * (p[d] - m[d]) / (2.0 * h)).sum();
        }
        self.stop_row = (coeff, r.rhs);
    }

    /// The nonlinear objective and violations of the current rollout with `forces`
    /// (or `trial`).
    pub(super) fn merit(&self, use_trial: bool) -> (f64, f64, f64, f64, f64) {
        let s = &self.settings;
        let w = &s.weights;
        let f = if use_trial { &self.trial } else { &self.forces };
        let xn = &self.xs[self.n];
        let h = xn[idx::PSI] + self.yaw_decay() * xn[idx::R] - self.psi_rev;
        let v2 = xn[idx::VX].powi(2) + xn[idx::VY].powi(2);
        let hi = s.corridor_fraction * self.force_max;
        let mut j = w.lambda_t * (w.heading * h * h + w.speed * v2);
        let mut prev = Vec2::zeros();
        for fj in f.iter() {
            let e = ((fj.x - hi) / self.scale).max(0.0);
            j += w.lambda_t * w.corridor * e * e + w.effort * (fj.x / self.scale).powi(2);
            j += w.smooth * ((fj - prev) / self.scale).norm_squared();
            prev = *fj;
        }
        j += w.smooth * (prev / self.scale).norm_squared();
        // The rows' right-hand sides are the exact margins at the rollout they were
        // linearised at (call after `linearise_rows`): road margin beyond `road_margin`,
        // obstacle gap beyond d_safe, the stopping point's road margin.
        let mut road_margin = f64::INFINITY;
        let mut clearance = f64::INFINITY;
        let mut pen = 0.0;
        for k in 1..=self.n {
            road_margin = road_margin.min(self.road_rows[k].1);
            clearance = clearance.min(self.obs_rows[k].1 + s.obstacle_clearance);
            pen += (-self.road_rows[k].1).max(0.0) + (-self.obs_rows[k].1).max(0.0);
        }
        let stop_margin = self.stop_row.1;
        pen += (-stop_margin).max(0.0);
        let objective = j + w.penalty * pen;
        (
            objective,
            wrap(h).abs(),
            road_margin,
            clearance,
            stop_margin,
        )
    }

    /// Optimise the forces of one candidate; `None` if the rollout or the QP fails.
    pub(super) fn evaluate(
        &mut self,
        side: Side,
        k0: usize,
        lane: f64,
        input: &PlannerInput<'_>,
    ) -> Option<Outcome> {
        self.setup_candidate(side, k0, lane);
        self.initial_guess(input);
        self.rollout(Some(input.road), &input.target, false, true);
        self.linearise_rows(input.road, input.obstacles);
        let mut current = self.merit(false);
        if !current.0.is_finite() {
            return None;
        }
        let mut trust = self.settings.trust_force_g * self.weight;
        for _ in 0..self.settings.scp_iterations {
            self.fill_qp(trust);
            let st = self.qp.solve();
            if !st.usable() {
                if st == QpStatus::MaxTime || st == QpStatus::MaxIterations {
                    break;
                }
                return None;
            }
            let l = Layout::new(&self.settings);
            for j in 0..self.w {
                let y = self.qp.x();
                let d = Vec2::new(y[l.force(j)], y[l.force(j) + 1]) * self.scale;
                let f = self.forces[j] + d;
                // Project onto the hard corridor (the QP holds it to its tolerance).
                let fx = f.x.clamp(0.0, self.force_max);
                let mu_c = self.settings.friction;
                let ft = self.friction_sign() * f.y;
                self.trial[j] = Vec2::new(fx, self.friction_sign() * ft.clamp(0.0, mu_c * fx));
            }
            // Evaluate the candidate step on the nonlinear rollout.
            self.rollout(Some(input.road), &input.target, true, true);
            self.linearise_rows(input.road, input.obstacles);
            let cand = self.merit(true);
            if cand.0.is_finite() && cand.0 <= current.0 {
                self.forces.copy_from_slice(&self.trial);
                current = cand;
            } else {
                // Rejected: back to the accepted forces, a smaller trust region.
                trust *= 0.3;
                self.rollout(Some(input.road), &input.target, false, true);
                self.linearise_rows(input.road, input.obstacles);
            }
        }
        let delay = self.settings.weights.delay * k0 as f64 * self.settings.dt;
        Some(Outcome {
            side,
            k0,
            contact_x: self.contact_x,
            objective: current.0 + delay,
            heading_error: projected_heading_error(
                &self.xs[self.n],
                self.yaw_decay(),
                self.psi_rev,
            ),
            road_margin: current.2,
            clearance: current.3,
            stop_margin: current.4,
        })
    }

    /// The SCP's starting point: the best of a small grid of constant pushes (level ×
    /// duration from the window's start) by the nonlinear merit, rolled out without
    /// Jacobians. The yaw response to a push is strongly nonlinear (the tyres saturate), so
    /// one fixed guess can start the SCP far beyond the reversed heading.
    pub(super) fn initial_guess(&mut self, input: &PlannerInput<'_>) {
        const LEVELS: [f64; 6] = [0.0, 0.15, 0.3, 0.5, 0.75, 1.0];
        const DURATIONS: [f64; 3] = [0.34, 0.67, 1.0];
        let top = self.settings.force_guess_g * self.weight * 2.0;
        let mut best = (f64::INFINITY, 0.0, 0usize);
        for &d in &DURATIONS {
            let m = ((d * self.w as f64).round() as usize).clamp(1, self.w);
            for &lv in &LEVELS[1..] {
                let f = (lv * top).min(self.force_max);
                for (j, t) in self.trial.iter_mut().enumerate() {
                    *t = if j < m {
                        Vec2::new(f, 0.0)
                    } else {
                        Vec2::zeros()
                    };
                }
                self.rollout(Some(input.road), &input.target, true, false);
                self.linearise_rows(input.road, input.obstacles);
                let merit = self.merit(true).0;
                if merit < best.0 {
                    best = (merit, f, m);
                }
            }
        }
        let (_, f, m) = best;
        for (j, t) in self.forces.iter_mut().enumerate() {
            *t = if j < m {
                Vec2::new(f, 0.0)
            } else {
                Vec2::zeros()
            };
        }
    }

    /// Write the QP's data at the current linearisation (values mode).
    pub(super) fn fill_qp(&mut self, trust: f64) {
        let view = RowsView {
            l: Layout::new(&self.settings),
            s: &self.settings,
            scale: self.scale,
            force_max: self.force_max,
            trust,
            friction_sign: self.friction_sign(),
            forces: &self.forces,
            xn: &self.xs[self.n],
            psi_rev: self.psi_rev,
            tau: self.yaw_decay(),
            sens: &self.sens,
            road_rows: &self.road_rows,
            obs_rows: &self.obs_rows,
            stop_row: &self.stop_row,
        };
        let qp = &mut self.qp;
        let mut ep = Emitter::values(&qp.p_slots, &mut qp.p_val, true);
        let mut ea = Emitter::values(&qp.a_slots, &mut qp.a_val, false);
        assemble(&view, &mut ep, &mut ea, &mut qp.q, &mut qp.b);
        ep.finish();
        ea.finish();
    }

    pub(super) fn fill_package(
        &mut self,
        mode: Mode,
        infeasible: Option<Infeasible>,
        chosen: Option<Outcome>,
        lane: f64,
        input: &PlannerInput<'_>,
    ) {
        if let Some(o) = chosen {
            self.contact_x = o.contact_x;
            self.setup_candidate(o.side, o.k0, lane);
        }
        self.rollout(Some(input.road), &input.target, false, false);
        self.linearise_rows(input.road, input.obstacles);
        let merit = self.merit(false);
        let tau = self.yaw_decay();
        let s = &self.settings;
        let c = self.contact_pose(self.side);
        let lateral_speed =
            self.crossing_speed(self.side, input.road, &input.target, &input.bullet);
        let standoff = self.standoff(self.side);
        let p = &mut self.package;
        p.mode = mode;
        p.infeasible = infeasible;
        p.race_lost = false;
        p.hold_back = false;
        p.time = input.time;
        p.side = self.side;
        p.contact_point = self.contact_point;
        p.contact_rel_pos = c.rel_pos;
        p.contact_rel_heading = c.rel_heading;
        p.push_speed = s.push_speed;
        p.envelope_lat = c.envelope_lat;
        p.approach = Profile::with_brake_margin(
            crate::href::relative_position(&input.target, &input.bullet).x,
            crate::href::relative_velocity(&input.target, &input.bullet).x,
            c.rel_pos.x,
            s.approach_accel(self.mu),
            s.approach_speed,
            BRAKE_MARGIN,
        );
        p.lateral_speed = lateral_speed;
        p.standoff = standoff;
        p.window = match chosen {
            Some(o) => (
                input.time + o.k0 as f64 * s.dt,
                input.time + (o.k0 + self.w) as f64 * s.dt,
            ),
            None => (f64::INFINITY, f64::NEG_INFINITY),
        };
        p.terminal = TerminalSet {
            heading: self.psi_rev,
            heading_tol: s.heading_tol,
            yaw_decay: tau,
        };
        p.road_margin = s.road_margin;
        p.obstacle_clearance = s.obstacle_clearance;
        p.obstacles.clear();
        p.obstacles.extend(input.obstacles.iter().cloned());
        p.steps.clear();
        let hi_comfort = s.corridor_fraction * self.force_max;
        for k in 0..=self.n {
            let in_window = chosen.is_some() && k >= self.k0 && k < self.k0 + self.w;
            let f = if in_window {
                self.forces[k - self.k0]
            } else {
                Vec2::zeros()
            };
            let corridor = if in_window {
                (
                    0.5 * f.x,
                    (1.5 * f.x)
                        .max(f.x + 0.1 * self.force_max)
                        .min(hi_comfort.max(f.x)),
                )
            } else {
                (0.0, 0.0)
            };
            p.steps.push(PlanStep {
                time: input.time + k as f64 * s.dt,
                force: f,
                corridor,
                target: self.xs[k],
            });
        }
        p.predicted_heading_error = projected_heading_error(&self.xs[self.n], tau, self.psi_rev);
        p.predicted_road_margin = merit.2;
        p.predicted_clearance = merit.3;
        p.predicted_stop_margin = merit.4;
        p.objective = chosen.map_or(merit.0, |o| o.objective);
    }
}

/// What the QP assembly reads.
pub(super) struct RowsView<'a> {
    l: Layout,
    s: &'a PlannerSettings,
    scale: f64,
    force_max: f64,
    trust: f64,
    friction_sign: f64,
    forces: &'a [Vec2],
    xn: &'a TargetState,
    psi_rev: f64,
    /// The yaw decay of the projected heading ([`Planner::yaw_decay`]).
    tau: f64,
    sens: &'a [f64],
    road_rows: &'a [([f64; 3], f64)],
    obs_rows: &'a [([f64; 3], f64)],
    stop_row: &'a ([f64; 8], f64),
}

impl RowsView<'_> {
    pub(super) fn sens(&self, k: usize, state: usize, c: usize) -> f64 {
        let cols = 2 * self.l.w;
        self.sens[k * 8 * cols + state * cols + c]
    }
}

/// Placeholder data of the right sizes for the pattern pass.
pub(super) struct DummyRows {
    l: Layout,
    forces: Vec<Vec2>,
    xn: TargetState,
    sens: Vec<f64>,
    rows: Vec<([f64; 3], f64)>,
    stop: ([f64; 8], f64),
}

impl DummyRows {
    pub(super) fn new(l: Layout) -> Self {
        Self {
            l,
            forces: vec![Vec2::zeros(); l.w],
            xn: TargetState::zeros(),
            sens: vec![0.0; (l.n + 1) * 8 * 2 * l.w],
            rows: vec![([0.0; 3], FAR); l.n + 1],
            stop: ([0.0; 8], FAR),
        }
    }

    pub(super) fn view<'a>(&'a self, s: &'a PlannerSettings) -> RowsView<'a> {
        RowsView {
            l: self.l,
            s,
            scale: 1.0,
            force_max: 1.0,
            trust: 1.0,
            friction_sign: 1.0,
            forces: &self.forces,
            xn: &self.xn,
            psi_rev: 0.0,
            tau: s.yaw_decay,
            sens: &self.sens,
            road_rows: &self.rows,
            obs_rows: &self.rows,
            stop_row: &self.stop,
        }
    }
}

/// The QP in the scaled force steps y = δF / S: one code path writes the pattern (at
/// construction) and the values (every iteration), every entry unconditionally.
pub(super) fn assemble(
    v: &RowsView<'_>,
    ep: &mut Emitter<'_>,
    ea: &mut Emitter<'_>,
    q: &mut [f64],
    b: &mut [f64],
) {
    let l = v.l;
    let s = v.s;
    let w = &s.weights;
    let cols = 2 * l.w;
    q.fill(0.0);
    b.fill(0.0);
    // --- Objective. Terminal rows: projected heading, vx, vy (each a row g over y, value h).
    let tau = v.tau;
    let h_psi = v.xn[idx::PSI] + tau * v.xn[idx::R] - v.psi_rev;
    let terms = [
        (w.lambda_t * w.heading, h_psi, 0usize),
        (w.lambda_t * w.speed, v.xn[idx::VX], 1),
        (w.lambda_t * w.speed, v.xn[idx::VY], 2),
    ];
    let n = l.n;
    let g = |which: usize, c: usize| -> f64 {
        match which {
            0 => v.sens(n, idx::PSI, c) + tau * v.sens(n, idx::R, c),
            1 => v.sens(n, idx::VX, c),
            _ => v.sens(n, idx::VY, c),
        }
    };
    // P over the force block: Σ 2 w g gᵀ (dense upper triangle), plus the diagonal terms.
    for c2 in 0..cols {
        for c1 in 0..=c2 {
            let mut val = 0.0;
            for &(wt, _, which) in &terms {
                val += 2.0 * wt * g(which, c1) * g(which, c2);
            }
            ep.put(c1, c2, val);
        }
    }
    for &(wt, h, which) in &terms {
        for (c, qc) in q.iter_mut().enumerate().take(cols) {
            *qc += 2.0 * wt * h * g(which, c);
        }
    }
    // Effort, proximal and smoothness on the forces (scaled units).
    for j in 0..l.w {
        let f = v.forces[j] / v.scale;
        let (cn, ct) = (l.force(j), l.force(j) + 1);
        ep.put(cn, cn, 2.0 * (w.effort + w.proximal));
        ep.put(ct, ct, 2.0 * w.proximal);
        q[cn] += 2.0 * w.effort * f.x;
        // Smoothness: (F_j − F_{j−1})² with F_{−1} = F_W = 0.
        for d in 0..2 {
            let c = l.force(j) + d;
            let fj = if d == 0 { f.x } else { f.y };
            let prev = if j > 0 {
                let p = v.forces[j - 1] / v.scale;
                if d == 0 {
                    p.x
                } else {
                    p.y
                }
            } else {
                0.0
            };
            let next = if j + 1 < l.w {
                let p = v.forces[j + 1] / v.scale;
                if d == 0 {
                    p.x
                } else {
                    p.y
                }
            } else {
                0.0
            };
            ep.put(c, c, 4.0 * w.smooth);
            q[c] += 2.0 * w.smooth * (2.0 * fj - prev - next);
            if j + 1 < l.w {
                ep.put(c, c + 2, -2.0 * w.smooth);
            }
        }
        // Corridor excess e_j ≥ F_n − F_hi, cost λ w_c e².
        ep.put(l.excess(j), l.excess(j), 2.0 * w.lambda_t * w.corridor);
    }
    // Slacks: linear penalty.
    for i in 0..l.soft() {
        q[l.s_road(i)] = w.penalty;
        q[l.s_obs(i)] = w.penalty;
    }
    q[l.s_stop()] = w.penalty;
    // --- Constraints A y ≤ b.
    let mut row = 0usize;
    let mu = s.friction;
    let trust = v.trust / v.scale;
    let fmax = v.force_max / v.scale;
    let hi = s.corridor_fraction * fmax;
    for j in 0..l.w {
        let f = v.forces[j] / v.scale;
        let (cn, ct) = (l.force(j), l.force(j) + 1);
        // 0 ≤ F_n ≤ F_max.
        ea.put(row, cn, -1.0);
        b[row] = f.x;
        row += 1;
        ea.put(row, cn, 1.0);
        b[row] = fmax - f.x;
        row += 1;
        // Friction: 0 ≤ σ F_t ≤ μ F_n, σ the sign of the bullet's sliding along the target's
        // side (its push speed): friction drags the target the way the bullet moves.
        let sg = v.friction_sign;
        ea.put(row, ct, sg);
        ea.put(row, cn, -mu);
        b[row] = mu * f.x - sg * f.y;
        row += 1;
        ea.put(row, ct, -sg);
        b[row] = sg * f.y;
        row += 1;
        // Trust region.
        for (c, sign) in [(cn, 1.0), (cn, -1.0), (ct, 1.0), (ct, -1.0)] {
            ea.put(row, c, sign);
            b[row] = trust;
            row += 1;
        }
        // Corridor excess: F_n − e ≤ F_hi, e ≥ 0.
        ea.put(row, cn, 1.0);
        ea.put(row, l.excess(j), -1.0);
        b[row] = hi - f.x;
        row += 1;
        ea.put(row, l.excess(j), -1.0);
        row += 1;
    }
    // Road and obstacle rows per step: grad · (∂pose_k/∂y) y − s_k ≤ rhs_k.
    let pose = [idx::X, idx::Y, idx::PSI];
    for (rows, slack) in [(v.road_rows, 0usize), (v.obs_rows, 1)] {
        for i in 0..l.soft() {
            let k = l.soft_step(i);
            let (grad, rhs) = rows[k];
            for c in 0..cols {
                let mut val = 0.0;
                for d in 0..3 {
                    val += grad[d] * v.sens(k, pose[d], c);
                }
                ea.put(row, c, val);
            }
            let sc = if slack == 0 { l.s_road(i) } else { l.s_obs(i) };
            ea.put(row, sc, -1.0);
            b[row] = rhs;
            row += 1;
        }
    }
    // The stopping point.
    let (coeff, rhs) = v.stop_row;
    for c in 0..cols {
        let mut val = 0.0;
        for (i, ci) in coeff.iter().enumerate() {
            val += ci * v.sens(n, i, c);
        }
        ea.put(row, c, val);
    }
    ea.put(row, l.s_stop(), -1.0);
    b[row] = *rhs;
    row += 1;
    // Slacks ≥ 0.
    for i in 0..l.soft() {
        ea.put(row, l.s_road(i), -1.0);
        row += 1;
        ea.put(row, l.s_obs(i), -1.0);
        row += 1;
    }
    ea.put(row, l.s_stop(), -1.0);
    row += 1;
    debug_assert_eq!(row, l.rows());
    let _ = cols;
}
