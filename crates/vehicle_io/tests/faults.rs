//! IPC faults with both binaries as processes on the wall clock, each repeated 20 times:
//!
//! - SIGKILL the controller mid-run: the vehicle never freezes; it latches its safe stop
//!   within one period of the command timeout and ends its run;
//! - SIGSTOP the controller for 0.05–0.5 s, then SIGCONT: the controller carries on, and a
//!   safe stop the pause caused is released by its fresh commands;
//! - SIGSTOP the vehicle for 0.05–0.5 s, then SIGCONT: both carry on and end cleanly;
//! - either start order works;
//! - a missing or vanished peer is waited for a bounded time, then the process exits with
//!   status 1 and says why;
//! - SIGTERM ends the vehicle promptly, on the wall clock and in lock step, also when it
//!   comes while the vehicle is stopped and a SIGCONT follows.
//!
//! Every process is bounded by a timeout. The binaries are the test profile's (debug, at
//! the workspace's `opt-level = 1`): the controller runs the 4-DOF model without the upper
//! layer and without a deadline, so that its answers keep pace with the wall clock on a slow
//! machine. Unoptimised, its cycle took about 90 ms on a 2-core machine busy with a
//! benchmark, against the 100 ms a command stays valid, and most commands came stale (18 of
//! 20 in a failed run); at `opt-level = 1`, 10 ms.

mod common;

use common::{json, out_dir, prefix, root, signal, try_wait, wait, wait_for_messages, HALF};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

const SUITE: &str = "faults";
const REPEATS: usize = 20;
/// The vehicle's state period and command timeout (the defaults).
const PERIOD_MS: f64 = 50.0;
const COMMAND_TIMEOUT: f64 = 0.15;
/// Generous bounds on a process that should end by itself.
const LIMIT: Duration = Duration::from_secs(60);

/// `defaults` (option, value) pairs, except those `extra` gives, then `extra`.
fn options<'a>(defaults: &[(&'a str, &'a str)], extra: &[&'a str]) -> Vec<&'a str> {
    let mut out = Vec::new();
    for (k, v) in defaults {
        if !extra.contains(k) {
            out.extend([*k, *v]);
        }
    }
    out.extend(extra);
    out
}

fn vehicle(p: &str, dir: &Path, max_time: f64, extra: &[&str]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_pit-vehicle"));
    c.current_dir(root())
        .args(["--scenario", common::TRIALS, "--id", "R1"])
        .args(["--prefix", p])
        .args(["--max-time", &max_time.to_string()])
        .arg("--summary")
        .arg(dir.join("vehicle.json"))
        .arg("--record")
        .arg(dir.join("vehicle.mcap"))
        .args(options(
            &[("--clock", "wall"), ("--connect-timeout", "60")],
            extra,
        ))
        .stdout(Stdio::null())
        .stderr(Stdio::null());
    c
}

fn controller(p: &str, dir: &Path, extra: &[&str]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_pit-controller"));
    c.current_dir(root())
        .args(["--scenario", common::TRIALS, "--id", "R1"])
        .args(["--prefix", p, "--controller-config", HALF])
        .args(["--model", "4dof", "--no-upper-layer", "--deadline", "60"])
        .arg("--summary")
        .arg(dir.join("controller.json"))
        .args(options(
            &[
                ("--clock", "wall"),
                ("--connect-timeout", "60"),
                ("--peer-lost-timeout", "10"),
            ],
            extra,
        ))
        .stdout(Stdio::null())
        .stderr(Stdio::null());
    c
}

