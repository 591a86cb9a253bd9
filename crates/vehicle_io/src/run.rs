//! The two processes' loops over their ports: [`run_controller`] and [`run_vehicle`]. The
//! binaries parse their command lines and call these; the logic lives in
//! [`crate::control::ControlLoop`] and [`crate::vehicle`].

use crate::config::{secs_to_ns, ControllerClock, VehicleClock, VehicleIoSettings};
use crate::control::{ControlLoop, Counters, CycleInput};
use crate::msg::{
    ActuatorCommand, Heartbeat, StateEstimate, PEER_CONTROLLER, PEER_VEHICLE, STATE_FINISHED,
    STATE_RESTARTED,
};
use crate::ports::{
    monotonic_ns, newest, publish, termination_requested, wait_event, ControllerPorts, IoFault,
    VehiclePorts,
};
use crate::vehicle::{Actuation, CommandGate, SafeStopReason, VehicleBridge};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;
use std::time::Duration;

/// Median, 99th percentile and maximum of a sample (NaN when empty).
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct Stats {
    pub count: usize,
    pub median: f64,
    pub p99: f64,
    pub max: f64,
}

impl Stats {
    /// Of `v` (sorted in place); linear interpolation between order statistics.
    #[must_use]
    pub fn of(v: &mut [f64]) -> Self {
        v.sort_by(f64::total_cmp);
        Self {
            count: v.len(),
            median: sim::episode::percentile(v, 50.0),
            p99: sim::episode::percentile(v, 99.0),
            max: v.last().copied().unwrap_or(f64::NAN),
        }
    }
}

/// Peak and current resident memory of this process (KiB, from `/proc/self/status`).
#[must_use]
pub fn resident_kib() -> (u64, u64) {
    let text = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let field = |name: &str| {
        text.lines()
            .find(|l| l.starts_with(name))
            .and_then(|l| l.split_whitespace().nth(1))
            .and_then(|v| v.parse().ok())
            .unwrap_or(0)
    };
    (field("VmHWM:"), field("VmRSS:"))
}

/// How a loop ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Ending {
    /// The run is over (the vehicle's judge decided).
    Finished,
    /// SIGINT or SIGTERM.
    Interrupted,
    /// The peer never showed up within `connect_timeout`.
    NoPeer,
    /// The peer was heard, then nothing came from it for `peer_lost_timeout` (controller).
    PeerLost,
    /// The time limit passed.
    TimeLimit,
    /// The transport failed.
    Transport,
}

impl Ending {
    /// Whether the process could not do its job: the binaries exit with status 1 then.
    #[must_use]
    pub fn is_failure(self) -> bool {
        matches!(self, Self::NoPeer | Self::PeerLost | Self::Transport)
    }

    /// The exit status of a process that ended so: 0, or 1 for a failure.
    #[must_use]
    pub fn exit_code(self) -> i32 {
        i32::from(self.is_failure())
    }
}

/// What the controller did.
#[derive(Debug, Clone, Serialize)]
pub struct ControllerSummary {
    pub ending: Ending,
    #[serde(flatten)]
    pub counters: Counters,
    pub states_received: u64,
    /// New vehicle processes met mid-run (their state sequence started again).
    pub vehicle_restarts: u64,
    /// Control-step time, planning included (ms), over the solving cycles.
    pub cycle_ms: Stats,
    /// Planning time of the cycles that replanned (ms).
    pub plan_ms: Stats,
    pub peak_rss_kib: u64,
    pub rss_kib: u64,
}

fn heartbeat(peer: u32) -> Heartbeat {
    Heartbeat {
        peer,
        pid: std::process::id(),
        ..Heartbeat::default()
    }
}

fn beat(
    p: &iceoryx2::port::publisher::Publisher<crate::ports::Svc, Heartbeat, ()>,
    hb: &mut Heartbeat,
    vehicle_ns: u64,
) -> Result<(), IoFault> {
    hb.seq += 1;
    hb.wall_sent_ns = monotonic_ns();
    hb.vehicle_ns = vehicle_ns;
    publish(p, *hb)
}

