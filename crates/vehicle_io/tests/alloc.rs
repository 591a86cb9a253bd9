//! The controller's cycle allocates nothing after construction: the watchdog, the delay
//! compensation, the hierarchical controller (replans included) and the fallback. The
//! iceoryx2 receive → publish → notify around it is counted too: iceoryx2 0.10's publisher
//! allocates once per sent sample, inside the library (docs/vehicle_io.md). The counting
//! allocator counts this thread only, so the recorder threads of other tests do not count.

use alloc_count::{allocations, CountingAlloc};
use dynamics::TargetModel;
use vehicle_io::config::ControllerIoSettings;
use vehicle_io::control::{ControlLoop, CycleInput};
use vehicle_io::msg::StateEstimate;
use vehicle_io::ports::{newest, publish, ControllerPorts, ServiceNames, VehiclePorts};

#[global_allocator]
static GLOBAL: CountingAlloc = CountingAlloc;

#[test]
fn the_control_cycle_and_its_ipc_allocate_nothing() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let sc =
        vehicle_io::cli::load_scenario(&root.join("data/trials/half_scale.jsonl"), "R1").unwrap();
    let params = sc.params.load().unwrap();
    let mut s = ControllerIoSettings {
        deadline: 60.0,
        ..ControllerIoSettings::default()
    };
    s.controller = planner::ControllerSettings::from_toml_str(
        &std::fs::read_to_string(root.join("configs/controller_half_scale.toml")).unwrap(),
    )
    .unwrap();
    s.controller.mpc.time_budget = 10.0;
    s.controller.mpc.qp.time_limit = 10.0;
    s.controller.planner.qp.time_limit = 10.0;
    let dt = s.controller.mpc.dt;
    let model = || -> Box<dyn TargetModel + Send + Sync> {
        Box::new(dynamics::target4dof::FourDofTarget::new(
            &params.target,
            sc.mu,
            dt,
        ))
    };
    let ctl = planner::PitController::new(&params, sc.mu, model(), model(), s.controller.clone())
        .unwrap();
    let road = sc.build_road().unwrap();
    let mut lp = ControlLoop::new(s, ctl, &params, sc.mu, road, sc.obstacles());

    let names = ServiceNames::new(&format!("picopit-test-alloc-{}", std::process::id())).unwrap();
    let vp = VehiclePorts::open(&names).unwrap();
    let cp = ControllerPorts::open(&names).unwrap();

    // The plant in process, with noise and a latency (so the compensation predicts).
    let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(1);
    let u = sim::Uncertainty {
        position_std: 0.01,
        yaw_rate_std: 0.002,
        latency: 0.03,
        ..sim::Uncertainty::default()
    };
    let mut car = sim::vehicle::SimVehicle::new(&sc, u, dt, &mut rng).unwrap();

    let (mut in_step, mut in_ipc) = (0usize, 0usize);
    let mut cycles = 0usize;
    let mut contact = false;
    for k in 0..120u64 {
        let sensed = car.sense(&mut rng);
        let now = (car.time() * 1e9).round() as u64;
        let st = StateEstimate {
            seq: k,
            stamp_ns: now.saturating_sub((sensed.age * 1e9).round() as u64),
            sent_ns: now,
            target: sensed.target.as_slice().try_into().unwrap(),
            bullet: sensed.bullet,
            target_input: sensed.target_input,
            bullet_applied: car.applied(),
            ..StateEstimate::default()
        };
        publish(&vp.state, st).unwrap();
        vp.state_ready.notify().unwrap();

        // The controller's side of one cycle, counted (after a warm-up that lets the ports
        // and the controller settle): receive, the cycle, publish command and status, notify.
        let a0 = allocations();
        let got = newest(&cp.state).unwrap().expect("the state arrived");
        let a1 = allocations();
        // Every 20th cycle pretends the state is old: the stale fallback path.
        let now_ns = if k % 20 == 19 {
            now + 1_000_000_000
        } else {
            now
        };
        let (cmd, status) = lp.step(&CycleInput {
            state: Some(&got),
            now_ns,
            wall_received_ns: 1,
            peer_alive: true,
        });
        let a2 = allocations();
        publish(&cp.command, cmd).unwrap();
        publish(&cp.status, status).unwrap();
        cp.command_ready.notify().unwrap();
        let a3 = allocations();
        if k >= 5 {
            in_step += a2 - a1;
            in_ipc += (a1 - a0) + (a3 - a2);
            cycles += 1;
        }

        let applied = newest(&vp.command).unwrap().expect("the command arrived");
        car.actuate([applied.steer, applied.torque]);
        car.advance();
        contact |= car.plant().contact().is_some();
    }
    assert!(
        contact,
        "the run reached the contact (replans and PIT phase exercised)"
    );
    assert!(lp.counters().stale_states >= 5 && lp.counters().solves > 100);
    assert_eq!(
        in_step, 0,
        "{in_step} allocations in {cycles} control cycles"
    );
    // iceoryx2 0.10's publisher makes one small heap allocation per sent sample (inside the
    // library; receive and notify make none): pinned here so that a change shows.
    assert!(
        in_ipc <= 2 * cycles,
        "{in_ipc} allocations in the IPC of {cycles} cycles"
    );
    eprintln!(
        "IPC allocations per cycle: {:.2}",
        in_ipc as f64 / cycles as f64
    );
}
