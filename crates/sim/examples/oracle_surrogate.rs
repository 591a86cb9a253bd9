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
//! * `best`: at the earliest time the model calls a shove feasible, the feasible shove it
//!   puts nearest the reversed heading (the least projected heading error, the main term of
//!   the planner's objective J_T): what an optimiser over the push picks;
//! * `mean`: the true success of a shove drawn at random among the model's feasible shoves
//!   at that time. `best` below `mean` means the model's own optimum is worse than its
//!   average feasible push: its optimiser would seek the model's errors (the winner's
//!   curse); a model whose confidence carries information has `best` at or above `mean`;
//!
//! and how the model's verdict on single shoves agrees with the truth (precision: the share
//! of shoves called feasible that succeed; recall: the share of succeeding shoves called
//! feasible), with what the model holds against the succeeding shoves it rejects (`miss_*`:
//! short of or past the terminal heading set, over the road edge within the look-ahead,
//! its stopping point over the edge, too near an obstacle; a shove can fail several).
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
use planner::{Judgement, Planner, PlannerInput, PlannerSettings};
use sim::episode::{target_model, ModelKind};
use sim::oracle::{shove_grid, shove_states, DriverView, GridChoice, OracleSettings, ShoveGrid};
use std::path::Path;

/// Bins of the model's projected heading error (rad) of the shoves it calls feasible: the
/// upper edges (the last bin takes the rest, up to `heading_tol`).
const CONFIDENCE_EDGES: [f64; 3] = [0.15, 0.3, 0.45];

/// Per confidence bin: shoves called feasible, and of them true successes.
type Confidence = [[usize; 2]; CONFIDENCE_EDGES.len() + 1];

fn confidence_bin(heading_error: f64) -> usize {
    CONFIDENCE_EDGES
        .iter()
        .position(|&e| heading_error < e)
        .unwrap_or(CONFIDENCE_EDGES.len())
}

/// One model's verdict on a scene.
#[derive(Default, Clone, Copy)]
struct Verdict {
    first: f64,
    robust: f64,
    exp: f64,
    best: f64,
    mean: f64,
    /// Shoves: called feasible and true success, called feasible only, true success only.
    both: usize,
    model_only: usize,
    truth_only: usize,
    /// Of the `truth_only` shoves, those the model puts outside the terminal heading set,
    /// over the road edge, with the stopping point over the edge, too near an obstacle.
    miss: [usize; 4],
}

/// Which of the plan's criteria a judgement fails: the terminal heading set, the road, the
/// stopping point, the obstacle clearance (as `Planner`'s feasibility test).
fn failed(j: &Judgement, s: &PlannerSettings) -> [bool; 4] {
    let tol = s.violation_tol;
    [
        j.heading_error > s.heading_tol,
        j.road_margin < -tol || j.slide_margin < -tol,
        j.stop_margin < -tol,
        j.clearance < s.obstacle_clearance - tol,
    ]
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
) -> Result<(ShoveGrid, Vec<Judgement>), String> {
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
    let mut judged = Vec::with_capacity(truth.success.len());
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
                judged.push(j);
            }
        }
    }
    Ok((grid, judged))
}

