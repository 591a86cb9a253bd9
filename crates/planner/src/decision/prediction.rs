//! A candidate's prediction: the target's rollout under the candidate's virtual push, its
//! chained sensitivities to the forces, the footprint and the post-PIT stopping point.

use super::*;

impl Planner {
    pub(super) fn setup_candidate(&mut self, side: Side, k0: usize, lane: f64) {
        self.side = side;
        self.k0 = k0;
        let t = &self.params.target;
        self.contact_point = Vec2::new(self.contact_x, side.sign() * 0.5 * t.width);
        // Pushing the rear quarter to the right (bullet on the left) yaws the target
        // counter-clockwise: the reversed heading is reached by spinning that way.
        self.psi_rev = lane + side.sign() * std::f64::consts::PI;
    }

    /// The contact input of step k for the force f (N): the normal is the target's side
    /// normal (from the bullet into the target) at the step's heading.
    pub(super) fn contact(&self, k: usize, f: Vec2, psi: f64) -> ContactInput {
        if k < self.k0 || k >= self.k0 + self.w {
            return ContactInput::none();
        }
        ContactInput {
            fc: f,
            gamma: psi - self.side.sign() * std::f64::consts::FRAC_PI_2,
            point_in_body: self.contact_point,
        }
    }

    /// A lane keeper (gain 1) of the lane centre nearest to the target now.
    pub(super) fn lane_keeper_of(&self, input: &PlannerInput<'_>) -> LaneKeeper {
        let road = input.road;
        let d = road
            .project(Vec2::new(input.target[idx::X], input.target[idx::Y]))
            .d;
        let lanes = road.spec().lanes;
        let offset = (0..lanes)
            .map(|l| road.lane_center_offset(l))
            .min_by(|a, b| (a - d).abs().total_cmp(&(b - d).abs()))
            .unwrap_or(0.0);
        LaneKeeper {
            offset,
            gain: 1.0,
            wheelbase: self.params.target.wheelbase(),
        }
    }

    /// How the rollout the rows were last linearised at fails first ([`race::first_failure`]).
    pub(super) fn free_failure(&self) -> Option<race::Failure> {
        let s = &self.settings;
        race::first_failure(
            &self.road_rows,
            &self.obs_rows,
            s.road_margin,
            s.obstacle_clearance,
            s.violation_tol,
        )
    }

    /// Roll out with `forces` from `x0`; with `jac`, store the Jacobians and sensitivities.
    /// With a lane keeper and a road, the driver's steer follows the predicted state (and
    /// its gradient enters ∂x⁺/∂x); otherwise the command `input_u` is held.
    pub(super) fn rollout(
        &mut self,
        road: Option<&Road>,
        x0: &TargetState,
        use_trial: bool,
        jac: bool,
    ) {
        self.xs[0] = *x0;
        let mut hint = f64::NAN;
        for k in 0..self.n {
            let f = if k >= self.k0 && k < self.k0 + self.w {
                let j = k - self.k0;
                if use_trial {
                    self.trial[j]
                } else {
                    self.forces[j]
                }
            } else {
                Vec2::zeros()
            };
            let c = self.contact(k, f, self.xs[k][idx::PSI]);
            let x = self.xs[k];
            let (u, grad) = match (self.lane_keeper, road) {
                (Some(lk), Some(road)) => {
                    let p = Vec2::new(x[idx::X], x[idx::Y]);
                    let fr = if hint.is_finite() {
                        road.project_with_hint(p, hint)
                    } else {
                        road.project(p)
                    };
                    hint = fr.s;
                    let (steer, g) = lk.steer_and_gradient(&x, &fr);
                    (TargetInput::new(steer, self.input_u[1]), Some(g))
                }
                _ => (self.input_u, None),
            };
            if jac {
                let next = self.model.step_jac(&x, &u, &c, &mut self.jac);
                let mut a = self.jac.a;
                if let Some(g) = grad {
                    // The driver's steer follows the state: ∂x⁺/∂x += ∂x⁺/∂δ · ∂δ/∂x.
                    a += self.jac.b.column(0) * g.transpose();
                }
                if k >= self.k0 && k < self.k0 + self.w {
                    // γ turns with ψ: add ∂x⁺/∂γ = F · (J f_c) to the heading column.
                    let jf = Vec2::new(-c.fc.y, c.fc.x);
                    for r in 0..8 {
                        a[(r, idx::PSI)] += self.jac.f[(r, 0)] * jf.x + self.jac.f[(r, 1)] * jf.y;
                    }
                }
                self.jac_a[k] = a;
                self.jac_f[k] = self.jac.f;
                self.xs[k + 1] = next;
            } else {
                self.xs[k + 1] = self.model.step(&x, &u, &c);
            }
        }
        if jac {
            self.propagate_sensitivities();
        }
    }