/// The controller's loop: wake on each vehicle event, answer every new state with a
/// command and a status, fall back when the state goes stale or the peer dies.
///
/// Ends when the vehicle reports the run finished, on SIGINT/SIGTERM, when the vehicle is
/// not heard within `connect_timeout` of the start ([`Ending::NoPeer`]) or for
/// `peer_lost_timeout` after it was heard ([`Ending::PeerLost`]), or when the transport
/// fails. A signal that only interrupts a wait (SIGSTOP/SIGCONT) does not end it. A state
/// whose sequence number goes back comes from a new vehicle process: the controller starts
/// over.
///
/// Memory: `max_cycles` samples of cycle and planning times, preallocated; the loop
/// allocates nothing else (the ports are iceoryx2 shared memory).
#[allow(clippy::too_many_lines)]
pub fn run_controller(
    lp: &mut ControlLoop,
    ports: &ControllerPorts,
    max_cycles: usize,
) -> ControllerSummary {
    let s = lp.settings().clone();
    let period = Duration::from_secs_f64(s.period);
    let peer_timeout_ns = secs_to_ns(s.peer_timeout);
    let connect_ns = secs_to_ns(s.connect_timeout);
    let lost_ns = secs_to_ns(s.peer_lost_timeout);
    let stale_ns = s.stale_ns();
    let mut cycle_ms = Vec::with_capacity(max_cycles);
    let mut plan_ms = Vec::with_capacity(max_cycles);
    let mut hb = heartbeat(PEER_CONTROLLER);
    let mut latest: Option<StateEstimate> = None;
    let mut latest_wall = 0u64;
    // The newest (vehicle clock, wall clock) pair heard from the vehicle.
    let mut reference: Option<(u64, u64)> = None;
    let mut last_hb_wall: Option<u64> = None;
    // When anything (a state or a heartbeat) last came from the vehicle.
    let mut heard_wall: Option<u64> = None;
    let start_wall = monotonic_ns();
    let mut states_received = 0u64;
    let mut vehicle_restarts = 0u64;
    let ending = loop {
        if beat(&ports.heartbeat, &mut hb, 0).is_err() {
            break Ending::Transport;
        }
        let waited = wait_event(&ports.state_ready, period);
        // A signal interrupts the wait: SIGINT/SIGTERM end the loop cleanly.
        if termination_requested(&ports.node) {
            break Ending::Interrupted;
        }
        if waited.is_err() {
            break Ending::Transport;
        }
        let wall = monotonic_ns();
        let mut new_state = false;
        while let Ok(Some(sample)) = ports.state.receive() {
            let st = *sample.payload();
            states_received += 1;
            heard_wall = Some(wall);
            if latest.is_some_and(|l| st.seq < l.seq) {
                // A new vehicle process (its states count from 0 again): start over.
                vehicle_restarts += 1;
                lp.reset();
                latest = None;
                reference = None;
            }
            if latest.is_none_or(|l| st.seq > l.seq) {
                if st.flags & STATE_RESTARTED != 0 {
                    lp.reset();
                }
                latest = Some(st);
                latest_wall = wall;
                new_state = true;
                if reference.is_none_or(|(v, _)| st.sent_ns >= v) {
                    reference = Some((st.sent_ns, st.wall_sent_ns));
                }
            }
        }
        if let Ok(Some(h)) = newest(&ports.vehicle_heartbeat) {
            last_hb_wall = Some(wall);
            heard_wall = Some(wall);
            if reference.is_none_or(|(v, _)| h.vehicle_ns >= v) {
                reference = Some((h.vehicle_ns, h.wall_sent_ns));
            }
        }
        match heard_wall {
            None if wall.saturating_sub(start_wall) > connect_ns => break Ending::NoPeer,
            Some(t) if wall.saturating_sub(t) > lost_ns => break Ending::PeerLost,
            _ => {}
        }
        // Nothing to answer before the first state (a command now would be stale or a
        // safe-stop request by the time the vehicle's clock starts).
        let (Some((ref_vehicle, ref_wall)), true) = (reference, latest.is_some()) else {
            continue;
        };
        let now_ns = match s.clock {
            ControllerClock::Vehicle => ref_vehicle,
            ControllerClock::Wall => ref_vehicle + wall.saturating_sub(ref_wall),
        };
        let peer_alive =
            last_hb_wall.is_some_and(|t| wall.saturating_sub(t) <= peer_timeout_ns) || new_state;
        let stale = latest.is_none_or(|l| now_ns.saturating_sub(l.stamp_ns) > stale_ns);
        // Answer each new state once; without one, speak only to fall back.
        if !(new_state || stale || !peer_alive) {
            continue;
        }
        let (mut cmd, status) = lp.step(&CycleInput {
            state: latest.as_ref(),
            now_ns,
            wall_received_ns: latest_wall,
            peer_alive,
        });
        cmd.wall_sent_ns = monotonic_ns();
        let sent = publish(&ports.command, cmd)
            .and_then(|()| publish(&ports.status, status))
            .and_then(|()| {
                ports
                    .command_ready
                    .notify()
                    .map(|_| ())
                    .map_err(|_| IoFault::Notify)
            });
        if sent.is_err() {
            break Ending::Transport;
        }
        if new_state && cycle_ms.len() < max_cycles {
            cycle_ms.push(cmd.wall_sent_ns.saturating_sub(latest_wall) as f64 * 1e-6);
            if status.plan_ns > 0 {
                plan_ms.push(status.plan_ns as f64 * 1e-6);
            }
        }
        if s.exit_when_finished && latest.is_some_and(|l| l.flags & STATE_FINISHED != 0) {
            break Ending::Finished;
        }
    };
    let (peak, rss) = resident_kib();
    ControllerSummary {
        ending,
        counters: lp.counters(),
        states_received,
        vehicle_restarts,
        cycle_ms: Stats::of(&mut cycle_ms),
        plan_ms: Stats::of(&mut plan_ms),
        peak_rss_kib: peak,
        rss_kib: rss,
    }
}