/// Run both on a fresh prefix: `fault` gets the children once the vehicle has published a
/// few states. Returns the vehicle's and the controller's exit codes and summaries
/// (`Null` when a process wrote none).
fn run_pair(
    name: &str,
    max_time: f64,
    fault: impl FnOnce(&mut Child, &mut Child, &Path),
) -> (
    Option<i32>,
    serde_json::Value,
    Option<i32>,
    serde_json::Value,
) {
    let dir = out_dir(SUITE, name);
    let p = prefix(SUITE, name);
    let mut v = vehicle(&p, &dir, max_time, &[]).spawn().unwrap();
    let mut c = controller(&p, &dir, &[]).spawn().unwrap();
    fault(&mut v, &mut c, &dir);
    let vs = try_wait(&mut v, LIMIT);
    let cs = try_wait(&mut c, LIMIT);
    assert!(
        vs.is_some(),
        "{name}: pit-vehicle froze (still running after {LIMIT:?})"
    );
    assert!(
        cs.is_some(),
        "{name}: pit-controller still running after {LIMIT:?}"
    );
    let read = |f: &str| {
        let path = dir.join(f);
        if path.exists() {
            json(&path)
        } else {
            serde_json::Value::Null
        }
    };
    (
        vs.unwrap().code(),
        read("vehicle.json"),
        cs.unwrap().code(),
        read("controller.json"),
    )
}

/// The vehicle's run ended by its time limit or by the judge's decision.
fn ended_cleanly(v: &serde_json::Value) -> bool {
    v["ending"] == "time_limit" || v["ending"] == "finished"
}

fn f64_of(v: &serde_json::Value) -> f64 {
    v.as_f64().unwrap_or(f64::NAN)
}

#[test]
fn a_killed_controller_never_freezes_the_vehicle_and_its_safe_stop_is_on_time() {
    for i in 0..REPEATS {
        let name = format!("kill-{i}");
        // Kill after 2 to 11 states (0.05 to 0.5 s into the run).
        let after = 2 + i % 10;
        let (vc, v, _, _) = run_pair(&name, 1.5, |_, c, dir| {
            wait_for_messages(&dir.join("vehicle.mcap"), "/state", after, LIMIT);
            c.kill().unwrap();
            let _ = c.wait();
        });
        assert_eq!(vc, Some(0), "{name}: {v}");
        assert!(ended_cleanly(&v), "{name}: {v}");
        let stop = &v["safe_stop"];
        assert_eq!(stop["reason"], "command_timeout", "{name}: {v}");
        assert!(stop["resumed_at"].is_null(), "{name}: {v}");
        let late = f64_of(&v["safe_stop_late_max_ms"]);
        assert!(
            (0.0..=PERIOD_MS).contains(&late),
            "{name}: a safe stop {late} ms after its deadline: {v}"
        );
    }
}

#[test]
fn a_paused_controller_carries_on_and_gets_the_vehicle_back() {
    for i in 0..REPEATS {
        let name = format!("pause-controller-{i}");
        let pause = 0.05 + 0.45 * i as f64 / (REPEATS - 1) as f64;
        let (vc, v, cc, c) = run_pair(&name, 2.5, |_, c, dir| {
            wait_for_messages(&dir.join("vehicle.mcap"), "/state", 10, LIMIT);
            signal(c, libc::SIGSTOP);
            std::thread::sleep(Duration::from_secs_f64(pause));
            signal(c, libc::SIGCONT);
        });
        // The interrupted wait is not a transport failure: the controller runs to the end.
        assert_eq!(c["ending"], "finished", "{name} ({pause:.2} s): {c}");
        assert_eq!(cc, Some(0), "{name}: {c}");
        assert_eq!(vc, Some(0), "{name}: {v}");
        assert!(ended_cleanly(&v), "{name}: {v}");
        let (stops, resumes) = (
            v["safe_stops"].as_u64().unwrap(),
            v["resumes"].as_u64().unwrap(),
        );
        if pause >= 2.0 * COMMAND_TIMEOUT {
            // The pause outlasted the command timeout: the vehicle stopped itself, and the
            // controller that came back had it again.
            assert!(stops >= 1, "{name} ({pause:.2} s): no safe stop: {v}");
            assert!(resumes >= 1, "{name} ({pause:.2} s): never resumed: {v}");
        }
        assert!(
            f64_of(&v["safe_stop_late_max_ms"]) <= PERIOD_MS,
            "{name}: {v}"
        );
    }
}

