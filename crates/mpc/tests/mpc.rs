//! Behaviour of the coupled collision MPC on scripted situations.

mod common;

use common::*;
use dynamics::road::Obstacle;
use mpc::{MpcSettings, MpcStatus, ScpMode, SolveError};

/// Default settings with wall-clock limits out of the way: these tests check behaviour, and
/// the test profile (`cargo test`: opt-level 1, debug assertions) is slower than a release
/// build.
fn settings() -> MpcSettings {
    let d = MpcSettings::default();
    MpcSettings {
        time_budget: 10.0,
        qp: mpc::settings::QpSettings {
            time_limit: 10.0,
            ..d.qp.clone()
        },
        ..d
    }
}

#[test]
fn the_qp_prediction_matches_the_nonlinear_rollout_and_the_error_shrinks_quadratically() {
    // Bullet 8 m behind and to the left: no contact, a smooth linearisation. Shrinking the
    // trust region by 4 (both below the steer-rate limit of 0.02 rad per step, so the trust
    // region is what limits the step) shrinks the first-order model's error by more than
    // it shrinks the step (quadratically where the step sits at the trust bound).
    let s = situation(-8.0, 3.0, 0.0, 15.0, 17.0);
    let mut errs = Vec::new();
    for trust in [0.02, 0.005] {
        let mut st = settings();
        st.trust_steer = trust;
        st.trust_torque = trust;
        // Solve the QPs tightly: this test is about the model, not the solver's tolerance.
        st.qp.tol_gap = 1e-9;
        st.qp.tol_feas = 1e-9;
        st.qp.iterative_refinement = true;
        let mut m = mpc_with(st, four_dof(&params()));
        let out = m.solve(&input(&s, None)).unwrap();
        assert_eq!(out.status, MpcStatus::RtiStep);
        errs.push(m.linearisation_error());
    }
    assert!(errs[0] < 0.05, "linearisation error {:?}", errs);
    assert!(
        errs[1] < errs[0] / 4.0,
        "error does not shrink faster than the step: {errs:?}"
    );
    assert!(errs[1] < 5e-3, "{errs:?}");
}

#[test]
fn with_the_vehicles_apart_no_force_is_planned() {
    let s = situation(-12.0, 3.5, 0.0, 15.0, 16.0);
    let mut m = mpc_with(settings(), four_dof(&params()));
    let out = m.solve(&input(&s, Some(&road()))).unwrap();
    assert_eq!(out.status, MpcStatus::RtiStep);
    let plan = m.plan();
    for k in 0..plan.len() {
        assert!(
            plan.pair[k].gap > 0.3,
            "the plan closes to contact at step {k}"
        );
        assert_eq!(
            plan.f[k].x, 0.0,
            "force planned at step {k} with gap {}",
            plan.pair[k].gap
        );
        assert_eq!(plan.f[k].y, 0.0);
    }
}

