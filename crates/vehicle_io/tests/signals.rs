//! SIGTERM is not lost to a signal that follows it. iceoryx2 records only the last signal a
//! process received, in one slot; a SIGCONT right after a SIGTERM (`systemctl stop` sends
//! them so, and a soak's pause can end just before a stop) used to erase the request, and
//! the process ran on. Its own test binary: the request, once seen, holds for the process.

use vehicle_io::ports::{node, termination_requested};

#[test]
fn a_sigterm_followed_by_a_sigcont_still_ends_the_process() {
    let n = node("signals-test").expect("an iceoryx2 node");
    assert!(!termination_requested(&n), "no signal yet");
    // SIGCONT alone (the end of a pause) is no request to stop.
    // SAFETY: raising a signal this process handles.
    assert_eq!(unsafe { libc::raise(libc::SIGCONT) }, 0);
    assert!(!termination_requested(&n), "SIGCONT is not a stop");
    // SAFETY: as above; the process catches SIGTERM (it would die here otherwise).
    unsafe {
        assert_eq!(libc::raise(libc::SIGTERM), 0);
        assert_eq!(libc::raise(libc::SIGCONT), 0);
    }
    assert!(
        termination_requested(&n),
        "the SIGTERM was lost to the SIGCONT after it"
    );
    assert!(termination_requested(&n), "and it stays seen");
}