#[test]
fn a_paused_vehicle_catches_up_and_both_end_cleanly() {
    for i in 0..REPEATS {
        let name = format!("pause-vehicle-{i}");
        let pause = 0.05 + 0.45 * i as f64 / (REPEATS - 1) as f64;
        let (vc, v, cc, c) = run_pair(&name, 2.5, |v, _, dir| {
            wait_for_messages(&dir.join("vehicle.mcap"), "/state", 10, LIMIT);
            signal(v, libc::SIGSTOP);
            std::thread::sleep(Duration::from_secs_f64(pause));
            signal(v, libc::SIGCONT);
        });
        assert_eq!(vc, Some(0), "{name} ({pause:.2} s): {v}");
        assert!(ended_cleanly(&v), "{name}: {v}");
        assert_eq!(cc, Some(0), "{name}: {c}");
        assert_eq!(c["ending"], "finished", "{name}: {c}");
        assert!(
            f64_of(&v["safe_stop_late_max_ms"]) <= PERIOD_MS,
            "{name}: {v}"
        );
        // The controller had the vehicle again after the pause: a safe stop it caused was
        // released. The pause ends after about a second (it begins once ten 50 ms states are
        // on disk and lasts at most 0.5 s); a later latch is a debug-build controller late on
        // a loaded machine (CI: one at 1.975 s of 2.5, 0.525 s before the end, with 250 ms
        // round trips), and one in the last second may still be on.
        let stop = &v["safe_stop"];
        assert!(
            stop.is_null()
                || !stop["resumed_at"].is_null()
                || f64_of(&stop["at"]) > f64_of(&v["time"]) - 1.0,
            "{name} ({pause:.2} s): {v}"
        );
    }
}

#[test]
fn either_process_may_start_first() {
    for i in 0..REPEATS {
        let name = format!("order-{i}");
        let dir = out_dir(SUITE, &name);
        let p = prefix(SUITE, &name);
        let delay = Duration::from_millis(30 * (i as u64 / 2 % 10));
        let (mut v, mut c) = if i % 2 == 0 {
            let v = vehicle(&p, &dir, 1.0, &[]).spawn().unwrap();
            std::thread::sleep(delay);
            (v, controller(&p, &dir, &[]).spawn().unwrap())
        } else {
            let c = controller(&p, &dir, &[]).spawn().unwrap();
            std::thread::sleep(delay);
            (vehicle(&p, &dir, 1.0, &[]).spawn().unwrap(), c)
        };
        assert!(wait(&mut v, LIMIT, "pit-vehicle").success(), "{name}");
        assert!(wait(&mut c, LIMIT, "pit-controller").success(), "{name}");
        let s = json(&dir.join("vehicle.json"));
        // The controller took charge whichever came first (a debug build's first cycles on a
        // loaded machine can be slow enough for a few stale commands, so no more is asked).
        assert!(s["commands_applied"].as_u64().unwrap() >= 1, "{name}: {s}");
        // No early answer to a heartbeat asked the vehicle for its safe stop.
        assert_ne!(
            s["safe_stop"]["reason"], "controller_request",
            "{name}: {s}"
        );
        assert_eq!(json(&dir.join("controller.json"))["ending"], "finished");
    }
}

/// Run `cmd` alone: it must exit with status 1 within `LIMIT`; its stderr.
fn gives_up(mut cmd: Command, what: &str) -> String {
    let mut child = cmd.stderr(Stdio::piped()).spawn().unwrap();
    let st = wait(&mut child, LIMIT, what);
    let mut err = String::new();
    std::io::Read::read_to_string(child.stderr.as_mut().unwrap(), &mut err).unwrap();
    assert_eq!(st.code(), Some(1), "{what}: {st:?}\n{err}");
    err
}