/// A chase straight behind the target, 1.5 m off its rear bumper and 2.5 m/s faster, with a
/// reference that plans no force anywhere (its corridor closed) but asks to close in: the
/// MPC plans no force and keeps the bullet off the target's rear (the bullet-only QP and its
/// no-contact row). The same situation with the corridor open takes the coupled QP.
#[test]
fn a_reference_without_force_keeps_the_bullet_off_the_targets_rear() {
    let p = params();
    let (t, b) = (&p.target, &p.bullet);
    let rel_x = -((t.length - t.cg_to_front) + b.cg_to_front + 1.5);
    let mut s = situation(rel_x, 0.0, 0.0, 10.0, 12.5);
    for st in &mut s.reference.stages {
        st.rel_pos.x = rel_x + 1.0;
        st.rel_pos.y = 0.0;
        st.rel_speed = 2.0;
        st.fn_lo = 0.0;
        st.fn_hi = 0.0;
    }
    let mut m = mpc_with(settings(), four_dof(&p));
    let out = m.solve(&input(&s, Some(&road()))).unwrap();
    assert_eq!(out.status, MpcStatus::RtiStep);
    assert!(!m.last_qp_coupled(), "no force planned: the bullet-only QP");
    let plan = m.plan();
    for k in 0..plan.len() {
        assert_eq!(plan.f[k].x, 0.0, "force planned at step {k}");
        assert!(
            plan.pair[k + 1].gap > -0.05,
            "the plan runs into the target's rear at step {}: gap {}",
            k + 1,
            plan.pair[k + 1].gap
        );
    }
    for st in &mut s.reference.stages {
        st.fn_hi = 15_000.0;
    }
    m.reset();
    m.solve(&input(&s, Some(&road()))).unwrap();
    assert!(m.last_qp_coupled(), "a force planned and the vehicles near");
    // … and then it does plan a push on the rear bumper (what the closed corridor prevents).
    let plan = m.plan();
    let most = (0..plan.len()).map(|k| plan.f[k].x).fold(0.0, f64::max);
    assert!(
        most > 1000.0,
        "open corridor: largest planned force {most} N"
    );
}

#[test]
fn in_contact_the_planned_force_stays_in_the_corridor_and_the_bullet_in_its_envelope() {
    in_contact_force_and_envelope(true);
}

/// The same with the coupled QP that leaves the target's roll states out
/// (`qp.target_roll = false`, 17 columns and 31 rows per stage instead of 19 and 33).
#[test]
fn without_the_targets_roll_in_the_qp_the_push_keeps_the_same_constraints() {
    in_contact_force_and_envelope(false);
}

fn in_contact_force_and_envelope(target_roll: bool) {
    let (rx, ry) = touching_rel(0.04);
    let mut s = situation(rx, ry, -0.1, 15.0, 16.0);
    // Engaged: the default reference opens the corridor.
    let st = &s.reference.stages[0];
    assert!(
        st.fn_hi > 0.0,
        "the default reference should be engaged here: {st:?}"
    );
    for stage in &mut s.reference.stages {
        stage.fn_lo = 3000.0;
    }
    // Converged SCP: the nonlinear rollout of the plan, not only its linearisation, must
    // honour the contact constraints.
    let mut settings = settings();
    settings.mode = ScpMode::Converged;
    settings.max_scp_iter = 20;
    settings.time_budget = 10.0;
    settings.qp.target_roll = target_roll;
    let mut m = mpc_with(settings.clone(), four_dof(&params()));
    let ((n, rows), _) = m.qp_sizes();
    assert_eq!((n, rows), if target_roll { (380, 660) } else { (340, 620) });
    let out = m.solve(&input(&s, Some(&road()))).unwrap();
    assert!(out.status != MpcStatus::QpFailure, "{out:?}");
    assert!(m.last_qp_coupled(), "touching: the coupled QP");
    eprintln!("{out:?}");
    let plan = m.plan();
    let c = &settings.contact;
    let mut any_force = false;
    for k in 0..plan.len() {
        let f = plan.f[k];
        let g = plan.pair[k].gap.min(plan.pair[k + 1].gap);
        let bound = if g <= c.gap_release { c.force_max } else { 0.0 };
        assert!(
            f.x >= 0.0 && f.x <= bound + 1e-6,
            "F_n {} outside [0, {bound}] at {k}",
            f.x
        );
        // The compliance band, with the solver's slack tolerance of a centimetre.
        assert!(
            f.x <= c.stiffness * (c.band - g + 0.01),
            "F_n {} across a gap {g} at {k}",
            f.x
        );
        assert!(
            f.y.abs() <= c.friction * f.x + 1e-6,
            "friction cone violated at {k}: {f:?}"
        );
        any_force |= f.x > 100.0;
    }
    assert!(
        any_force,
        "no force planned while touching with the corridor open"
    );
    // The bullet's predicted lateral position in the target frame stays in the envelope
    // (soft constraint: allow the solver's tolerance).
    for k in 1..=plan.len() {
        let (xt, xb) = (&plan.xt[k], &plan.xb[k]);
        let (sn, cs) = xt[2].sin_cos();
        let rel_y = -sn * (xb[0] - xt[6]) + cs * (xb[1] - xt[7]);
        let st = &s.reference.stages[k - 1];
        assert!(
            (rel_y - st.rel_pos.y).abs() <= st.envelope_lat + 0.05,
            "bullet outside its envelope at {k}: {rel_y} vs {} ± {}",
            st.rel_pos.y,
            st.envelope_lat
        );
    }
}

