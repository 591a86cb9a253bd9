//! `pit-vehicle`: the vehicle side of the IPC. Here it runs the high-fidelity plant for
//! both vehicles (the `VehicleBridge` a real car's CAN gateway would implement), with
//! sensing noise, latency and actuator errors; publishes the state estimates every period,
//! applies the controller's commands, and brings the bullet to a safe stop on its own when
//! commands stop coming.

use clap::{Parser, ValueEnum};
use std::path::PathBuf;
use vehicle_io::cli::{check_writable, fail, load_scenario, read_text, write_json};
use vehicle_io::config::{VehicleClock, VehicleIoSettings};
use vehicle_io::ports::{ServiceNames, VehiclePorts};
use vehicle_io::vehicle::SimBridge;

#[derive(Clone, Copy, Debug, ValueEnum)]
enum Clock {
    /// Real time: the plant advances with the wall clock; commands apply on arrival.
    Wall,
    /// Lock step on a simulated clock, as fast as the controller answers.
    Simulated,
}

#[derive(Clone, Copy, Debug, ValueEnum, PartialEq, Eq)]
enum Noise {
    /// No sensing noise.
    None,
    /// The paper's half-scale platform: position σ 0.01 m, angular rate σ 0.002 rad/s.
    Paper,
}

/// The vehicle-side process (iceoryx2 IPC; see docs/vehicle_io.md).
///
/// Settings come from defaults, then `--config`, then the options given here.
#[derive(Parser, Debug)]
#[command(
    name = "pit-vehicle",
    version,
    about = "The vehicle side: the plant for both vehicles, states out, commands in, over iceoryx2"
)]
struct Args {
    /// Scenario file (JSON lines, the scenario dataset's schema).
    #[arg(long, default_value = "data/scenarios.jsonl")]
    scenario: PathBuf,
    /// Id of the scenario in that file (e.g. sc-00000, R1).
    #[arg(long)]
    id: String,
    /// Settings file (TOML, `VehicleIoSettings`: prefix, period, clock, lockstep_timeout,
    /// command_timeout, resume_after, connect_timeout, safe_stop_brake, seed, soak_periods and the
    /// [uncertainty] and [faults] tables).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Service-name prefix; must match pit-controller's.
    #[arg(long)]
    prefix: Option<String>,
    /// How the run is paced.
    #[arg(long, value_enum)]
    clock: Option<Clock>,
    /// Seed of the sensing noise, actuator errors and dropped states.
    #[arg(long)]
    seed: Option<u64>,
    /// Sensing noise preset (adds to the settings file's [uncertainty]).
    #[arg(long, value_enum, default_value = "none")]
    noise: Noise,
    /// Sensing latency (s): the states are this old when published.
    #[arg(long)]
    latency: Option<f64>,
    /// Probability that a state estimate is dropped (not published).
    #[arg(long)]
    drop_states: Option<f64>,
    /// Publish no state from this vehicle time on (s) ...
    #[arg(long)]
    stall_at: Option<f64>,
    /// ... for this long (s).
    #[arg(long)]
    stall_for: Option<f64>,
    /// No valid command for this long (s): the vehicle's own safe stop.
    #[arg(long)]
    command_timeout: Option<f64>,
    /// Consecutive fresh commands that release a safe stop latched on the command timeout
    /// (0: it stays latched until the run ends).
    #[arg(long)]
    resume_after: Option<u32>,
    /// Simulated clock: wall time to wait for each answer (s).
    #[arg(long)]
    lockstep_timeout: Option<f64>,
    /// Wall time to wait for the controller before giving up (s).
    #[arg(long)]
    connect_timeout: Option<f64>,
    /// Soak: restart the scenario until this many periods have run.
    #[arg(long)]
    soak_periods: Option<u64>,
    /// Stop at this vehicle time (s; default: the scenario's T_max + 20 s, or the soak's length).
    #[arg(long)]
    max_time: Option<f64>,
    /// Record every topic to this MCAP file (Foxglove-readable).
    #[arg(long)]
    record: Option<PathBuf>,
    /// Write a JSON summary (outcome, safe stop, IPC latency, counters) here.
    #[arg(long)]
    summary: Option<PathBuf>,
    /// Print the effective settings as TOML and exit.
    #[arg(long)]
    print_config: bool,
}

