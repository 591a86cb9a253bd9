//! IPC round trip without a solve: publish a state and notify, an echo thread (its own
//! iceoryx2 node, as the controller would be) wakes on the event, takes the newest state and
//! answers with a command and a notification; the bench waits for that answer. This is the
//! transport's share of a control cycle (docs/BENCHMARKS.md, "Vehicle I/O").

use criterion::{criterion_group, criterion_main, Criterion};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;
use vehicle_io::msg::{ActuatorCommand, StateEstimate};
use vehicle_io::ports::{newest, publish, wait_event, ControllerPorts, ServiceNames, VehiclePorts};

fn roundtrip(c: &mut Criterion) {
    let names = ServiceNames::new(&format!("picopit-bench-ipc-{}", std::process::id())).unwrap();
    let vp = VehiclePorts::open(&names).unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let (ready_tx, ready_rx) = std::sync::mpsc::channel();
    let echo = {
        let names = names.clone();
        let stop = Arc::clone(&stop);
        std::thread::spawn(move || {
            let cp = ControllerPorts::open(&names).unwrap();
            ready_tx.send(()).unwrap();
            while !stop.load(Ordering::Relaxed) {
                if !wait_event(&cp.state_ready, Duration::from_millis(20)).unwrap() {
                    continue;
                }
                if let Some(st) = newest(&cp.state).unwrap() {
                    let cmd = ActuatorCommand {
                        seq: st.seq,
                        state_seq: st.seq,
                        ..ActuatorCommand::default()
                    };
                    publish(&cp.command, cmd).unwrap();
                    cp.command_ready.notify().unwrap();
                }
            }
        })
    };
    ready_rx.recv().unwrap();
    let mut seq = 0u64;
    let mut round = || {
        seq += 1;
        publish(
            &vp.state,
            StateEstimate {
                seq,
                ..StateEstimate::default()
            },
        )
        .unwrap();
        vp.state_ready.notify().unwrap();
        loop {
            let _ = wait_event(&vp.command_ready, Duration::from_millis(100)).unwrap();
            if newest(&vp.command)
                .unwrap()
                .is_some_and(|c| c.state_seq == seq)
            {
                break;
            }
        }
    };
    // Let the echo thread connect (the first samples may precede its subscription).
    for _ in 0..10 {
        round();
    }
    let mut group = c.benchmark_group("ipc");
    group.bench_function("state_to_command", |b| b.iter(&mut round));
    group.finish();
    stop.store(true, Ordering::Relaxed);
    echo.join().unwrap();
}

criterion_group!(benches, roundtrip);
criterion_main!(benches);