#[test]
fn a_missing_or_vanished_peer_is_waited_for_a_bounded_time_then_named() {
    // No vehicle at all (also: started after the vehicle gave up).
    let dir = out_dir(SUITE, "alone-c");
    let c = controller(&prefix(SUITE, "alone-c"), &dir, &["--connect-timeout", "1"]);
    let err = gives_up(c, "pit-controller without a vehicle");
    assert!(
        err.contains("no vehicle") && err.contains("connect_timeout"),
        "{err}"
    );
    assert_eq!(json(&dir.join("controller.json"))["ending"], "no_peer");

    // No controller.
    let dir = out_dir(SUITE, "alone-v");
    let v = vehicle(
        &prefix(SUITE, "alone-v"),
        &dir,
        1.0,
        &["--connect-timeout", "1"],
    );
    let err = gives_up(v, "pit-vehicle without a controller");
    assert!(
        err.contains("no controller") && err.contains("connect_timeout"),
        "{err}"
    );
    assert_eq!(json(&dir.join("vehicle.json"))["ending"], "no_peer");

    // The vehicle dies mid-run: the controller falls back, then gives up.
    let dir = out_dir(SUITE, "vanished");
    let p = prefix(SUITE, "vanished");
    let mut v = vehicle(&p, &dir, 30.0, &[]).spawn().unwrap();
    let mut c = controller(&p, &dir, &["--peer-lost-timeout", "1"]);
    c.stderr(Stdio::piped());
    let mut c = c.spawn().unwrap();
    wait_for_messages(&dir.join("vehicle.mcap"), "/state", 5, LIMIT);
    v.kill().unwrap();
    let _ = v.wait();
    let st = wait(&mut c, LIMIT, "pit-controller after its vehicle died");
    let mut err = String::new();
    std::io::Read::read_to_string(c.stderr.as_mut().unwrap(), &mut err).unwrap();
    assert_eq!(st.code(), Some(1), "{err}");
    assert!(err.contains("went silent"), "{err}");
    let s = json(&dir.join("controller.json"));
    assert_eq!(s["ending"], "peer_lost", "{s}");
    assert!(
        s["fallbacks"].as_u64().unwrap() >= 1,
        "it fell back first: {s}"
    );
}

#[test]
fn sigterm_ends_the_vehicle_promptly_on_either_clock() {
    // The vehicle checks for SIGTERM while it waits for a command and again at the end of
    // each period. iceoryx2 keeps only the last signal (a SIGCONT after the SIGTERM would
    // replace it): the processes catch SIGINT and SIGTERM themselves.
    for i in 0..10 {
        let name = format!("term-{i}");
        let dir = out_dir(SUITE, &name);
        let p = prefix(SUITE, &name);
        let lock_step = i % 2 == 1;
        let (vc, cc) = if lock_step {
            (
                vec!["--clock", "simulated", "--lockstep-timeout", "5"],
                vec!["--clock", "vehicle", "--peer-lost-timeout", "1"],
            )
        } else {
            (vec![], vec!["--peer-lost-timeout", "1"])
        };
        let mut v = vehicle(&p, &dir, 30.0, &vc).spawn().unwrap();
        let mut c = controller(&p, &dir, &cc).spawn().unwrap();
        wait_for_messages(&dir.join("vehicle.mcap"), "/state", 10 + i, LIMIT);
        // Every other pair of runs the vehicle is stopped when the SIGTERM comes, and a
        // SIGCONT follows, as `systemctl stop` sends them: on resuming, the kernel delivers
        // the SIGTERM first and the SIGCONT after it, which must not erase it.
        let stopped = i % 4 >= 2;
        if stopped {
            signal(&v, libc::SIGSTOP);
            std::thread::sleep(Duration::from_millis(100));
        }
        signal(&v, libc::SIGTERM);
        if stopped {
            std::thread::sleep(Duration::from_millis(50));
            signal(&v, libc::SIGCONT);
        }
        let st = try_wait(&mut v, Duration::from_secs(10));
        assert!(
            st.is_some(),
            "{name}: pit-vehicle ignored SIGTERM (lock step {lock_step})"
        );
        assert_eq!(st.unwrap().code(), Some(0), "{name}");
        let s = json(&dir.join("vehicle.json"));
        assert_eq!(s["ending"], "interrupted", "{name}: {s}");
        // Its controller gives up on the vanished vehicle.
        assert_eq!(wait(&mut c, LIMIT, "pit-controller").code(), Some(1));
    }
}
