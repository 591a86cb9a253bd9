//! The MPC alone (fixed PIT reference, no upper layer) driving the bullet of the plant into a
//! PIT on a straight road: prints the maneuver step by step.
//!
//! `cargo run --release -p picopit-mpc --example closed_loop [converged]`

use dynamics::params::ParamSet;
use dynamics::plant::{Plant, PlantConfig, VehicleInit};
use dynamics::road::Road;
use dynamics::target4dof::FourDofTarget;
use dynamics::{TargetInput, TargetModel};
use mpc::{CoupledMpc, MpcInput, MpcSettings, Reference, ScpMode, Side};

fn main() {
    let converged = std::env::args().any(|a| a == "converged");
    let params = ParamSet::builtin("full_size").unwrap();
    let mu = 0.9;
    let mut settings = match std::env::var("MPC_TOML") {
        Ok(text) => MpcSettings::from_toml_str(&text).unwrap(),
        Err(_) => MpcSettings::default(),
    };
    if converged {
        settings.mode = ScpMode::Converged;
    }
    let target: Box<dyn TargetModel + Send + Sync> =
        Box::new(FourDofTarget::new(&params.target, mu, settings.dt));
    let mut mpc = CoupledMpc::new(&params, mu, target, settings.clone()).unwrap();
    println!("{mpc:?}");
    let road = Road::straight(2000.0, 3, 3.5, 1.0);
    let mut plant = Plant::new(
        &params,
        PlantConfig {
            mu,
            ..PlantConfig::default()
        },
    )
    .unwrap();
    let lane = road.lane_center_offset(1);
    let vt = 15.0;
    plant.reset(
        &VehicleInit {
            x: 40.0,
            y: lane + 3.0,
            yaw: 0.0,
            vx: vt + 2.0,
            vy: 0.0,
            r: 0.0,
        },
        &VehicleInit {
            x: 50.0,
            y: lane,
            yaw: 0.0,
            vx: vt,
            vy: 0.0,
            r: 0.0,
        },
    );
    let mut reference = Reference::new(settings.horizon);
    if let Ok(v) = std::env::var("REF") {
        // "long,lat,heading_deg": a plain relative pose to hold (no force wanted).
        let f: Vec<f64> = v.split(',').map(|x| x.parse().unwrap()).collect();
        for st in &mut reference.stages {
            st.rel_pos = dynamics::geometry::Vec2::new(f[0], f[1]);
            st.rel_heading = f[2].to_radians();
            st.rel_speed = 0.0;
            st.fn_lo = 0.0;
            st.envelope_lat = 10.0;
        }
        reference.target_weight = 0.0;
    }
    println!("reference stage: {:?}", reference.stages[0]);
    let default_pit = mpc::reference::DefaultPit::new(&params, Side::Left);
    let staged = std::env::var("REF").is_err();
    let mut cmd = dynamics::bullet::BulletInput::zeros();
    let mut peak: f64 = 0.0;
    let (mut t_coupled, mut t_bullet) = (Vec::new(), Vec::new());
    let mut it_coupled = Vec::new();
    for step in 0..160 {
        let t = step as f64 * settings.dt;
        let xt = plant.target_state();
        let xb = plant.bullet_state();
        if staged {
            default_pit.fill(
                &mut reference,
                xt.as_slice(),
                xb.as_slice(),
                settings.dt,
                0.0,
            );
        }
        let input = MpcInput {
            time: t,
            target: xt,
            bullet: xb,
            target_input: TargetInput::zeros(),
            last_command: cmd,
            road: Some(&road),
            obstacles: &[],
            reference: &reference,
        };
        let out = mpc.solve(&input).unwrap();
        if std::env::var("DUMP").is_ok() && mpc.linearisation_error() > 0.5 {
            eprintln!("--- t={t:.2}");
            for (k, e) in mpc.linearisation_error_by_stage().iter().enumerate() {
                let p = mpc.plan();
                eprintln!(
                    "k={k:2} err={:.3} state={} gap={:.3} F=({:.0},{:.0}) u=({:.3},{:.1})",
                    e.0, e.1, p.pair[k].gap, p.f[k].x, p.f[k].y, p.u[k][0], p.u[k][1]
                );
            }
            std::process::exit(0);
        }
        cmd = out.command;
        if mpc.last_qp_coupled() {
            it_coupled.push(f64::from(out.qp_iterations));
            t_coupled.push(out.times.total * 1e3);
        } else {
            t_bullet.push(out.times.total * 1e3);
        }
        plant.set_bullet_command_blended(cmd[0], cmd[1]);
        plant.advance(settings.dt);
        let c = plant.take_contact_average();
        let fc = c.map_or(0.0, |c| c.fc.x);
        peak = peak.max(fc);
        let plan = mpc.plan();
        if step % 2 == 0 {
            println!(
                "t={t:5.2} ψB={:6.1}° vyB={:5.2} {:?} it={} qp={:2} tot={:6.2}ms qp={:5.2}ms | gap={:6.3} plannedFn={:7.0} realFn={:7.0} | psiT={:7.1}° r={:5.2} vT={:5.2} | cmd δ={:6.3} T={:7.1} | merit={:9.2} viol={:.3} linerr={:.3}",
                xb[2].to_degrees(),
                xb[4],
                out.status,
                out.scp_iterations,
                out.qp_iterations,
                out.times.total * 1e3,
                out.times.qp * 1e3,
                plan.pair[0].gap,
                plan.f[0].x,
                fc,
                xt[2].to_degrees(),
                xt[3],
                xt[0],
                cmd[0],
                cmd[1],
                out.merit,
                out.max_violation, mpc.linearisation_error()
            );
        }
    }
    let xt = plant.target_state();
    println!(
        "coupled steps: median {:.2} ms max {:.2} ms ({} steps); bullet-only: median {:.2} ms max {:.2} ms ({} steps)",
        median(&mut t_coupled), t_coupled.last().copied().unwrap_or(0.0), t_coupled.len(),
        median(&mut t_bullet), t_bullet.last().copied().unwrap_or(0.0), t_bullet.len()
    );
    println!(
        "coupled QP iterations: median {} max {}",
        median(&mut it_coupled),
        it_coupled.last().copied().unwrap_or(0.0)
    );
    println!(
        "final target heading {:.1}°, speed {:.2}, peak contact {:.0} N",
        xt[2].to_degrees(),
        xt[0].hypot(xt[1]),
        peak
    );
}

fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}
