//! The QP's cost and constraint rows, written by one routine for the pattern at construction
//! and for the values at every solve, so that the two cannot drift apart.

use super::*;

/// Everything the assembly reads (borrowed apart from the QP buffers it writes).
pub(super) struct AssemblyView<'a> {
    pub(super) layout: Layout,
    pub(super) s: &'a MpcSettings,
    pub(super) lin: &'a Plan,
    pub(super) soft: &'a [SoftRows],
    pub(super) reference: &'a Reference,
    pub(super) last_command: BulletInput,
    pub(super) lim: Limits,
}

impl AssemblyView<'_> {
    /// P (upper triangle) and q. Every `put` is unconditional for a given layout: the
    /// pattern is fixed.
    pub(super) fn cost(&self, e: &mut Emitter<'_>, q: &mut [f64]) {
        let l = self.layout;
        let n = self.lin.len();
        let w = &self.s.weights;
        let r = self.reference;
        q.fill(0.0);
        let prox = 2.0 * w.proximal;
        for k in 0..n {
            let c0 = k * l.stage;
            let st = &r.stages[k];
            let (xt, xb) = (&self.lin.xt[k + 1], &self.lin.xb[k + 1]);
            // --- Tracking residuals r_i = r̄_i + Σ c_ij δ_j over the tracked entries
            // X_T, Y_T, ψ_T, vx_T, X_B, Y_B, ψ_B, vx_B.
            let (sn, cs) = xt[2].sin_cos();
            let d = Vec2::new(xb[0] - xt[6], xb[1] - xt[7]);
            let rel = Vec2::new(cs * d.x + sn * d.y, -sn * d.x + cs * d.y);
            let jac: [[f64; 8]; 4] = [
                [-cs, -sn, rel.y, 0.0, cs, sn, 0.0, 0.0],
                [sn, -cs, -rel.x, 0.0, -sn, cs, 0.0, 0.0],
                [0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0, 0.0],
                [0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0],
            ];
            let res = [
                rel.x - st.rel_pos.x,
                rel.y - st.rel_pos.y,
                xb[2] - xt[2] - st.rel_heading,
                xb[3] - xt[0] - st.rel_speed,
            ];
            let we = [w.rel_long, w.rel_lat, w.rel_heading, w.rel_speed].map(|v| v * st.track);
            let mut h = [[0.0; 8]; 8];
            let mut g = [0.0; 8];
            for i in 0..4 {
                for a in 0..8 {
                    g[a] += 2.0 * we[i] * res[i] * jac[i][a];
                    for b in a..8 {
                        h[a][b] += 2.0 * we[i] * jac[i][a] * jac[i][b];
                    }
                }
            }
            // Target objective at the last stage.
            if k == n - 1 {
                let wt = w.target * r.target_weight;
                let eh = xt[2] - r.target_heading;
                h[2][2] += 2.0 * wt * w.target_heading;
                g[2] += 2.0 * wt * w.target_heading * eh;
                h[3][3] += 2.0 * wt * w.target_speed;
                g[3] += 2.0 * wt * w.target_speed * xt[0];
            }
            let mut cols = [0usize; 8];
            for i in 0..4 {
                // The bullet-only layout has no target columns (their entries are unused).
                if l.coupled {
                    cols[i] = c0 + l.o_xt + TRACKED_T[i];
                }
                cols[4 + i] = c0 + l.o_xb + TRACKED_B[i];
            }
            // The bullet-only QP holds the target fixed: only the bullet's entries.
            let first = if l.coupled { 0 } else { 4 };
            for a in first..8 {
                q[cols[a]] += g[a];
                for b in a..8 {
                    e.put(cols[a], cols[b], h[a][b]);
                }
            }
            if l.coupled {
                // vy_T (terminal speed) and the proximal term on the target's states.
                let vy_t = c0 + l.o_xt + 1;
                let wvy = if k == n - 1 {
                    2.0 * w.target * r.target_weight * w.target_speed
                } else {
                    0.0
                };
                e.put(vy_t, vy_t, wvy);
                q[vy_t] += wvy * xt[1];
                for j in 0..l.nt {
                    e.put(c0 + l.o_xt + j, c0 + l.o_xt + j, prox);
                }
            }
            for j in 0..NB {
                e.put(c0 + l.o_xb + j, c0 + l.o_xb + j, prox);
            }
            // --- Inputs: effort, rate (coupled to the previous stage), proximal.
            let u = self.lin.u[k];
            let u_prev = if k == 0 {
                self.last_command
            } else {
                self.lin.u[k - 1]
            };
            let scales = [1.0, self.lim.t_scale];
            let wu = [w.steer, w.torque];
            let wr = [w.steer_rate, w.torque_rate];
            for i in 0..2 {
                let col = c0 + l.o_u + i;
                let ubar = u[i] / scales[i];
                let dbar = (u[i] - u_prev[i]) / scales[i];
                // Effort wu (ū + ũ)²; rate wr (ū_k + ũ_k − ū_{k−1} − ũ_{k−1})².
                let mut diag = 2.0 * wu[i] + 2.0 * wr[i] + prox;
                q[col] += 2.0 * wu[i] * ubar + 2.0 * wr[i] * dbar;
                if k + 1 < n {
                    diag += 2.0 * wr[i];
                    let un = self.lin.u[k + 1];
                    q[col] -= 2.0 * wr[i] * (un[i] - u[i]) / scales[i];
                }
                e.put(col, col, diag);
                if k > 0 {
                    e.put(l.col(k - 1, l.o_u + i), col, -2.0 * wr[i]);
                }
            }
            if l.coupled {
                // --- Force: corridor (Gauss–Newton on the squared distance), proximal.
                let f = self.lin.f[k];
                let fs = self.lim.f_scale;
                let proj = f.x.clamp(st.fn_lo, st.fn_hi);
                let outside = if (f.x - proj).abs() > 0.0 { 1.0 } else { 0.0 };
                let wc = 2.0 * w.corridor * outside;
                let fcol = c0 + l.o_f;
                e.put(fcol, fcol, wc + prox);
                q[fcol] += -wc * proj / fs - prox * f.x / fs;
                e.put(fcol + 1, fcol + 1, prox);
                q[fcol + 1] += -prox * f.y / fs;
            }
            // --- Slack: exact L1 penalty plus a little curvature.
            e.put(c0 + l.o_s, c0 + l.o_s, prox);
            q[c0 + l.o_s] += w.penalty;
        }
    }

    pub(super) fn constraints(&self, e: &mut Emitter<'_>, b: &mut [f64]) {
        self.constraints_trust(e, b, 1.0);
    }

    /// A and b: dynamics (equalities) then the inequality rows of every stage.
    pub(super) fn constraints_trust(&self, e: &mut Emitter<'_>, b: &mut [f64], trust: f64) {
        let l = self.layout;
        let n = self.lin.len();
        let s = self.s;
        let fs = self.lim.f_scale;
        let ts = self.lim.t_scale;
        let n_eq = l.dyn_rows * n;
        for k in 0..n {
            let c0 = k * l.stage;
            let mut r = l.dyn_rows * k;
            let jb = &self.lin.jb[k];
            let f = self.lin.f[k];
            if l.coupled {
                let jt = &self.lin.jt[k];
                for (qi, &i) in TQ[..l.nt].iter().enumerate() {
                    e.put(r, c0 + l.o_xt + qi, 1.0);
                    if k > 0 {
                        for (qj, &j) in TQ[..l.nt].iter().enumerate() {
                            e.put(r, l.col(k - 1, l.o_xt + qj), -jt.a[(i, j)]);
                        }
                    }
                    for c in 0..2 {
                        e.put(r, c0 + l.o_f + c, -jt.f[(i, c)] * fs);
                    }
                    b[r] = -(jt.f[(i, 0)] * f.x + jt.f[(i, 1)] * f.y);
                    r += 1;
                }
            }
            for i in 0..NB {
                e.put(r, c0 + l.o_xb + i, 1.0);
                if k > 0 {
                    for j in 0..NB {
                        e.put(r, l.col(k - 1, l.o_xb + j), -jb.a[(i, j)]);
                    }
                }
                e.put(r, c0 + l.o_u, -jb.b[(i, 0)]);
                e.put(r, c0 + l.o_u + 1, -jb.b[(i, 1)] * ts);
                if l.coupled {
                    for c in 0..2 {
                        e.put(r, c0 + l.o_f + c, -jb.f[(i, c)] * fs);
                    }
                    b[r] = -(jb.f[(i, 0)] * f.x + jb.f[(i, 1)] * f.y);
                } else {
                    b[r] = 0.0;
                }
                r += 1;
            }
        }
        for k in 0..n {
            let c0 = k * l.stage;
            let mut r = n_eq + l.rows * k;
            let u = self.lin.u[k];
            let soft = &self.soft[k];
            let st = &self.reference.stages[k];
            let o_s = c0 + l.o_s;
            let mut row =
                |e: &mut Emitter<'_>, b: &mut [f64], entries: &[(usize, f64)], rhs: f64| {
                    for &(c, v) in entries {
                        e.put(r, c, v);
                    }
                    b[r] = rhs;
                    r += 1;
                };
            // Input bounds ∩ trust region, on ũ.
            let (ts_steer, ts_torque) = (s.trust_steer * trust, s.trust_torque * trust);
            let (cu, ct) = (c0 + l.o_u, c0 + l.o_u + 1);
            let steer_max = self.lim.steer_at(self.lin.xb[k][dynamics::bullet::idx::VX]);
            row(
                e,
                b,
                &[(cu, 1.0)],
                (steer_max - u[0]).min(ts_steer).max(0.0),
            );
            row(
                e,
                b,
                &[(cu, -1.0)],
                (steer_max + u[0]).min(ts_steer).max(0.0),
            );
            row(
                e,
                b,
                &[(ct, 1.0)],
                ((self.lim.torque_max - u[1]) / ts).min(ts_torque).max(0.0),
            );
            row(
                e,
                b,
                &[(ct, -1.0)],
                ((u[1] - self.lim.torque_min) / ts).min(ts_torque).max(0.0),
            );
            // Steer rate.
            let dmax = self.lim.steer_rate * s.dt;
            let u_prev = if k == 0 {
                self.last_command[0]
            } else {
                self.lin.u[k - 1][0]
            };
            let dbar = u[0] - u_prev;
            let prev = l.col(k.saturating_sub(1), l.o_u);
            let couple = if k > 0 { 1.0 } else { 0.0 };
            row(e, b, &[(cu, 1.0), (prev, -couple)], (dmax - dbar).max(0.0));
            row(e, b, &[(cu, -1.0), (prev, couple)], (dmax + dbar).max(0.0));
            // Gap rows on the poses (the target's only in the coupled QP).
            let mut gap_entries = [(0usize, 0.0); 8];
            for j in 0..3 {
                gap_entries[j] = (c0 + l.o_xb + B_POSE[j], soft.gap_b[j]);
                gap_entries[3 + j] = if l.coupled {
                    (c0 + l.o_xt + T_POSE[j], soft.gap_t[j])
                } else {
                    (o_s, 0.0)
                };
            }
            let neg = |v: &[(usize, f64)]| {
                let mut out = [(0usize, 0.0); 8];
                for (o, &(c, x)) in out.iter_mut().zip(v) {
                    *o = (c, -x);
                }
                out
            };
            if l.coupled {
                let (cn, cf) = (c0 + l.o_f, c0 + l.o_f + 1);
                let mu = s.contact.friction;
                // Force bounds and friction cone on f̃ = f / f_scale.
                row(e, b, &[(cn, -1.0)], 0.0);
                row(e, b, &[(cn, 1.0)], soft.fn_max / fs);
                row(e, b, &[(cf, 1.0), (cn, -mu)], 0.0);
                row(e, b, &[(cf, -1.0), (cn, -mu)], 0.0);
                // Penetration law at x_{k+1}: −∇gap·δ − (f_s/k) f̃_n − s ≤ gap.
                let mut ent = neg(&gap_entries);
                ent[6] = (cn, -fs / s.contact.stiffness);
                ent[7] = (o_s, -1.0);
                row(e, b, &ent, soft.gap);
                // Compliance band's upper side, near contact only:
                // F_n/k + gap ≤ band + s.
                let mut ent = gap_entries;
                ent[6] = (cn, fs / s.contact.stiffness);
                ent[7] = (o_s, -1.0);
                let rhs = if soft.band {
                    s.contact.band - soft.gap
                } else {
                    FAR
                };
                row(e, b, &ent, rhs);
            } else {
                // No force: the bullet may not run into the (fixed) target.
                let mut ent = neg(&gap_entries[..3]);
                ent[3] = (o_s, -1.0);
                row(e, b, &ent[..4], soft.gap);
            }
            // Road edges and obstacles, bullet then target.
            let pose_row = |row: &EdgeRowC, off: usize, pose: [usize; 3]| {
                [
                    (c0 + off + pose[0], row.grad[0]),
                    (c0 + off + pose[1], row.grad[1]),
                    (c0 + off + pose[2], row.grad[2]),
                    (o_s, -1.0),
                ]
            };
            row(
                e,
                b,
                &pose_row(&soft.road_b, l.o_xb, B_POSE),
                soft.road_b.rhs,
            );
            row(e, b, &pose_row(&soft.obs_b, l.o_xb, B_POSE), soft.obs_b.rhs);
            if l.coupled {
                row(
                    e,
                    b,
                    &pose_row(&soft.road_t, l.o_xt, T_POSE),
                    soft.road_t.rhs,
                );
                row(e, b, &pose_row(&soft.obs_t, l.o_xt, T_POSE), soft.obs_t.rhs);
            }
            // Envelope on the lateral position in the target frame.
            let xt = &self.lin.xt[k + 1];
            let (sn, cs) = xt[2].sin_cos();
            let mut up = [(0usize, 0.0); 6];
            let mut down = [(0usize, 0.0); 6];
            let gy = [(c0 + l.o_xb, -sn), (c0 + l.o_xb + 1, cs)];
            let gt = [sn, -cs, -soft.rel.x];
            let n_ent = if l.coupled { 6 } else { 3 };
            for (j, &(c, v)) in gy.iter().enumerate() {
                up[j] = (c, v);
                down[j] = (c, -v);
            }
            up[2] = (o_s, -1.0);
            down[2] = (o_s, -1.0);
            if l.coupled {
                for j in 0..3 {
                    let c = c0 + l.o_xt + T_POSE[j];
                    up[3 + j] = (c, gt[j]);
                    down[3 + j] = (c, -gt[j]);
                }
            }
            let dev = soft.rel.y - st.rel_pos.y;
            row(e, b, &up[..n_ent], st.envelope_lat - dev);
            row(e, b, &down[..n_ent], st.envelope_lat + dev);
            // s ≥ 0.
            row(e, b, &[(o_s, -1.0)], 0.0);
            debug_assert_eq!(r, n_eq + l.rows * (k + 1));
        }
    }
}
