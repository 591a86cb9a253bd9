//! The counter sees allocations, zeroed allocations and reallocations of its own thread.

use alloc_count::{allocations, CountingAlloc};

#[global_allocator]
static GLOBAL: CountingAlloc = CountingAlloc;

#[test]
fn counts_allocations_and_growth_but_not_plain_arithmetic() {
    let before = allocations();
    let x: u64 = (1..100u64).sum();
    assert_eq!(allocations(), before, "{x}");
    let mut v: Vec<u8> = Vec::with_capacity(1);
    assert_eq!(allocations(), before + 1);
    v.extend_from_slice(&[0; 64]); // grows: a reallocation
    assert_eq!(allocations(), before + 2);
    let z = vec![0u64; 1000]; // alloc_zeroed
    assert_eq!(allocations(), before + 3);
    drop((v, z));
    assert_eq!(allocations(), before + 3, "frees are not counted");
    // Another thread counts its own allocations, and they do not reach this thread's
    // count: it allocates 100 times between two barriers while this thread waits.
    let barrier = std::sync::Arc::new(std::sync::Barrier::new(2));
    let other = {
        let barrier = barrier.clone();
        std::thread::spawn(move || {
            barrier.wait();
            let b = allocations();
            for i in 0..100u8 {
                drop(vec![i; 10]);
            }
            let n = allocations() - b;
            barrier.wait();
            n
        })
    };
    barrier.wait();
    let here = allocations();
    barrier.wait();
    assert_eq!(
        allocations(),
        here,
        "the other thread's allocations are not counted here"
    );
    assert_eq!(other.join().unwrap(), 100);
}
