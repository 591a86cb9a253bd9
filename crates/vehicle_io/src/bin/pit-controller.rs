//! `pit-controller`: the hierarchical PIT controller as a process. Subscribes to the state
//! estimates of both vehicles over iceoryx2, runs the upper decision layer (every
//! replanning period) and the coupled MPC (every state) on the newest state, predicted
//! forward by its latency, and publishes the bullet command and the controller status.
//! Falls back to controlled braking on a stale state, a missed deadline, a solver failure
//! or a dead peer.

use clap::{Parser, ValueEnum};
use planner::{ControllerSettings, PitController};
use std::path::PathBuf;
use vehicle_io::cli::{check_writable, fail, load_scenario, read_text, write_json};
use vehicle_io::config::{ControllerClock, ControllerIoSettings};
use vehicle_io::control::ControlLoop;
use vehicle_io::ports::{ControllerPorts, ServiceNames};
use vehicle_io::run::Ending;

#[derive(Clone, Copy, Debug, ValueEnum)]
enum Clock {
    /// Real time: "now" is the vehicle time of the newest message plus the wall time since.
    Wall,
    /// The vehicle's (possibly simulated) clock only: for lock-step, faster-than-real-time runs.
    Vehicle,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum Model {
    /// The 4-DOF analytic target model.
    #[value(name = "4dof")]
    FourDof,
    /// The teacher PINN (models/<params>/pinn.safetensors).
    Pinn,
    /// PicoPINN (models/<params>/picopinn.safetensors).
    Picopinn,
}

/// The PIT controller process (iceoryx2 IPC; see docs/vehicle_io.md).
///
/// Settings come from defaults, then `--config`, then the options given here. The road,
/// the obstacles, μ and the vehicle parameters are the scenario's (the controller's map).
#[derive(Parser, Debug)]
#[command(
    name = "pit-controller",
    version,
    about = "The hierarchical PIT controller as a process: states in, bullet commands out, over iceoryx2"
)]
struct Args {
    /// Scenario file (JSON lines, the scenario dataset's schema).
    #[arg(long, default_value = "data/scenarios.jsonl")]
    scenario: PathBuf,
    /// Id of the scenario in that file (e.g. sc-00000, R1).
    #[arg(long)]
    id: String,
    /// Settings file (TOML, `ControllerIoSettings`: prefix, period, stale_periods, deadline,
    /// peer_timeout, connect_timeout, peer_lost_timeout, compensate_delay, actuation_delay, max_compensation, fallback_brake,
    /// clock, model, models_dir, exit_when_finished and a [controller] table).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Controller settings file (TOML, `planner::ControllerSettings`), replacing the
    /// [controller] table (e.g. configs/controller_half_scale.toml).
    #[arg(long)]
    controller_config: Option<PathBuf>,
    /// Service-name prefix; must match pit-vehicle's.
    #[arg(long)]
    prefix: Option<String>,
    /// Whose clock "now" is read from.
    #[arg(long, value_enum)]
    clock: Option<Clock>,
    /// The target surrogate used by the planner and the MPC.
    #[arg(long, value_enum)]
    model: Option<Model>,
    /// Folder of the model files (<dir>/<params>/{pinn,picopinn}.safetensors).
    #[arg(long)]
    models_dir: Option<PathBuf>,
    /// Wall-time deadline of one control step (s); a later step publishes the fallback.
    #[arg(long)]
    deadline: Option<f64>,
    /// Wall time to wait for the vehicle's first heartbeat or state before giving up (s).
    #[arg(long)]
    connect_timeout: Option<f64>,
    /// Wall time without a word from the vehicle, once heard, before giving up (s).
    #[arg(long)]
    peer_lost_timeout: Option<f64>,
    /// Turn the delay compensation off (the states are used as measured).
    #[arg(long)]
    no_delay_compensation: bool,
    /// Turn the upper decision layer off (the MPC follows the default PIT reference).
    #[arg(long)]
    no_upper_layer: bool,
    /// Record every topic to this MCAP file (Foxglove-readable).
    #[arg(long)]
    record: Option<PathBuf>,
    /// Write a JSON summary (cycles, fallbacks, deadline misses, step times, memory) here.
    #[arg(long)]
    summary: Option<PathBuf>,
    /// Keep the step times of at most this many cycles for the summary (preallocated).
    #[arg(long, default_value_t = 200_000)]
    max_cycles: usize,
    /// Print the effective settings as TOML and exit.
    #[arg(long)]
    print_config: bool,
}