/// The vehicle's safe stop, as it happened.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct SafeStopReport {
    pub reason: SafeStopReason,
    /// Vehicle time of the latch (s).
    pub at: f64,
    /// Vehicle time the bullet came to rest (< 0.1 m/s), if it did (s).
    pub stopped_at: Option<f64>,
    /// Bullet speed at the latch (m/s).
    pub speed_at_latch: f64,
    /// Vehicle time the latch was released by fresh commands, if it was (s).
    pub resumed_at: Option<f64>,
}

/// What the vehicle side did.
#[derive(Debug, Clone, Serialize)]
pub struct VehicleSummary {
    pub ending: Ending,
    /// Vehicle time at the end (s).
    pub time: f64,
    pub periods: u64,
    pub states_published: u64,
    pub states_dropped: u64,
    pub commands_received: u64,
    pub commands_applied: u64,
    pub commands_stale: u64,
    /// Simulated clock: periods whose answer did not come within `lockstep_timeout`.
    pub lockstep_misses: u64,
    /// Soak: scenario restarts.
    pub restarts: u64,
    /// The most recent safe stop (none if it never latched).
    pub safe_stop: Option<SafeStopReport>,
    /// Safe stops latched, and how many a controller that came back released.
    pub safe_stops: u64,
    pub resumes: u64,
    /// The largest delay of a command-timeout latch past its deadline (ms, vehicle clock).
    pub safe_stop_late_max_ms: f64,
    /// Command sequence numbers that went back: new controller processes.
    pub controller_restarts: u64,
    pub final_bullet_speed: f64,
    /// IPC latency of a control cycle excluding the controller's own time: state publish →
    /// command receive, minus (command send − state receive) (µs).
    pub ipc_us: Stats,
    /// State transit (vehicle publish → controller receive) and command transit (µs).
    pub state_transit_us: Stats,
    pub command_transit_us: Stats,
    /// Wall time from state publish to the answering command, the solve included (ms).
    pub round_trip_ms: Stats,
    pub peak_rss_kib: u64,
}

/// Latency samples, preallocated.
struct Latencies {
    sent_wall: Vec<u64>,
    ipc: Vec<f64>,
    state: Vec<f64>,
    command: Vec<f64>,
    round: Vec<f64>,
}

const SENT_RING: usize = 256;
/// The most cycles whose latencies the vehicle keeps (4 × 8 MiB, preallocated).
pub const MAX_LATENCY_SAMPLES: usize = 1 << 20;

impl Latencies {
    fn new(n: usize) -> Self {
        Self {
            sent_wall: vec![0; SENT_RING],
            ipc: Vec::with_capacity(n),
            state: Vec::with_capacity(n),
            command: Vec::with_capacity(n),
            round: Vec::with_capacity(n),
        }
    }

