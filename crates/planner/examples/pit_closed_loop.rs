//! The whole controller (upper layer + coupled MPC + phase machine) driving the bullet of the
//! plant into a PIT on a straight road: prints the maneuver.
//!
//! `cargo run --release -p picopit-planner --example pit_closed_loop [no-upper] [model PATH]`
//! (environment: `CTL_TOML` controller settings, `MU`, `VT`, `DV`, `RX`, `RY`, `MPC_DEBUG`)

use dynamics::params::ParamSet;
use dynamics::plant::{Plant, PlantConfig, VehicleInit};
use dynamics::road::Road;
use dynamics::target4dof::FourDofTarget;
use dynamics::{TargetInput, TargetModel};
use planner::{ControllerInput, ControllerSettings, Phase, PitController};

fn model(
    path: Option<&str>,
    params: &ParamSet,
    mu: f64,
    dt: f64,
) -> Box<dyn TargetModel + Send + Sync> {
    match path {
        Some(p) => Box::new(
            pico_nn::SurrogateModel::from_path(std::path::Path::new(p))
                .and_then(|m| m.with_mu(mu))
                .unwrap(),
        ),
        None => Box::new(FourDofTarget::new(&params.target, mu, dt)),
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let upper = !args.iter().any(|a| a == "no-upper");
    let path = args
        .iter()
        .position(|a| a == "model")
        .map(|i| args[i + 1].as_str());
    let env = |k: &str, d: f64| {
        std::env::var(k)
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(d)
    };
    let mu = env("MU", 0.9);
    let vt = env("VT", 15.0);
    let params = ParamSet::builtin("full_size").unwrap();
    let mut settings = match std::env::var("CTL_TOML") {
        Ok(t) => ControllerSettings::from_toml_str(&t).unwrap(),
        Err(_) => ControllerSettings::default(),
    };
    settings.upper_layer = upper;
    let dt = settings.mpc.dt;
    let mut ctl = PitController::new(
        &params,
        mu,
        model(path, &params, mu, dt),
        model(path, &params, mu, dt),
        settings,
    )
    .unwrap();
    let road = Road::straight(3000.0, 3, 3.5, 1.0);
    let lane = road.lane_center_offset(1);
    let mut plant = Plant::new(
        &params,
        PlantConfig {
            mu,
            ..PlantConfig::default()
        },
    )
    .unwrap();
    plant.reset(
        &VehicleInit {
            x: 100.0 + env("RX", -10.0),
            y: lane + env("RY", 3.0),
            yaw: 0.0,
            vx: vt + env("DV", 2.0),
            vy: 0.0,
            r: 0.0,
        },
        &VehicleInit {
            x: 100.0,
            y: lane,
            yaw: 0.0,
            vx: vt,
            vy: 0.0,
            r: 0.0,
        },
    );
    let mut last_phase = Phase::Chasing;
    let mut peak: f64 = 0.0;
    for step in 0..400 {
        let t = step as f64 * dt;
        let xt = plant.target_state();
        let xb = plant.bullet_state();
        let out = ctl
            .step(&ControllerInput {
                time: t,
                target: xt,
                bullet: xb,
                target_input: TargetInput::zeros(),
                road: &road,
                obstacles: &[],
            })
            .unwrap();
        plant.set_bullet_command_blended(out.command[0], out.command[1]);
        plant.advance(dt);
        let fc = plant.take_contact_average().map_or(0.0, |c| c.fc.x);
        peak = peak.max(fc);
        if out.replanned || out.phase != last_phase || step % 5 == 0 || fc > 0.0 {
            let pkg = ctl.package();
            let mp = ctl.mpc().plan();
            let r = ctl.reference();
            if std::env::var("MPC_DEBUG").is_ok() {
                println!(
                    "    mpc: ψT_N pred {:.1}° ref {:.1}° w {:.0} | f0 {:.0} f5 {:.0} corridor0 ({:.0},{:.0}) | relpos ref {:?}",
                    mp.xt[mp.xt.len() - 1][2].to_degrees(), r.target_heading.to_degrees(), r.target_weight,
                    mp.f[0].x, mp.f[5].x, r.stages[0].fn_lo, r.stages[0].fn_hi, (r.stages[0].rel_pos.x, r.stages[0].rel_pos.y)
                );
            }
            println!(
                "t={t:5.2} {:?} {:?} {:?} plan={:5.2}ms ctrl={:5.2}ms | Fn={fc:6.0} | ψT={:6.1}° rT={:5.2} vT={:5.2} YT={:5.2} | ψB={:6.1}° vB={:5.2} YB={:5.2} | cmd ({:6.3},{:7.1}) {}",
                out.phase, out.mode, out.mpc_status, out.plan_time * 1e3, out.ctrl_time * 1e3,
                xt[2].to_degrees(), xt[3], xt[0].hypot(xt[1]), xt[7], xb[2].to_degrees(), xb[3], xb[1],
                out.command[0], out.command[1],
                if out.replanned { pkg.map_or(String::new(), |p| format!("Π: {:?} {:?} win=({:.2},{:.2}) cand {}/{} herr {:.2}", p.side, p.infeasible, p.window.0, p.window.1, p.feasible_candidates, p.candidates, p.predicted_heading_error)) } else { String::new() }
            );
        }
        last_phase = out.phase;
        if matches!(out.phase, Phase::Done | Phase::Aborted) && xb[3] < 0.5 {
            break;
        }
    }
    let xt = plant.target_state();
    let err = planner::decision::wrap(xt[2] - std::f64::consts::PI).abs();
    println!(
        "final: phase {:?} abort {:?}; target heading {:.1}° (error to reversed {:.2} rad), speed {:.2}, Y {:.2}; peak contact {peak:.0} N",
        ctl.phase(), ctl.abort_reason(), xt[2].to_degrees(), err, xt[0].hypot(xt[1]), xt[7]
    );
}