#[test]
fn a_start_off_the_road_still_gives_a_status_and_a_finite_command() {
    // The bullet starts 1 m beyond the left edge, an obstacle sits in its way: every
    // constraint but the input bounds is soft, so the QP stays feasible.
    let s = situation(-10.0, 7.5, 0.2, 15.0, 17.0);
    let obstacles = [Obstacle {
        x: 100.0,
        y: 6.0,
        heading: 0.0,
        vx: 0.0,
        vy: 0.0,
        length: 2.0,
        width: 1.0,
    }];
    let mut m = mpc_with(settings(), four_dof(&params()));
    let road = road();
    let mut inp = input(&s, Some(&road));
    inp.obstacles = &obstacles;
    let out = m.solve(&inp).unwrap();
    assert_eq!(out.status, MpcStatus::RtiStep, "{out:?}");
    assert!(out.command.iter().all(|v| v.is_finite()));
    assert!(
        out.max_violation > 0.5,
        "the start violates the road: {out:?}"
    );
    // The plan steers back toward the road (to the right).
    let plan = m.plan();
    assert!(plan.u.iter().any(|u| u[0] < -0.05), "{:?}", plan.u);
}

#[test]
fn non_finite_input_is_refused_with_a_typed_error() {
    let s = situation(-8.0, 3.0, 0.0, 15.0, 17.0);
    let mut m = mpc_with(settings(), four_dof(&params()));
    let mut inp = input(&s, None);
    let mut bad = s.target;
    bad[3] = f64::NAN;
    inp.target = bad;
    assert_eq!(m.solve(&inp).unwrap_err(), SolveError::TargetState);
    let mut inp = input(&s, None);
    inp.last_command[1] = f64::INFINITY;
    assert_eq!(m.solve(&inp).unwrap_err(), SolveError::LastCommand);
}

#[test]
fn the_same_input_gives_the_same_plan() {
    let s = situation(-8.0, 3.0, 0.0, 15.0, 17.0);
    let run = || {
        let mut m = mpc_with(settings(), four_dof(&params()));
        let out = m.solve(&input(&s, Some(&road()))).unwrap();
        (out.command, m.plan().xb.clone(), m.plan().f.clone())
    };
    assert_eq!(run(), run());
}

#[test]
fn converged_mode_never_ends_with_a_worse_merit_than_rti() {
    let s = situation(-6.0, 2.8, -0.05, 15.0, 17.0);
    let mut merits = Vec::new();
    for mode in [ScpMode::Rti, ScpMode::Converged] {
        let mut st = settings();
        st.mode = mode;
        st.time_budget = 10.0;
        let mut m = mpc_with(st, four_dof(&params()));
        let out = m.solve(&input(&s, Some(&road()))).unwrap();
        assert!(out.status != MpcStatus::QpFailure, "{out:?}");
        merits.push(out.merit);
        if mode == ScpMode::Converged {
            assert!(out.scp_iterations >= 1);
        }
    }
    assert!(
        merits[1] <= merits[0] * 1.0001 + 1e-9,
        "converged {merits:?}"
    );
}

#[test]
fn a_target_model_with_another_step_is_refused() {
    let p = params();
    let t = Box::new(dynamics::target4dof::FourDofTarget::new(&p.target, MU, 0.1));
    let e = mpc::CoupledMpc::new(&p, MU, t, settings()).unwrap_err();
    assert!(e.to_string().contains("0.1"), "{e}");
}

