//! Would the upper layer pick a working shove if the push landed exactly? For each scenario
//! the whole grid of single shoves of `examples/oracle_tiers` is simulated on the plant with
//! the target driver's true law (the truth), and the same shoves are judged by the upper
//! layer's own criteria (`Planner::judge`: its target model, its 2 s look-ahead, the driver's
//! command held, the terminal heading set, road, stopping-point and obstacle margins). The
//! shove `Δv` of the target's c.g. is given to the model as a constant normal force
//! `m_T Δv / (n·dt)` over the first `n` plan steps at the rear-quarter point (`n = 3`,
//! 0.15 s: about the compliant contact's duration).
//!
//! Per model, three choices made in the model's view and judged in the truth:
//!
//! * `first`: the earliest shove the model calls feasible (as the planner commits to the
//!   earliest window it can reach);
//! * `robust`: the shove whose 3 × 3 box (±0.1 s, ±1 size step) the model calls feasible
//!   most often;
//! * `exp`: that choice's expected true success when the push lands anywhere in its box;
//!
//! and how the model's verdict on single shoves agrees with the truth (precision: the share
//! of shoves called feasible that succeed; recall: the share of succeeding shoves called
//! feasible).
//!
//! `cargo run --release -p picopit-sim --example oracle_surrogate -- [FIRST] [COUNT]
//! [THREADS] [MODELS] [STEPS] [PLANNER] [CACHE]` (defaults 0, 192, 2, `4dof,pinn,picopinn`,
//! 3, `{}`, none). PLANNER is a JSON object of planner settings over the defaults (e.g.
//! `{"check_horizon":4.0}`); CACHE a folder where the true grids are kept (`ID.json`) and
//! read back on the next run, so that criteria can be compared without simulating the
//! truth again (about 2.6 s per scene on two threads).

mod common;

use dynamics::geometry::Vec2;
use dynamics::{TargetInput, TargetState};
use planner::{Planner, PlannerInput, PlannerSettings};
use sim::episode::{target_model, ModelKind};
use sim::oracle::{shove_grid, shove_states, DriverView, GridChoice, OracleSettings, ShoveGrid};
use std::path::Path;

/// One model's verdict on a scene.
#[derive(Default, Clone, Copy)]
struct Verdict {
    first: f64,
    robust: f64,
    exp: f64,
    /// Shoves: called feasible and true success, called feasible only, true success only.
    both: usize,
    model_only: usize,
    truth_only: usize,
}

/// The true grid of a scene, from `cache` when it holds it (and written there when not).
fn truth_grid(
    sc: &sim::Scenario,
    settings: &OracleSettings,
    cache: Option<&Path>,
) -> Result<ShoveGrid, String> {
    let file = cache.map(|c| c.join(format!("{}.json", sc.id)));
    if let Some((f, Ok(text))) = file.as_ref().map(|f| (f, std::fs::read_to_string(f))) {
        let g: ShoveGrid =
            serde_json::from_str(&text).map_err(|e| format!("{}: {e}", f.display()))?;
        // A grid kept by a build with another shove grid would be judged against the
        // wrong shoves: refuse it rather than read it.
        if g.shoves != settings.shoves || g.sides != settings.sides {
            return Err(format!(
                "{}: kept with other shoves or sides than this grid's; remove it",
                f.display()
            ));
        }
        return Ok(g);
    }
    let g = shove_grid(sc, settings, DriverView::True).map_err(|e| e.to_string())?;
    if let Some(f) = file {
        let text = serde_json::to_string(&g).map_err(|e| e.to_string())?;
        std::fs::write(&f, text).map_err(|e| format!("{}: {e}", f.display()))?;
    }
    Ok(g)
}

fn judge_grid(
    sc: &sim::Scenario,
    settings: &OracleSettings,
    truth: &ShoveGrid,
    kind: ModelKind,
    steps: usize,
    ps: &PlannerSettings,
) -> Result<ShoveGrid, String> {
    let params = sc.params.load().map_err(|e| e.to_string())?;
    let road = sc.build_road().map_err(|e| e.to_string())?;
    let obstacles = sc.obstacles();
    let ps = ps.clone();
    let model = target_model(kind, Path::new("models"), None, sc, &params, ps.dt)
        .map_err(|e| e.to_string())?;
    let dt = ps.dt;
    let mut planner = Planner::new(&params, sc.mu, model, ps).map_err(|e| e.to_string())?;
    let states = shove_states(sc, settings).map_err(|e| e.to_string())?;
    assert_eq!(states.len(), truth.times.len(), "grids of different times");
    let mut grid = ShoveGrid {
        success: Vec::with_capacity(truth.success.len()),
        ..truth.clone()
    };
    let m = params.target.mass;
    let mut forces = vec![Vec2::zeros(); steps];
    for st in &states {
        let input = PlannerInput {
            time: st.time,
            target: TargetState::from_row_slice(&st.target),
            bullet: dynamics::bullet::BulletState::zeros(),
            target_input: TargetInput::new(st.command[0], st.command[1]),
            road: &road,
            obstacles: &obstacles,
            side: None,
            best_effort: false,
        };
        for &side in &truth.sides {
            let side = if side > 0.0 {
                mpc::Side::Left
            } else {
                mpc::Side::Right
            };
            for &dv in &truth.shoves {
                forces.fill(Vec2::new(m * dv / (steps as f64 * dt), 0.0));
                let j = planner
                    .judge(&input, side, 0, &forces)
                    .map_err(|e| e.to_string())?;
                grid.success.push(j.feasible);
            }
        }
    }
    Ok(grid)
}