fn settings(args: &Args) -> Result<VehicleIoSettings, String> {
    let mut s = match &args.config {
        Some(p) => VehicleIoSettings::from_toml_str(&read_text(p)?, &p.display().to_string())
            .map_err(|e| e.to_string())?,
        None => VehicleIoSettings::default(),
    };
    if let Some(v) = &args.prefix {
        s.prefix.clone_from(v);
    }
    if let Some(c) = args.clock {
        s.clock = match c {
            Clock::Wall => VehicleClock::Wall,
            Clock::Simulated => VehicleClock::Simulated,
        };
    }
    if let Some(v) = args.seed {
        s.seed = v;
    }
    if args.noise == Noise::Paper {
        s.uncertainty.position_std = 0.01;
        s.uncertainty.yaw_rate_std = 0.002;
    }
    if let Some(v) = args.latency {
        s.uncertainty.latency = v;
    }
    if let Some(v) = args.drop_states {
        s.faults.drop_states = v;
    }
    if let Some(v) = args.stall_at {
        s.faults.stall_at = v;
    }
    if let Some(v) = args.stall_for {
        s.faults.stall_for = v;
    }
    if let Some(v) = args.command_timeout {
        s.command_timeout = v;
    }
    if let Some(v) = args.resume_after {
        s.resume_after = v;
    }
    if let Some(v) = args.lockstep_timeout {
        s.lockstep_timeout = v;
    }
    if let Some(v) = args.connect_timeout {
        s.connect_timeout = v;
    }
    if let Some(v) = args.soak_periods {
        s.soak_periods = v;
    }
    s.validate().map_err(|e| e.to_string())?;
    Ok(s)
}

/// The vehicle summary with the judge's verdict.
#[derive(serde::Serialize)]
struct Report<'a> {
    scenario: &'a str,
    params: &'a str,
    seed: u64,
    metrics: sim::Metrics,
    success: bool,
    cause: Option<&'static str>,
    #[serde(flatten)]
    io: vehicle_io::run::VehicleSummary,
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
    if let Some(p) = &args.summary {
        check_writable(p, "--summary").unwrap_or_else(|e| fail(&e));
    }
    let sc = load_scenario(&args.scenario, &args.id).unwrap_or_else(|e| fail(&e));
    let params = sc.params.load().unwrap_or_else(|e| fail(&e.to_string()));
    let mut bridge = SimBridge::new(&sc, s.uncertainty, s.period, s.seed, s.safe_stop_brake)
        .unwrap_or_else(|e| fail(&e.to_string()));
    let names = ServiceNames::new(&s.prefix).unwrap_or_else(|e| fail(&e.to_string()));
    let ports = VehiclePorts::open(&names).unwrap_or_else(|e| fail(&e.to_string()));
    let recorder = args.record.as_ref().map(|path| {
        vehicle_io::recording::start(&names, path, &sc, &params, "pit-vehicle")
            .unwrap_or_else(|e| fail(&e))
    });
    let default_max_time = if s.soak_periods > 0 {
        s.soak_periods as f64 * s.period + sc.t_max + 30.0
    } else {
        sc.t_max + 20.0
    };
    let max_time = args.max_time.unwrap_or(default_max_time);
    if !(max_time.is_finite() && max_time > 0.0) {
        fail(&format!(
            "--max-time {max_time}: must be a positive number of seconds"
        ));
    }
    let io = vehicle_io::run::run_vehicle(&s, &mut bridge, &ports, max_time);
    if let Some(r) = recorder {
        if let Err(e) = vehicle_io::recording::stop(r) {
            eprintln!("warning: {e}");
        }
    }
    let metrics = bridge.metrics();
    let ending = io.ending;
    eprintln!(
        "pit-vehicle: {:?} at t = {:.2} s after {} periods; outcome {}; {} states ({} dropped), {} commands applied, {} lock-step misses; {} safe stops ({} resumed, last {:?}); IPC median {:.1} µs, p99 {:.1} µs",
        io.ending,
        io.time,
        io.periods,
        metrics.cause.map_or(if metrics.success { "success" } else { "undecided" }, |c| c.name()),
        io.states_published,
        io.states_dropped,
        io.commands_applied,
        io.lockstep_misses,
        io.safe_stops,
        io.resumes,
        io.safe_stop.map(|r| r.reason),
        io.ipc_us.median,
        io.ipc_us.p99
    );
    if let Some(p) = &args.summary {
        let report = Report {
            scenario: &sc.id,
            params: sc.params.name(),
            seed: s.seed,
            metrics,
            success: metrics.success,
            cause: metrics.cause.map(|c| c.name()),
            io,
        };
        write_json(p, &report).unwrap_or_else(|e| fail(&e));
    }
    if ending.is_failure() {
        let why = match ending {
            vehicle_io::run::Ending::NoPeer => format!(
                "no controller heard within connect_timeout = {} s; is pit-controller running with the same --prefix?",
                s.connect_timeout
            ),
            _ => "the iceoryx2 transport failed".to_owned(),
        };
        eprintln!("pit-vehicle: error: {why} (prefix {:?})", s.prefix);
    }
    std::process::exit(ending.exit_code());
}
