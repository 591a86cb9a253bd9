//! One control step: the SCP iterations over the bullet-only or coupled QP within the
//! time budget, and the fall-back command when the QP fails.

use super::*;

impl CoupledMpc {
    /// One control step.
    ///
    /// # Errors
    /// [`SolveError`] for non-finite input or a reference of the wrong length; numerical
    /// trouble is a status ([`MpcStatus::QpFailure`] with a safe command), never an error.
    pub fn solve(&mut self, input: &MpcInput<'_>) -> Result<MpcOutput, SolveError> {
        check_input(input, self.n)?;
        let t0 = self.clock.now();
        let mut times = StepTimes::default();
        // The linearisation point: the previous plan shifted by one step, or the last
        // command held; projected onto the input bounds and rate limits.
        self.init_linearisation(input);
        let tl = self.clock.now();
        self.roll(false, &input.target_input, true);
        self.linearise_soft(input);
        times.linearise += self.clock.now() - tl;
        self.coupled = self.soft.iter().any(|r| r.band);
        // Only converged mode tests steps against the merit; RTI takes its one step.
        let converged = self.settings.mode == ScpMode::Converged;
        let mut merit_lin = if converged {
            self.merit(&self.lin, input).0
        } else {
            0.0
        };

        let max_iter = match self.settings.mode {
            ScpMode::Rti => 1,
            ScpMode::Converged => self.settings.max_scp_iter,
        };
        let mut trust = 1.0;
        let mut status = MpcStatus::IterationCap;
        let mut accepted_any = false;
        let mut qp_iterations = 0;
        let mut scp_iterations = 0;
        let mut qp_failed = false;
        for it in 0..max_iter {
            let elapsed = self.clock.now() - t0;
            let per_iter = if it == 0 {
                0.0
            } else {
                elapsed / f64::from(it)
            };
            if it > 0 && elapsed + per_iter > self.settings.time_budget {
                status = MpcStatus::TimeBudget;
                break;
            }
            scp_iterations += 1;
            let ta = self.clock.now();
            self.assemble(input, trust);
            times.assemble += self.clock.now() - ta;
            let obj_lin = if converged {
                self.objective_at_lin(input.reference)
            } else {
                0.0
            };
            self.lin_snapshot.copy_trajectory_from(&self.lin);
            let tq = self.clock.now();
            let qs = if self.coupled {
                self.qp_coupled.solve()
            } else {
                self.qp_bullet.solve()
            };
            times.qp += self.clock.now() - tq;
            qp_iterations += self.qp().iterations();
            if !qs.usable() {
                if qs == QpStatus::MaxTime {
                    status = MpcStatus::TimeBudget;
                }
                qp_failed = !accepted_any;
                break;
            }
            // Candidate: the QP's inputs and forces, rolled out through the nonlinear models.
            let tl = self.clock.now();
            self.candidate_from_qp();
            // RTI never linearises at the candidate (the next step re-linearises from the
            // new measurement), so its rollout skips the Jacobians.
            self.cand.xt[0] = self.lin.xt[0];
            self.cand.xb[0] = self.lin.xb[0];
            self.roll(true, &input.target_input, converged);
            self.model_error = self.qp_model_error();
            times.linearise += self.clock.now() - tl;
            if !converged {
                self.lin.copy_trajectory_from(&self.cand);
                accepted_any = true;
                status = MpcStatus::RtiStep;
                break;
            }
            let merit_cand = self.merit(&self.cand, input).0;
            // The QP models the merit's change: its objective at the linearisation point
            // (zero step, slacks at their smallest feasible value) minus at the solution.
            let predicted = obj_lin - self.qp().objective();
            let step = self.step_size();
            let actual = merit_lin - merit_cand;
            if actual >= 0.1 * predicted.max(0.0) && merit_cand.is_finite() {
                self.lin.copy_from(&self.cand);
                merit_lin = merit_cand;
                accepted_any = true;
                let tl = self.clock.now();
                self.linearise_soft(input);
                self.coupled = self.soft.iter().any(|r| r.band);
                times.linearise += self.clock.now() - tl;
                if step < self.settings.step_tol * trust
                    || predicted.abs() < 1e-6 * (1.0 + merit_lin.abs())
                {
                    status = MpcStatus::Converged;
                    break;
                }
                if actual > 0.75 * predicted {
                    trust = (trust * 2.0).min(1.0);
                }
            } else {
                trust *= 0.25;
                if trust < 1e-3 {
                    status = MpcStatus::Converged;
                    break;
                }
            }
        }
        let out = if qp_failed || !accepted_any && !converged {
            self.fallback(input, qp_iterations, scp_iterations, times)
        } else {
            // Converged mode keeps the linearisation plan (the best accepted one, or the
            // initial guess if nothing was accepted).
            let (merit, viol) = self.merit(&self.lin, input);
            if !self.lin.is_finite() {
                self.fallback(input, qp_iterations, scp_iterations, times)
            } else {
                // Only the inputs and forces of `prev` are used (shifted, next step).
                self.prev.copy_trajectory_from(&self.lin);
                self.have_prev = true;
                MpcOutput {
                    status,
                    command: self.lin.u[0],
                    fallback: None,
                    scp_iterations,
                    qp_iterations,
                    merit,
                    max_violation: viol,
                    times,
                }
            }
        };
        let mut out = out;
        out.times.total = self.clock.now() - t0;
        Ok(out)
    }

    fn fallback(
        &mut self,
        input: &MpcInput<'_>,
        qp_iterations: u32,
        scp_iterations: u32,
        times: StepTimes,
    ) -> MpcOutput {
        let (command, kind) = if self.have_prev && self.prev.is_finite() {
            // Shift the previous plan: drop its first input.
            let n = self.n;
            self.prev.u.copy_within(1..n, 0);
            self.prev.f.copy_within(1..n, 0);
            self.prev.xt.copy_within(1..=n, 0);
            self.prev.xb.copy_within(1..=n, 0);
            (self.prev.u[0], Fallback::ShiftedPlan)
        } else {
            self.have_prev = false;
            let steer = input.last_command[0].clamp(-self.lim.steer_max, self.lim.steer_max) * 0.5;
            (
                BulletInput::new(steer, 0.5 * self.lim.torque_min),
                Fallback::Brake,
            )
        };
        MpcOutput {
            status: MpcStatus::QpFailure,
            command,
            fallback: Some(kind),
            scp_iterations,
            qp_iterations,
            merit: f64::INFINITY,
            max_violation: 0.0,
            times,
        }
    }
}