fn verdict(truth: &ShoveGrid, view: &ShoveGrid) -> Verdict {
    let at = |c: Option<GridChoice>| {
        f64::from(u8::from(c.is_some_and(|c| {
            truth.get(c.time as isize, c.side, c.shove as isize)
        })))
    };
    let pick = view.most_robust(1, 1);
    let mut v = Verdict {
        first: at(view.earliest()),
        robust: at(pick),
        exp: pick.map_or(0.0, |c| {
            truth.box_score(c.time, c.side, c.shove, 1, 1) as f64 / 9.0
        }),
        ..Verdict::default()
    };
    for (&t, &m) in truth.success.iter().zip(&view.success) {
        v.both += usize::from(t && m);
        v.model_only += usize::from(m && !t);
        v.truth_only += usize::from(t && !m);
    }
    v
}

/// The planner settings of the JSON object `text` (fields left out take their defaults;
/// exit code 2 naming the problem).
fn planner_settings(text: &str) -> PlannerSettings {
    let fail = |e: &dyn std::fmt::Display| -> ! {
        eprintln!("PLANNER: {e}");
        std::process::exit(2);
    };
    let value: serde_json::Value = serde_json::from_str(text).unwrap_or_else(|e| fail(&e));
    if !value.is_object() {
        // (serde would read a JSON array as the fields in order.)
        fail(&format!("not a JSON object: {text}"));
    }
    let s: PlannerSettings = serde_json::from_value(value).unwrap_or_else(|e| fail(&e));
    if let Err(e) = s.validate() {
        fail(&e);
    }
    s
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let first = common::number(&args, 0, "FIRST", 0);
    let count = common::number(&args, 1, "COUNT", 192);
    let threads = common::number(&args, 2, "THREADS", 2);
    let kinds: Vec<ModelKind> = args
        .get(3)
        .map_or("4dof,pinn,picopinn", String::as_str)
        .split(',')
        .map(|k| {
            serde_json::from_str(&format!("\"{k}\"")).unwrap_or_else(|_| {
                eprintln!("MODELS: {k:?} is not one of 4dof, pinn, picopinn");
                std::process::exit(2);
            })
        })
        .collect();
    let steps = common::number(&args, 4, "STEPS", 3);
    let planner_settings = planner_settings(args.get(5).map_or("{}", String::as_str));
    if steps == 0 || steps > planner_settings.window_steps() {
        eprintln!(
            "STEPS: {steps} is not within 1..={} (the planner's window)",
            planner_settings.window_steps()
        );
        std::process::exit(2);
    }
    let cache = args.get(6).map(Path::new);
    if let Some(c) = cache {
        if let Err(e) = std::fs::create_dir_all(c) {
            eprintln!("CACHE: {}: {e}", c.display());
            std::process::exit(2);
        }
    }
    let settings: OracleSettings = serde_json::from_str(
        r#"{"shoves":[0.4,0.5,0.63,0.8,1.0,1.25,1.6,2.0,2.5,3.15],"time_step":0.1}"#,
    )
    .expect("the built-in grid parses");
    let chosen = common::scenes(first, count);
    let t0 = std::time::Instant::now();
    let results = common::map_scenes(&chosen, threads, |sc| {
        let truth = truth_grid(sc, &settings, cache)?;
        let views = kinds
            .iter()
            .map(|&k| judge_grid(sc, &settings, &truth, k, steps, &planner_settings))
            .collect::<Result<Vec<_>, _>>()?;
        Ok::<_, String>((truth, views))
    });
    // Per model: first, robust, exp summed; shoves both / model only / truth only.
    let mut sums = vec![Verdict::default(); kinds.len()];
    let (mut n, mut ideal, mut ideal_exp) = (0usize, 0.0, 0.0);
    for (sc, r) in chosen.iter().zip(&results) {
        let (truth, views) = match r {
            Ok(g) => g,
            Err(e) => {
                println!("{}: error: {e}", sc.id);
                continue;
            }
        };
        n += 1;
        let best = truth.most_robust(1, 1);
        ideal += f64::from(u8::from(truth.earliest().is_some()));
        ideal_exp += best.map_or(0.0, |c| c.score as f64 / c.of as f64);
        let mut line = format!(
            "scene {} {} {} {} ideal={}",
            sc.id,
            sc.category.name(),
            sc.driver.kind(),
            sc.adhesion.name(),
            u8::from(truth.earliest().is_some())
        );
        for ((k, view), sum) in kinds.iter().zip(views).zip(sums.iter_mut()) {
            let v = verdict(truth, view);
            line += &format!(
                " | {} first={} robust={} exp={:.2} both={} model_only={} truth_only={}",
                k.name(),
                v.first,
                v.robust,
                v.exp,
                v.both,
                v.model_only,
                v.truth_only
            );
            sum.first += v.first;
            sum.robust += v.robust;
            sum.exp += v.exp;
            sum.both += v.both;
            sum.model_only += v.model_only;
            sum.truth_only += v.truth_only;
        }
        println!("{line}");
    }
    let pct = |x: f64| 100.0 * x / n.max(1) as f64;
    println!(
        "{n} scenes in {:.1} s; shove over {steps} plan steps",
        t0.elapsed().as_secs_f64()
    );
    println!(
        "truth: ideal {:.1} %, ideal-exp {:.1} %",
        pct(ideal),
        pct(ideal_exp)
    );
    println!("| model | first | robust | exp | precision | recall |");
    println!("|---|---|---|---|---|---|");
    for (k, s) in kinds.iter().zip(&sums) {
        let share = |a: usize, b: usize| 100.0 * a as f64 / (a + b).max(1) as f64;
        println!(
            "| {} | {:.1} % | {:.1} % | {:.1} % | {:.1} % | {:.1} % |",
            k.name(),
            pct(s.first),
            pct(s.robust),
            pct(s.exp),
            share(s.both, s.model_only),
            share(s.both, s.truth_only)
        );
    }
}