    pub(super) fn propagate_sensitivities(&mut self) {
        let cols = 2 * self.w;
        let stride = 8 * cols;
        self.sens[..stride].fill(0.0);
        for k in 0..self.n {
            let (head, tail) = self.sens.split_at_mut((k + 1) * stride);
            let g = &head[k * stride..];
            let next = &mut tail[..stride];
            let a = &self.jac_a[k];
            for r in 0..8 {
                for c in 0..cols {
                    let mut v = 0.0;
                    for i in 0..8 {
                        v += a[(r, i)] * g[i * cols + c];
                    }
                    next[r * cols + c] = v;
                }
            }
            if k >= self.k0 && k < self.k0 + self.w {
                let j = k - self.k0;
                let f = &self.jac_f[k];
                for r in 0..8 {
                    next[r * cols + 2 * j] += f[(r, 0)] * self.scale;
                    next[r * cols + 2 * j + 1] += f[(r, 1)] * self.scale;
                }
            }
        }
    }

    /// Signed distance between the two vehicles' footprints (m).
    pub(super) fn gap(&self, xt: &TargetState, xb: &BulletState) -> f64 {
        self.pair(xt, xb).gap
    }

    /// The two vehicles' footprint geometry (bullet first).
    pub(super) fn pair(&self, xt: &TargetState, xb: &BulletState) -> PairGeometry {
        let b = &self.params.bullet;
        let fb = Obb::vehicle_footprint(
            &Pose2::new(xb[0], xb[1], xb[2]),
            b.length,
            b.width,
            b.cg_to_front,
        );
        pair_geometry(&fb, &self.footprint(xt))
    }

    pub(super) fn footprint(&self, x: &TargetState) -> Obb {
        let t = &self.params.target;
        Obb::vehicle_footprint(
            &Pose2::new(x[idx::X], x[idx::Y], x[idx::PSI]),
            t.length,
            t.width,
            t.cg_to_front,
        )
    }

    /// Where the target comes to rest if it slides on from `x` at a constant deceleration
    /// (a fraction of μ g), its pose `[X, Y, ψ]`: the slide is split into its components
    /// along and across the road at the target, and carried along the road's reference line
    /// (so that on a curve a target sliding along the lane stays in it), heading turning
    /// with the road.
    pub(super) fn stop_pose(&self, road: &Road, x: &TargetState) -> [f64; 3] {
        let v = rotate(x[idx::PSI], Vec2::new(x[idx::VX], x[idx::VY]));
        let decel = self.stop_decel(x);
        let t = v.norm() / (2.0 * decel);
        let f = road.project(Vec2::new(x[idx::X], x[idx::Y]));
        let (sh, ch) = f.heading.sin_cos();
        let v_s = v.x * ch + v.y * sh;
        let v_d = -v.x * sh + v.y * ch;
        let s_stop = f.s + v_s * t;
        let p = road.to_world(s_stop, f.d + v_d * t);
        let turn = road.pose_at(s_stop).heading - f.heading;
        [p.x, p.y, x[idx::PSI] + turn]
    }

    /// The deceleration (m/s²) of a target rolling on without force from state `x`: its tyres
    /// sliding sideways take `stop_decel_fraction` of μ g; rolling along its body it keeps
    /// only rolling resistance and its driveline (in gear: the engine's drag rolling forwards,
    /// the stalled engine's hold rolling backwards); in between by the sine of the body slip.
    pub(super) fn stop_decel(&self, x: &TargetState) -> f64 {
        let slide = self.settings.stop_decel_fraction * self.mu.max(0.05) * GRAVITY;
        let speed = x[idx::VX].hypot(x[idx::VY]);
        if speed < 1e-6 {
            return slide;
        }
        let t = &self.params.target;
        let per_nm = t.gear_ratio / (t.wheel_radius * t.mass);
        let driveline = t.powertrain.as_ref().map_or(0.0, |pt| {
            per_nm
                * if x[idx::VX] < 0.0 {
                    pt.stall_torque
                } else {
                    pt.engine_drag_torque
                }
        });
        let roll = t.rolling_resistance * GRAVITY + driveline;
        let sin_slip = x[idx::VY].abs() / speed;
        roll.min(slide) + (slide - roll).max(0.0) * sin_slip
    }
}
