//! `ports::wait_event` never blocks for good: a timeout under a microsecond (the wall-clock
//! loops' last few hundred nanoseconds of a tick) returns, and a signal that interrupts the
//! wait (SIGCONT after a pause) is not a transport failure.
//!
//! Each wait runs on a thread of its own; a wait that hangs is reported after 20 s instead of
//! hanging the test.

use std::sync::mpsc;
use std::sync::Arc;
use std::time::Duration;
use vehicle_io::ports::{node, wait_event, IoFault, Svc};

fn listener(
    name: &str,
) -> (
    iceoryx2::node::Node<Svc>,
    iceoryx2::port::listener::Listener<Svc>,
) {
    use iceoryx2::prelude::*;
    let n = node("picopit-test-wait").unwrap();
    let sname: ServiceName = format!("picopit-test-wait-{}-{name}", std::process::id())
        .as_str()
        .try_into()
        .unwrap();
    let l = n
        .service_builder(&sname)
        .event()
        .open_or_create()
        .unwrap()
        .listener_builder()
        .create()
        .unwrap();
    (n, l)
}

/// Run `wait_event` with `timeout` on its own thread; its result, or `None` if it did not
/// return within 20 s. `poke` runs on this thread with the waiter's pthread id meanwhile.
fn bounded_wait(
    name: &'static str,
    timeout: Duration,
    poke: impl FnOnce(libc::pthread_t),
) -> Option<Result<bool, IoFault>> {
    let (tx, rx) = mpsc::channel();
    let (id_tx, id_rx) = mpsc::channel();
    let ready = Arc::new(std::sync::Barrier::new(2));
    let r2 = Arc::clone(&ready);
    std::thread::spawn(move || {
        let (_node, l) = listener(name);
        // SAFETY: pthread_self has no preconditions.
        id_tx.send(unsafe { libc::pthread_self() }).unwrap();
        r2.wait();
        let _ = tx.send(wait_event(&l, timeout));
    });
    let id = id_rx.recv().unwrap();
    ready.wait();
    poke(id);
    rx.recv_timeout(Duration::from_secs(20)).ok()
}

#[test]
fn a_wait_shorter_than_a_microsecond_returns() {
    for ns in [0, 1, 500, 999] {
        let r = bounded_wait("short", Duration::from_nanos(ns), |_| {});
        assert_eq!(r, Some(Ok(false)), "wait_event({ns} ns) blocked or failed");
    }
}

extern "C" fn on_usr1(_: libc::c_int) {}

#[test]
fn a_signal_during_the_wait_is_not_a_failure() {
    // A handler without SA_RESTART: the signal interrupts the waiter's recvfrom with EINTR,
    // as SIGCONT does after SIGSTOP.
    // SAFETY: installing a handler that does nothing, with a zeroed, then filled sigaction.
    unsafe {
        let mut sa: libc::sigaction = std::mem::zeroed();
        sa.sa_sigaction = on_usr1 as *const () as usize;
        libc::sigemptyset(&mut sa.sa_mask);
        sa.sa_flags = 0;
        assert_eq!(libc::sigaction(libc::SIGUSR1, &sa, std::ptr::null_mut()), 0);
    }
    let r = bounded_wait("eintr", Duration::from_secs(5), |id| {
        // Let the waiter enter its wait, then interrupt it.
        std::thread::sleep(Duration::from_millis(300));
        // SAFETY: `id` is a live thread of this process (it waits for 5 s).
        assert_eq!(unsafe { libc::pthread_kill(id, libc::SIGUSR1) }, 0);
    });
    assert_eq!(
        r,
        Some(Ok(false)),
        "an interrupted wait must return Ok(false)"
    );
}