#[test]
fn a_failed_qp_gives_a_safe_command_brake_first_then_the_shifted_plan() {
    let s = situation(-8.0, 3.0, 0.0, 15.0, 17.0);
    let road = road();
    let mut st = settings();
    st.qp.max_iter = 1; // no QP converges in one interior-point iteration
    let mut m = mpc_with(st, four_dof(&params()));
    // No previous plan: controlled braking.
    let out = m.solve(&input(&s, Some(&road))).unwrap();
    assert_eq!(out.status, MpcStatus::QpFailure);
    assert_eq!(out.fallback, Some(mpc::Fallback::Brake));
    assert!(out.command[1] < 0.0, "braking: {out:?}");
    // A good step, then a failing one: the previous plan shifted by one step.
    let mut qp = settings().qp;
    m.set_qp_settings(qp.clone()).unwrap();
    let good = m.solve(&input(&s, Some(&road))).unwrap();
    assert_eq!(good.status, MpcStatus::RtiStep);
    let next_planned = m.plan().u[1];
    qp.max_iter = 1;
    m.set_qp_settings(qp).unwrap();
    let out = m.solve(&input(&s, Some(&road))).unwrap();
    assert_eq!(out.status, MpcStatus::QpFailure);
    assert_eq!(out.fallback, Some(mpc::Fallback::ShiftedPlan));
    assert_eq!(out.command, next_planned);
    // Bad QP settings are refused with the field named.
    let mut bad = settings().qp;
    bad.tol_gap = -1.0;
    let e = m.set_qp_settings(bad).unwrap_err();
    assert!(e.to_string().contains("qp.tol_gap"), "{e}");
}

#[test]
fn the_time_budget_stops_converged_scp_on_an_injected_clock() {
    let s = situation(-6.0, 2.8, -0.05, 15.0, 17.0);
    let mut st = settings();
    st.mode = ScpMode::Converged;
    st.max_scp_iter = 50;
    // Every clock reading advances 1 ms; the budget allows a handful of readings (Clarabel's
    // own wall-clock limit stays out of the way).
    st.time_budget = 0.012;
    let clock = Box::new(mpc::TickClock::new(1e-3));
    let mut m = mpc_with(st, four_dof(&params())).with_clock(clock);
    let out = m.solve(&input(&s, Some(&road()))).unwrap();
    assert!(
        matches!(out.status, MpcStatus::TimeBudget | MpcStatus::Converged),
        "{out:?}"
    );
    assert!(out.scp_iterations < 50, "{out:?}");
    assert!(out.command.iter().all(|v| v.is_finite()));
}

#[test]
fn the_same_code_path_runs_the_4dof_model_the_pinn_and_picopinn() {
    // The shipped surrogates (models/, regenerated by models/regenerate.sh) behind the same
    // `TargetModel` box: only the constructor differs.
    let models = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models/full_size");
    let (rx, ry) = touching_rel(0.04);
    let s = situation(rx, ry, -0.1, 15.0, 16.0);
    let road = road();
    let mut names = Vec::new();
    let mut targets: Vec<Box<dyn dynamics::TargetModel + Send + Sync>> = vec![four_dof(&params())];
    for kind in ["pinn", "picopinn"] {
        let m = pico_nn::SurrogateModel::from_path(models.join(format!("{kind}.safetensors")))
            .and_then(|m| m.with_mu(MU))
            .unwrap_or_else(|e| panic!("shipped {kind} model: {e}"));
        targets.push(Box::new(m));
    }
    for target in targets {
        let mut m = mpc_with(settings(), target);
        names.push(m.target_model_name().to_owned());
        let out = m.solve(&input(&s, Some(&road))).unwrap();
        assert_eq!(
            out.status,
            MpcStatus::RtiStep,
            "{}: {out:?}",
            m.target_model_name()
        );
        assert!(m.last_qp_coupled());
        let plan = m.plan();
        assert!(plan
            .f
            .iter()
            .all(|f| f.x >= 0.0 && f.y.abs() <= 0.3 * f.x + 1e-6));
        assert!(
            plan.f.iter().any(|f| f.x > 100.0),
            "{}: no force",
            m.target_model_name()
        );
    }
    assert_eq!(names, ["4dof", "pinn", "picopinn"]);
}

