//! End to end over iceoryx2: both binaries as processes, on the lock-step simulated clock.
//!
//! - a lock-step run over IPC equals the in-process episode (same noise, same judge), and
//!   both processes' recordings are valid message for message against their schemas (the
//!   Foxglove SDK's for the scene, transforms and poses), with the contact drawn;
//! - killing the controller mid-run: the vehicle stops itself inside the road, and the
//!   controller's recording reads to its last message;
//! - a stall of the state stream: the controller falls back while the states are stale and
//!   resumes after; dropped states are survived;
//! - bad input names what is wrong.
//!
//! The binaries are the test profile's (debug): wall-clock deadlines are lifted.

mod common;

use common::schema_check::check_recording;
use common::{count_messages, json, root, wait, HALF, TRIALS};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn out_dir(name: &str) -> std::path::PathBuf {
    common::out_dir("ipc", name)
}

fn prefix(name: &str) -> String {
    common::prefix("ipc", name)
}

fn vehicle(id: &str, prefix: &str, extra: &[&str]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_pit-vehicle"));
    c.current_dir(root())
        .args(["--scenario", TRIALS, "--id", id, "--clock", "simulated"])
        .args(["--prefix", prefix, "--connect-timeout", "120"])
        .args(extra)
        .stdout(Stdio::null());
    c
}

fn controller(id: &str, prefix: &str, extra: &[&str]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_pit-controller"));
    c.current_dir(root())
        .args(["--scenario", TRIALS, "--id", id, "--clock", "vehicle"])
        .args(["--prefix", prefix, "--controller-config", HALF])
        .args(["--model", "4dof", "--deadline", "60"])
        .args(extra)
        .stdout(Stdio::null());
    c
}

/// Run both processes to the end; the vehicle's and the controller's summaries.
fn run_pair(
    name: &str,
    id: &str,
    vehicle_args: &[&str],
    controller_args: &[&str],
) -> (serde_json::Value, serde_json::Value) {
    let dir = out_dir(name);
    let p = prefix(name);
    let vs = dir.join("vehicle.json");
    let cs = dir.join("controller.json");
    let mut v = vehicle(id, &p, vehicle_args)
        .args(["--summary", vs.to_str().unwrap()])
        .spawn()
        .unwrap();
    let mut c = controller(id, &p, controller_args)
        .args(["--summary", cs.to_str().unwrap()])
        .spawn()
        .unwrap();
    let limit = Duration::from_secs(600);
    assert!(wait(&mut v, limit, "pit-vehicle").success());
    assert!(wait(&mut c, limit, "pit-controller").success());
    (json(&vs), json(&cs))
}

#[test]
fn a_lock_step_run_over_ipc_equals_the_in_process_episode() {
    // R4 with the paper platform's sensing noise and a 50 ms latency, seed 2; the
    // in-process runner does not compensate delays, so neither does the controller here.
    let dir = out_dir("parity");
    let (vm, cm) = (dir.join("vehicle.mcap"), dir.join("controller.mcap"));
    let (v, c) = run_pair(
        "parity",
        "R4",
        &[
            "--noise",
            "paper",
            "--latency",
            "0.05",
            "--seed",
            "2",
            "--lockstep-timeout",
            "30",
            "--record",
            vm.to_str().unwrap(),
        ],
        &["--no-delay-compensation", "--record", cm.to_str().unwrap()],
    );
    assert_eq!(v["ending"], "finished", "{v}");
    assert_eq!(c["ending"], "finished", "{c}");
    assert_eq!(v["lockstep_misses"], 0);
    assert_eq!(c["fallbacks"], 0, "{c}");

    let sc = vehicle_io::cli::load_scenario(&root().join(TRIALS), "R4").unwrap();
    let mut cfg = sim::EpisodeConfig::preset("4dof").unwrap();
    cfg.models_dir = root().join("models");
    cfg.controller = planner::ControllerSettings::from_toml_str(
        &std::fs::read_to_string(root().join(HALF)).unwrap(),
    )
    .unwrap();
    cfg.clock = sim::ClockKind::Simulated;
    cfg.uncertainty.position_std = 0.01;
    cfg.uncertainty.yaw_rate_std = 0.002;
    cfg.uncertainty.latency = 0.05;
    let r = sim::run_episode(&sc, &cfg, 2).unwrap();
    let m = serde_json::to_value(r.metrics).unwrap();
    assert_eq!(v["metrics"], m, "IPC {} vs in process {}", v["metrics"], m);

    // Both recordings: every message valid against its schema; every state drawn; the push
    // shows as a contact arrow on /scene and as force on /contact.
    for path in [&vm, &cm] {
        let rec = check_recording(&std::fs::read(path).unwrap());
        let states = rec.counts["/state"];
        assert!(states > 50, "{}: {:?}", path.display(), rec.counts);
        for t in [
            "/scene",
            "/tf",
            "/bullet/pose",
            "/target/pose",
            "/bullet/state",
            "/contact",
        ] {
            assert_eq!(rec.counts[t], states, "{}: {t}", path.display());
        }
        let arrows = rec
            .scenes
            .iter()
            .filter(|s| {
                s.entities
                    .iter()
                    .any(|e| e.id == "contact" && !e.arrows.is_empty())
            })
            .count();
        let pushing = rec.json["/contact"]
            .iter()
            .filter(|c| c["normal_force"].as_f64().unwrap() > 0.0)
            .count();
        assert!(
            arrows > 0 && arrows == pushing,
            "{}: {arrows} arrows, {pushing} pushes",
            path.display()
        );
        assert!(rec.scenes[0]
            .entities
            .iter()
            .any(|e| e.id == "road" && e.lines.len() == 3));
        assert_eq!(rec.counts["/road"], 1, "{}", path.display());
    }
}