    fn sent(&mut self, seq: u64, wall: u64) {
        self.sent_wall[(seq % SENT_RING as u64) as usize] = wall;
    }

    fn answered(&mut self, cmd: &ActuatorCommand, recv_wall: u64, newest_seq: u64) {
        if self.ipc.len() == self.ipc.capacity()
            || newest_seq.saturating_sub(cmd.state_seq) >= SENT_RING as u64
        {
            return;
        }
        let sent = self.sent_wall[(cmd.state_seq % SENT_RING as u64) as usize];
        if sent == 0
            || cmd.wall_state_received_ns < sent
            || cmd.wall_sent_ns < cmd.wall_state_received_ns
        {
            return;
        }
        let round = recv_wall.saturating_sub(sent) as f64;
        let solve = (cmd.wall_sent_ns - cmd.wall_state_received_ns) as f64;
        self.ipc.push((round - solve) * 1e-3);
        self.state
            .push((cmd.wall_state_received_ns - sent) as f64 * 1e-3);
        self.command
            .push(recv_wall.saturating_sub(cmd.wall_sent_ns) as f64 * 1e-3);
        self.round.push(round * 1e-6);
    }
}

/// The vehicle side's loop: publish the state every period, apply the newest valid
/// command, stop safely when commands stop and hand back to a controller that returns
/// ([`CommandGate`]); ends when the bridge says the run is over (and a latched safe stop
/// has brought the bullet to rest), at `max_time` seconds of vehicle time (both publish a
/// last state flagged finished, so the controller ends too), on SIGINT/SIGTERM, or when no
/// controller shows up within `connect_timeout` ([`Ending::NoPeer`]).
///
/// On the wall clock the plant keeps to the wall clock: after a pause of this process it
/// catches up (as a real vehicle's time would have passed), and the command timeout is
/// judged at every 5 ms sub-tick of that catch-up.
pub fn run_vehicle<B: VehicleBridge>(
    s: &VehicleIoSettings,
    bridge: &mut B,
    ports: &VehiclePorts,
    max_time: f64,
) -> VehicleSummary {
    let period_ns = secs_to_ns(s.period);
    let step_ns = bridge.step_ns().max(1);
    let steps_per = (period_ns / step_ns).max(1) as usize;
    // Real time: apply commands on arrival, at the next 5 ms sub-tick.
    let sub_steps = ((5_000_000 / step_ns).max(1) as usize).min(steps_per);
    // Latency samples of at most `MAX_LATENCY_SAMPLES` cycles (a long soak keeps the first).
    let max_periods = ((max_time / s.period).ceil() as usize + 2).min(MAX_LATENCY_SAMPLES);
    let mut lat = Latencies::new(max_periods);
    let mut rng = ChaCha8Rng::seed_from_u64(s.seed ^ 0x5eed_fa17);
    let mut hb = heartbeat(PEER_VEHICLE);
    let mut summary = VehicleSummary {
        ending: Ending::Finished,
        time: 0.0,
        periods: 0,
        states_published: 0,
        states_dropped: 0,
        commands_received: 0,
        commands_applied: 0,
        commands_stale: 0,
        lockstep_misses: 0,
        restarts: 0,
        safe_stop: None,
        safe_stops: 0,
        resumes: 0,
        safe_stop_late_max_ms: 0.0,
        controller_restarts: 0,
        final_bullet_speed: 0.0,
        ipc_us: Stats::of(&mut []),
        state_transit_us: Stats::of(&mut []),
        command_transit_us: Stats::of(&mut []),
        round_trip_ms: Stats::of(&mut []),
        peak_rss_kib: 0,
    };

    // Wait for the controller.
    let connect_deadline = monotonic_ns() + secs_to_ns(s.connect_timeout);
    let connected = loop {
        let _ = beat(&ports.heartbeat, &mut hb, 0);
        if matches!(newest(&ports.controller_heartbeat), Ok(Some(_))) {
            break true;
        }
        if termination_requested(&ports.node) || monotonic_ns() > connect_deadline {
            break false;
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    if !connected {
        summary.ending = if termination_requested(&ports.node) {
            Ending::Interrupted
        } else {
            Ending::NoPeer
        };
        return summary;
    }

    let mut gate = CommandGate::new(
        secs_to_ns(s.command_timeout),
        s.resume_after,
        bridge.now_ns(),
    );
    // The latch the summary's `safe_stop` describes, as (reason, vehicle ns).
    let mut report_latch: Option<(SafeStopReason, u64)> = None;
    let mut stopped_at: Option<f64> = None;
    let wall0 = monotonic_ns();
    let mut seq = 0u64;
    let stall = (
        secs_to_ns(s.faults.stall_at),
        secs_to_ns(s.faults.stall_at + s.faults.stall_for),
    );
    let mut finished = false;
    let mut time_up = false;
    let mut restarted = false;
    // Lock step: whether the controller answered lately (while latched, the vehicle waits
    // for answers only from a controller that is answering).
    let mut answering = true;
    summary.restarts = 0;
    summary.ending = loop {
        let now = bridge.now_ns();
        let mut st = StateEstimate::default();
        bridge.measure(&mut st);
        st.seq = seq;
        st.sent_ns = now;
        st.flags |= gate.flags();
        st.commands_applied = u32::try_from(gate.applied).unwrap_or(u32::MAX);
        let stalled = s.faults.stall_for > 0.0 && now >= stall.0 && now < stall.1;
        let dropped =
            stalled || (s.faults.drop_states > 0.0 && rng.random::<f64>() < s.faults.drop_states);
        if finished {
            st.flags |= STATE_FINISHED;
        }
        if restarted {
            st.flags |= STATE_RESTARTED;
            restarted = false;
        }
        if dropped && !finished {
            summary.states_dropped += 1;
        } else {
            st.wall_sent_ns = monotonic_ns();
            lat.sent(seq, st.wall_sent_ns);
            if publish(&ports.state, st).is_err() {
                break Ending::Transport;
            }
            gate.published(seq);
            summary.states_published += 1;
        }
        let _ = beat(&ports.heartbeat, &mut hb, now);
        let _ = ports.state_ready.notify();
        if finished {
            break if time_up {
                Ending::TimeLimit
            } else {
                Ending::Finished
            };
        }

        match s.clock {
            VehicleClock::Simulated => {
                // Wait for the answer to this state; after a dropped state, for whatever the
                // controller says (it speaks when the newest state it has goes stale).
                let waiting = gate.latched().is_none() || answering;
                let deadline = monotonic_ns() + secs_to_ns(s.lockstep_timeout);
                let (mut answered, mut any) = drain(ports, bridge, &mut gate, &mut lat, seq);
                while waiting && !(answered || (dropped && any)) {
                    let now_wall = monotonic_ns();
                    if now_wall >= deadline || termination_requested(&ports.node) {
                        break;
                    }
                    let _ = wait_event(
                        &ports.command_ready,
                        Duration::from_nanos(deadline - now_wall),
                    );
                    let (a, n) = drain(ports, bridge, &mut gate, &mut lat, seq);
                    answered |= a;
                    any |= n;
                }
                answering = answered || any;
                if waiting && !dropped && !answered {
                    summary.lockstep_misses += 1;
                }
                apply(bridge, gate.decide(bridge.now_ns()));
                bridge.step(steps_per);
            }
            VehicleClock::Wall => {
                let mut done = 0;
                while done < steps_per {
                    let n = sub_steps.min(steps_per - done);
                    let tick_end = wall0 + seq * period_ns + (done + n) as u64 * step_ns;
                    loop {
                        let _ = drain(ports, bridge, &mut gate, &mut lat, seq);
                        let w = monotonic_ns();
                        if w >= tick_end || termination_requested(&ports.node) {
                            break;
                        }
                        let _ =
                            wait_event(&ports.command_ready, Duration::from_nanos(tick_end - w));
                    }
                    apply(bridge, gate.decide(bridge.now_ns()));
                    bridge.step(n);
                    done += n;
                }
            }
        }
        let over = bridge.end_period();
        seq += 1;
        summary.periods += 1;
        if s.soak_periods >= 10 && summary.periods % (s.soak_periods / 10) == 0 {
            eprintln!(
                "pit-vehicle: soak {} / {} periods ({} runs), {} lock-step misses, {} safe stops ({} resumed)",
                summary.periods,
                s.soak_periods,
                summary.restarts + 1,
                summary.lockstep_misses,
                gate.latches,
                gate.resumes
            );
        }
        let t = bridge.now_ns() as f64 * 1e-9;
        match (gate.latched(), report_latch) {
            // A new latch (also one that followed a resume within this period).
            (Some(l), prev) if prev.is_none_or(|p| p.0 == l.0 && p.1 != l.1) => {
                summary.safe_stop = Some(SafeStopReport {
                    reason: l.0,
                    at: l.1 as f64 * 1e-9,
                    stopped_at: None,
                    speed_at_latch: bridge.bullet_speed(),
                    resumed_at: None,
                });
                stopped_at = None;
                report_latch = Some(l);
            }
            // The controller asked for the stop while the vehicle already stopped itself.
            (Some(l), Some(p)) if p != l => {
                if let Some(r) = summary.safe_stop.as_mut() {
                    r.reason = l.0;
                }
                report_latch = Some(l);
            }
            (None, Some(_)) => {
                if let Some(r) = summary.safe_stop.as_mut() {
                    r.resumed_at = Some(t);
                }
                report_latch = None;
                stopped_at = None;
            }
            _ => {}
        }
        if gate.latched().is_some() && stopped_at.is_none() && bridge.bullet_speed() < 0.1 {
            stopped_at = Some(t);
            if let Some(r) = summary.safe_stop.as_mut() {
                r.stopped_at = stopped_at;
            }
        }
        if termination_requested(&ports.node) {
            break Ending::Interrupted;
        }
        // Over when judged, but a vehicle stopping itself comes to rest first.
        if over && (gate.latched().is_none() || stopped_at.is_some()) {
            if summary.periods < s.soak_periods && bridge.restart() {
                summary.restarts += 1;
                restarted = true;
                gate.restart(bridge.now_ns());
                report_latch = None;
                stopped_at = None;
                continue;
            }
            finished = true;
            continue;
        }
        if t >= max_time {
            // The last state says so: the controller ends with the run.
            time_up = true;
            finished = true;
        }
    };
    summary.safe_stops = gate.latches;
    summary.resumes = gate.resumes;
    summary.safe_stop_late_max_ms = gate.latch_late_max_ns as f64 * 1e-6;
    summary.controller_restarts = gate.controller_restarts;
    summary.time = bridge.now_ns() as f64 * 1e-9;
    summary.commands_received = gate.received;
    summary.commands_applied = gate.applied;
    summary.commands_stale = gate.stale;
    summary.final_bullet_speed = bridge.bullet_speed();
    summary.ipc_us = Stats::of(&mut lat.ipc);
    summary.state_transit_us = Stats::of(&mut lat.state);
    summary.command_transit_us = Stats::of(&mut lat.command);
    summary.round_trip_ms = Stats::of(&mut lat.round);
    summary.peak_rss_kib = resident_kib().0;
    summary
}

/// Receive every pending status (its events go to the bridge) and command (offered to the
/// gate); returns whether a command answered state `seq` (or a newer one), and whether any
/// command came.
fn drain<B: VehicleBridge>(
    ports: &VehiclePorts,
    bridge: &mut B,
    gate: &mut CommandGate,
    lat: &mut Latencies,
    seq: u64,
) -> (bool, bool) {
    let now_ns = bridge.now_ns();
    while let Ok(Some(sample)) = ports.status.receive() {
        bridge.controller_events(sample.payload().events);
    }
    let (mut answered, mut any) = (false, false);
    while let Ok(Some(sample)) = ports.command.receive() {
        let cmd = *sample.payload();
        if cmd.state_seq == seq {
            // The latency of the cycle that answered the newest state (a fallback after a
            // stall answers an old one: its "latency" is the stall).
            lat.answered(&cmd, monotonic_ns(), seq);
        }
        answered |= cmd.state_seq >= seq;
        any = true;
        gate.offer(&cmd, now_ns);
    }
    (answered, any)
}

fn apply<B: VehicleBridge>(bridge: &mut B, a: Actuation) {
    match a {
        Actuation::Command([steer, torque]) => bridge.actuate(steer, torque),
        Actuation::Hold => {}
        Actuation::SafeStop => bridge.safe_stop(),
    }
}