#[test]
fn the_qp_time_limit_holds_per_solve_not_over_the_controllers_lifetime() {
    // A limit far below one interior-point iteration stops every QP at its first check:
    // no usable step, a finite safe command.
    let s = situation(-8.0, 3.0, 0.0, 15.0, 17.0);
    let mut st = settings();
    st.mode = ScpMode::Rti;
    st.qp.time_limit = 1e-9;
    let mut m = mpc_with(st.clone(), four_dof(&params()));
    let out = m.solve(&input(&s, None)).unwrap();
    assert!(
        matches!(out.status, MpcStatus::QpFailure | MpcStatus::TimeBudget),
        "{out:?}"
    );
    assert_eq!(out.qp_iterations, 0, "{out:?}");
    assert!(out.fallback.is_some(), "{out:?}");
    assert!(out.command.iter().all(|v| v.is_finite()), "{out:?}");
    // The same solver with a generous limit solves again: the time already spent in earlier
    // solves does not count against the next one.
    st.qp.time_limit = 10.0;
    m.set_qp_settings(st.qp.clone()).unwrap();
    for _ in 0..3 {
        let out = m.solve(&input(&s, None)).unwrap();
        assert_eq!(out.status, MpcStatus::RtiStep, "{out:?}");
        assert!(out.fallback.is_none(), "{out:?}");
    }
}

/// A turn-in that has stalled just beyond `gap_release`: the bullet parallel beside the
/// target's rear quarter, 0.34 m off its side, with the reference at the contact pose and
/// the corridor open. Pushing (`set_pushing(true)`) the linearisation keeps every stage
/// beyond `gap_release`, so no force may be planned anywhere and nothing draws the bullet
/// in; before the push (`set_pushing(false)`) the stages within `gap_engage` may carry a
/// force, and the plan closes in to touch.
#[test]
fn a_turn_in_stalled_beyond_the_release_gap_plans_the_contact_before_the_push() {
    let p = params();
    let (rx, ry) = touching_rel(-0.34);
    let mut s = situation(rx, ry, 0.0, 15.0, 15.0);
    let contact = mpc::reference::pit_stage_at(
        &p,
        mpc::Side::Left,
        -p.target.lr - 0.3,
        12f64.to_radians(),
        0.05,
        1.0,
        (3000.0, 11_000.0),
    );
    for st in &mut s.reference.stages {
        *st = contact;
    }
    s.reference.target_weight = 1.0;
    let c = settings().contact;
    assert!(c.gap_release < 0.34 && 0.34 < c.gap_engage, "{c:?}");
    let mut closest = Vec::new();
    for pushing in [true, false] {
        let mut m = mpc_with(settings(), four_dof(&p));
        m.set_pushing(pushing);
        m.solve(&input(&s, Some(&road()))).unwrap();
        let open = (0..20)
            .filter(|&k| m.stage_linearisation(k).fn_max > 0.0)
            .count();
        let plan = m.plan();
        let gap = (1..=plan.len())
            .map(|k| plan.pair[k].gap)
            .fold(f64::INFINITY, f64::min);
        closest.push(gap);
        if pushing {
            assert_eq!(open, 0, "pushing: no stage within gap_release");
        } else {
            assert!(
                open > 0,
                "before the push: stages within gap_engage may carry a force"
            );
        }
    }
    assert!(
        closest[1] < closest[0] - 0.05,
        "the plan should close in before the push: closest gap {closest:?} (pushing, not)"
    );
}