fn settings(args: &Args) -> Result<ControllerIoSettings, String> {
    let mut s = match &args.config {
        Some(p) => ControllerIoSettings::from_toml_str(&read_text(p)?, &p.display().to_string())
            .map_err(|e| e.to_string())?,
        None => ControllerIoSettings::default(),
    };
    if let Some(p) = &args.controller_config {
        s.controller = ControllerSettings::from_toml_str(&read_text(p)?)
            .map_err(|e| format!("{}: {e}", p.display()))?;
    }
    if let Some(v) = &args.prefix {
        s.prefix.clone_from(v);
    }
    if let Some(c) = args.clock {
        s.clock = match c {
            Clock::Wall => ControllerClock::Wall,
            Clock::Vehicle => ControllerClock::Vehicle,
        };
    }
    if let Some(m) = args.model {
        s.model = match m {
            Model::FourDof => sim::ModelKind::FourDof,
            Model::Pinn => sim::ModelKind::Pinn,
            Model::Picopinn => sim::ModelKind::PicoPinn,
        };
    }
    if let Some(d) = &args.models_dir {
        s.models_dir.clone_from(d);
    }
    if let Some(d) = args.deadline {
        s.deadline = d;
    }
    if let Some(v) = args.connect_timeout {
        s.connect_timeout = v;
    }
    if let Some(v) = args.peer_lost_timeout {
        s.peer_lost_timeout = v;
    }
    if args.no_delay_compensation {
        s.compensate_delay = false;
    }
    if args.no_upper_layer {
        s.controller.upper_layer = false;
    }
    if s.clock == ControllerClock::Vehicle {
        // Lock-step runs must not depend on the machine: lift the solvers' wall limits.
        s.controller.mpc.qp.time_limit = s.controller.mpc.qp.time_limit.max(1.0e3);
        s.controller.planner.qp.time_limit = s.controller.planner.qp.time_limit.max(1.0e3);
    }
    s.validate().map_err(|e| e.to_string())?;
    Ok(s)
}

/// A relative models folder that does not exist here is looked up beside the binary's
/// checkout (`<repo>/target/release/pit-controller` → `<repo>/models`).
fn resolve_models_dir(dir: &std::path::Path) -> PathBuf {
    if dir.is_absolute() || dir.exists() {
        return dir.to_path_buf();
    }
    std::env::current_exe()
        .ok()
        .and_then(|exe| {
            exe.ancestors()
                .skip(1)
                .map(|a| a.join(dir))
                .find(|p| p.is_dir())
        })
        .unwrap_or_else(|| dir.to_path_buf())
}

fn main() {
    let args = Args::parse();
    let s = settings(&args).unwrap_or_else(|e| fail(&e));
    if args.print_config {
        print!(
            "{}",
            toml::to_string(&s).unwrap_or_else(|e| fail(&e.to_string()))
        );
        return;
    }
    let mut s = s;
    s.models_dir = resolve_models_dir(&s.models_dir);
    if let Some(p) = &args.summary {
        check_writable(p, "--summary").unwrap_or_else(|e| fail(&e));
    }
    let sc = load_scenario(&args.scenario, &args.id).unwrap_or_else(|e| fail(&e));
    let params = sc.params.load().unwrap_or_else(|e| fail(&e.to_string()));
    let road = sc.build_road().unwrap_or_else(|e| fail(&e.to_string()));
    let dt = s.controller.mpc.dt;
    let model = |()| {
        sim::episode::target_model(s.model, &s.models_dir, None, &sc, &params, dt)
            .unwrap_or_else(|e| fail(&e.to_string()))
    };
    let mut ctl = PitController::new(&params, sc.mu, model(()), model(()), s.controller.clone())
        .unwrap_or_else(|e| fail(&e.to_string()));
    if s.clock == ControllerClock::Vehicle {
        // As the in-process runner's simulated clock: the controller's own timing (the MPC's
        // time budget) counts clock readings, so a lock-step run does not depend on the
        // machine's speed. Step times are still measured on the wall clock by the loop.
        ctl = ctl.with_clock(
            Box::new(mpc::TickClock::new(1.0e-5)),
            Box::new(mpc::TickClock::new(1.0e-5)),
        );
    }
    let names = ServiceNames::new(&s.prefix).unwrap_or_else(|e| fail(&e.to_string()));
    let ports = ControllerPorts::open(&names).unwrap_or_else(|e| fail(&e.to_string()));
    let recorder = args.record.as_ref().map(|path| {
        vehicle_io::recording::start(&names, path, &sc, &params, "pit-controller")
            .unwrap_or_else(|e| fail(&e))
    });
    let mut lp = ControlLoop::new(s, ctl, &params, sc.mu, road, sc.obstacles());
    let summary = vehicle_io::run::run_controller(&mut lp, &ports, args.max_cycles);
    if let Some(r) = recorder {
        if let Err(e) = vehicle_io::recording::stop(r) {
            eprintln!("warning: {e}");
        }
    }
    eprintln!(
        "pit-controller: {:?} after {} cycles ({} solves, {} fallbacks, {} deadline misses, {} stale); step median {:.2} ms, p99 {:.2} ms; peak RSS {} KiB",
        summary.ending,
        summary.counters.cycles,
        summary.counters.solves,
        summary.counters.fallbacks,
        summary.counters.deadline_misses,
        summary.counters.stale_states,
        summary.cycle_ms.median,
        summary.cycle_ms.p99,
        summary.peak_rss_kib
    );
    if let Some(p) = &args.summary {
        write_json(p, &summary).unwrap_or_else(|e| fail(&e));
    }
    if summary.ending.is_failure() {
        eprintln!(
            "pit-controller: error: {} (prefix {:?})",
            failure_text(summary.ending, &lp),
            lp.settings().prefix
        );
    }
    std::process::exit(summary.ending.exit_code());
}

/// Why the controller gave up, in words.
fn failure_text(ending: Ending, lp: &ControlLoop) -> String {
    let s = lp.settings();
    match ending {
        Ending::NoPeer => format!(
            "no vehicle heard within connect_timeout = {} s; is pit-vehicle running with the same --prefix?",
            s.connect_timeout
        ),
        Ending::PeerLost => format!(
            "the vehicle went silent for peer_lost_timeout = {} s; giving up",
            s.peer_lost_timeout
        ),
        _ => "the iceoryx2 transport failed".to_owned(),
    }
}
