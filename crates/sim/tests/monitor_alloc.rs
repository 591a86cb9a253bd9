//! The monitor's per-step work (latch after every plant step, observe every control step)
//! allocates nothing once built.

mod common;

use alloc_count::{allocations, CountingAlloc};
use dynamics::plant::{Plant, PlantConfig};
use sim::outcome::Monitor;
use sim::scenario::Scenario;

#[global_allocator]
static GLOBAL: CountingAlloc = CountingAlloc;

#[test]
fn monitor_steps_allocate_nothing() {
    let sc = Scenario::from_json_line(&common::curved().to_string(), 1).unwrap();
    let params = sc.params.load().unwrap();
    let road = sc.build_road().unwrap();
    let mut plant = Plant::new(
        &params,
        PlantConfig {
            mu: sc.mu,
            ..PlantConfig::default()
        },
    )
    .unwrap();
    plant.set_obstacles(sc.obstacles());
    let (b, t) = sc.initial_states(&road);
    plant.reset(&b, &t);
    let mut monitor = Monitor::for_scenario(&sc).unwrap();
    let mut driver = sc.target_driver(&params);
    let before = allocations();
    for k in 0..100 {
        let x = plant.target_state();
        let (d, tb) = driver.command(k as f64 * 0.05, None, &x, &road);
        plant.set_target_command(d, tb);
        // The bullet steers toward the target so that contact is exercised.
        plant.set_bullet_command(-0.05, 200.0);
        for _ in 0..50 {
            plant.step();
            monitor.latch(&plant);
        }
        monitor.observe_plant(&plant);
    }
    let after = allocations();
    assert_eq!(after - before, 0, "allocations in the monitored loop");
    assert!(monitor.metrics().observations > 0);
}
