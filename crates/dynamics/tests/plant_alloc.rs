//! The plant's step allocates nothing once built (it runs inside the 1 kHz loop of
//! pit-vehicle and millions of times per benchmark).

use alloc_count::{allocations, CountingAlloc};
use dynamics::params::ParamSet;
use dynamics::plant::{Plant, PlantConfig, VehicleInit};
use dynamics::road::Obstacle;

#[global_allocator]
static GLOBAL: CountingAlloc = CountingAlloc;

#[test]
fn plant_step_allocates_nothing() {
    let set = ParamSet::builtin("full_size").unwrap();
    let mut p = Plant::new(&set, PlantConfig::default()).unwrap();
    // A parked car ahead so that obstacle contact is exercised too.
    p.set_obstacles(vec![Obstacle {
        x: 40.0,
        y: 0.0,
        heading: 0.0,
        vx: 0.0,
        vy: 0.0,
        length: 4.5,
        width: 1.8,
    }]);
    p.reset(
        &VehicleInit {
            x: -3.9,
            y: -2.4,
            yaw: 20f64.to_radians(),
            vx: 19.0,
            ..Default::default()
        },
        &VehicleInit {
            vx: 15.0,
            ..Default::default()
        },
    );
    let before = allocations();
    let mut touched = (false, false);
    for k in 0..6000 {
        if k == 3000 {
            // Second act: the target drives into the parked car.
            p.reset(
                &VehicleInit {
                    x: -50.0,
                    y: 10.0,
                    ..Default::default()
                },
                &VehicleInit {
                    x: 20.0,
                    vx: 10.0,
                    ..Default::default()
                },
            );
        }
        p.set_bullet_command(if k < 500 { 0.08 } else { 0.0 }, 300.0);
        p.step();
        touched.0 |= p.contact().is_some();
        touched.1 |= p.obstacle_contacts().iter().any(Option::is_some);
        let _ = p.take_contact_average();
    }
    let after = allocations();
    assert!(touched.0, "the vehicles must touch");
    assert!(touched.1, "a vehicle must hit the parked car");
    assert_eq!(after - before, 0, "Plant::step allocated");
}