#[test]
fn killing_the_controller_makes_the_vehicle_stop_itself_and_the_recording_reads_to_its_end() {
    let dir = out_dir("kill");
    let p = prefix("kill");
    let vs = dir.join("vehicle.json");
    let cm = dir.join("controller.mcap");
    let vm = dir.join("vehicle.mcap");
    let mut v = vehicle("R1", &p, &["--lockstep-timeout", "0.3"])
        .args([
            "--summary",
            vs.to_str().unwrap(),
            "--record",
            vm.to_str().unwrap(),
        ])
        .spawn()
        .unwrap();
    let mut c = controller("R1", &p, &[])
        .args(["--record", cm.to_str().unwrap()])
        .spawn()
        .unwrap();
    // Let the maneuver get going (the bullet is driving at speed), then SIGKILL.
    let t0 = Instant::now();
    while count_messages(&vm, "/command").0 < 25 {
        assert!(
            t0.elapsed() < Duration::from_secs(300),
            "the run never got going"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    c.kill().unwrap();
    let _ = c.wait();
    assert!(wait(&mut v, Duration::from_secs(300), "pit-vehicle").success());

    let s = json(&vs);
    let stop = &s["safe_stop"];
    assert_eq!(stop["reason"], "command_timeout", "{s}");
    assert!(stop["speed_at_latch"].as_f64().unwrap() > 1.0, "{s}");
    assert!(
        stop["stopped_at"].is_number(),
        "the bullet came to rest: {s}"
    );
    assert!(s["final_bullet_speed"].as_f64().unwrap() < 0.1, "{s}");
    assert_ne!(
        s["metrics"]["failed_vehicle"], "bullet",
        "the bullet stayed clear: {s}"
    );
    assert_ne!(s["metrics"]["failed_vehicle"], "both", "{s}");

    // The killed controller's file: every record up to the end decodes.
    let (commands, clean) = count_messages(&cm, "/command");
    assert!(commands >= 20, "{commands} commands recorded");
    assert!(!clean, "a killed process leaves no footer");
    // The vehicle ended cleanly: its file is complete.
    let (_, clean) = count_messages(&vm, "/state");
    assert!(clean, "the vehicle's recording is finished");
}

#[test]
fn a_stall_of_the_states_makes_the_controller_fall_back_and_dropped_states_are_survived() {
    let (v, c) = run_pair(
        "stall",
        "R4",
        &[
            "--stall-at",
            "1.0",
            "--stall-for",
            "0.5",
            "--drop-states",
            "0.1",
            "--seed",
            "4",
            "--lockstep-timeout",
            "0.3",
            // Shorter than the stall, so a controller that fell silent while the states
            // stall would still trip it; longer than the 0.15 s default, so that a debug
            // build's late answer on a loaded machine does not.
            "--command-timeout",
            "0.4",
        ],
        &[],
    );
    assert_eq!(v["ending"], "finished", "{v}");
    assert!(v["states_dropped"].as_u64().unwrap() >= 10, "{v}");
    assert!(
        v["safe_stop"].is_null(),
        "fallbacks are commands: no safe stop {v}"
    );
    assert!(c["stale_states"].as_u64().unwrap() >= 5, "{c}");
    assert!(c["fallbacks"].as_u64().unwrap() >= 5, "{c}");
    // It resumed: far more states were answered than fell back.
    assert!(
        c["solves"].as_u64().unwrap() > 3 * c["fallbacks"].as_u64().unwrap(),
        "{c}"
    );
}

#[test]
fn bad_input_is_refused_with_its_name() {
    let err = refused(env!("CARGO_BIN_EXE_pit-vehicle"), &["--id", "R9"]);
    assert!(err.contains("R9") && err.contains("4 scenarios"), "{err}");

    let dir = out_dir("bad");
    let cfg = dir.join("controller.toml");
    let config = ["--id", "R1", "--config", cfg.to_str().unwrap()];
    std::fs::write(&cfg, "stale_periods = 0.5\n").unwrap();
    let err = refused(env!("CARGO_BIN_EXE_pit-controller"), &config);
    assert!(err.contains("stale_periods"), "{err}");

    std::fs::write(&cfg, "perod = 0.05\n").unwrap();
    let err = refused(env!("CARGO_BIN_EXE_pit-controller"), &config);
    assert!(err.contains("perod"), "{err}");

    // A summary that could not be written is refused before the run, not after it.
    for bin in [
        env!("CARGO_BIN_EXE_pit-vehicle"),
        env!("CARGO_BIN_EXE_pit-controller"),
    ] {
        for path in ["/proc/picopit-x/s.json", "/tmp"] {
            let err = refused(bin, &["--id", "R1", "--summary", path]);
            assert!(err.contains("--summary") && err.contains(path), "{err}");
        }
    }
}

/// Run `bin` on the trial scenarios with `args`: it must exit with status 2; its stderr.
fn refused(bin: &str, args: &[&str]) -> String {
    let out = Command::new(bin)
        .current_dir(root())
        .args(["--scenario", TRIALS])
        .args(args)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2), "{bin} {args:?}");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn a_controller_started_first_waits_for_the_first_state() {
    // The vehicle's heartbeats arrive before its first state: the controller must not
    // answer them (an early safe-stop request used to latch the vehicle's safe stop at t = 0).
    let dir = out_dir("order");
    let p = prefix("order");
    let vs = dir.join("vehicle.json");
    let mut c = controller("R4", &p, &[]).spawn().unwrap();
    std::thread::sleep(Duration::from_millis(500));
    let mut v = vehicle("R4", &p, &["--latency", "0.05", "--lockstep-timeout", "30"])
        .args(["--summary", vs.to_str().unwrap()])
        .spawn()
        .unwrap();
    let limit = Duration::from_secs(600);
    assert!(wait(&mut v, limit, "pit-vehicle").success());
    assert!(wait(&mut c, limit, "pit-controller").success());
    let s = json(&vs);
    assert!(s["safe_stop"].is_null(), "{s}");
    assert_eq!(s["commands_stale"], 0, "{s}");
    assert!(s["commands_applied"].as_u64().unwrap() >= 20, "{s}");
}

#[test]
fn sigterm_ends_the_controller_cleanly_with_a_complete_recording() {
    let dir = out_dir("term");
    let p = prefix("term");
    let cs = dir.join("controller.json");
    let cm = dir.join("controller.mcap");
    let vs = dir.join("vehicle.json");
    let mut v = vehicle("R1", &p, &["--lockstep-timeout", "0.3"])
        .args(["--summary", vs.to_str().unwrap()])
        .spawn()
        .unwrap();
    let mut c = controller("R1", &p, &[])
        .args([
            "--record",
            cm.to_str().unwrap(),
            "--summary",
            cs.to_str().unwrap(),
        ])
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    while count_messages(&cm, "/command").0 < 10 {
        assert!(
            t0.elapsed() < Duration::from_secs(300),
            "the run never got going"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    // SAFETY: kill(2) on our own child's pid with SIGTERM.
    let rc = unsafe { libc::kill(c.id() as i32, libc::SIGTERM) };
    assert_eq!(rc, 0);
    let st = wait(&mut c, Duration::from_secs(60), "pit-controller");
    assert!(st.success(), "{st:?}");
    assert_eq!(json(&cs)["ending"], "interrupted");
    let (commands, clean) = count_messages(&cm, "/command");
    assert!(
        clean && commands >= 10,
        "{commands} commands, footer {clean}"
    );
    assert!(wait(&mut v, Duration::from_secs(300), "pit-vehicle").success());
    assert_eq!(json(&vs)["safe_stop"]["reason"], "command_timeout");
}