fn verdict(
    truth: &ShoveGrid,
    view: &ShoveGrid,
    judged: &[Judgement],
    settings: &PlannerSettings,
    confidence: &mut Confidence,
) -> Verdict {
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
    for ((&t, &m), j) in truth.success.iter().zip(&view.success).zip(judged) {
        // `failed` restates the planner's test: it must agree with the planner's verdict.
        assert_eq!(
            failed(j, settings).contains(&true),
            !j.feasible,
            "the criteria disagree with Planner::judge: {j:?}"
        );
        v.both += usize::from(t && m);
        v.model_only += usize::from(m && !t);
        v.truth_only += usize::from(t && !m);
        if t && !m {
            for (n, f) in v.miss.iter_mut().zip(failed(j, settings)) {
                *n += usize::from(f);
            }
        }
        if m {
            let b = &mut confidence[confidence_bin(j.heading_error)];
            b[0] += 1;
            b[1] += usize::from(t);
        }
    }
    // The earliest time with a feasible shove: its optimum and its average.
    let heading: Vec<f64> = judged.iter().map(|j| j.heading_error).collect();
    if let Some((pick, feasible)) = view.earliest_optimum(&heading) {
        v.best = f64::from(u8::from(truth.success[pick]));
        v.mean =
            feasible.iter().filter(|&&i| truth.success[i]).count() as f64 / feasible.len() as f64;
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
        .map(|k| common::model_kind(k, "MODELS"))
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
    let mut called = vec![0usize; kinds.len()];
    let mut confidence = vec![Confidence::default(); kinds.len()];
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
        for (i, (k, (view, judged))) in kinds.iter().zip(views).enumerate() {
            let v = verdict(truth, view, judged, &planner_settings, &mut confidence[i]);
            let sum = &mut sums[i];
            line += &format!(
                " | {} first={} robust={} exp={:.2} best={} mean={:.3} both={} model_only={} truth_only={} miss_heading={} miss_road={} miss_stop={} miss_obstacle={}",
                k.name(),
                v.first,
                v.robust,
                v.exp,
                v.best,
                v.mean,
                v.both,
                v.model_only,
                v.truth_only,
                v.miss[0],
                v.miss[1],
                v.miss[2],
                v.miss[3]
            );
            // The model calls some shove feasible iff `best` and `mean` are defined.
            called[i] += usize::from(v.both + v.model_only > 0);
            sum.best += v.best;
            sum.mean += v.mean;
            sum.first += v.first;
            sum.robust += v.robust;
            sum.exp += v.exp;
            sum.both += v.both;
            sum.model_only += v.model_only;
            sum.truth_only += v.truth_only;
            for (a, b) in sum.miss.iter_mut().zip(v.miss) {
                *a += b;
            }
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
    println!(
        "\nthe model's optimum against its average feasible shove, at the earliest time it \
         calls one feasible (scenes where it does)"
    );
    println!("| model | scenes | best | mean | best − mean |");
    println!("|---|---|---|---|---|");
    for ((k, s), &c) in kinds.iter().zip(&sums).zip(&called) {
        let share = |x: f64| 100.0 * x / c.max(1) as f64;
        println!(
            "| {} | {c} | {:.1} % | {:.1} % | {:+.1} points |",
            k.name(),
            share(s.best),
            share(s.mean),
            share(s.best - s.mean)
        );
    }
    println!(
        "\nwhat the model holds against the succeeding shoves it rejects (share of them; a shove \
         can fail several criteria)"
    );
    println!(
        "| model | rejected successes | terminal heading | road edge | stopping point | obstacle |"
    );
    println!("|---|---|---|---|---|---|");
    for (k, s) in kinds.iter().zip(&sums) {
        let share = |a: usize| 100.0 * a as f64 / s.truth_only.max(1) as f64;
        println!(
            "| {} | {} | {:.1} % | {:.1} % | {:.1} % | {:.1} % |",
            k.name(),
            s.truth_only,
            share(s.miss[0]),
            share(s.miss[1]),
            share(s.miss[2]),
            share(s.miss[3])
        );
    }
    println!(
        "\ntrue success of the shoves a model calls feasible, by its projected heading error (rad)"
    );
    let mut head = String::from("| model |");
    let mut lo = 0.0;
    for e in CONFIDENCE_EDGES.iter().copied().chain([f64::INFINITY]) {
        head += &if e.is_finite() {
            format!(" {lo:.2}–{e:.2} |")
        } else {
            format!(" ≥ {lo:.2} |")
        };
        lo = e;
    }
    println!("{head}");
    println!("|---|{}", "---|".repeat(CONFIDENCE_EDGES.len() + 1));
    for (k, conf) in kinds.iter().zip(&confidence) {
        let cells: Vec<String> = conf
            .iter()
            .map(|[n, t]| format!("{:.1} % of {n}", 100.0 * *t as f64 / (*n).max(1) as f64))
            .collect();
        println!("| {} | {} |", k.name(), cells.join(" | "));
    }
}
