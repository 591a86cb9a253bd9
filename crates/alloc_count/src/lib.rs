//! A counting global allocator for the tests that prove a hot path allocates nothing after
//! construction (the plant step, the models, the MPC and controller steps, the success test,
//! the vehicle I/O cycle).
//!
//! A test binary installs it and reads the count of its own thread around the code under
//! test:
//!
//! ```
//! use alloc_count::{allocations, CountingAlloc};
//!
//! #[global_allocator]
//! static GLOBAL: CountingAlloc = CountingAlloc;
//!
//! fn hot_path(buf: &mut [f64]) {
//!     buf.iter_mut().for_each(|x| *x *= 2.0);
//! }
//!
//! let mut buf = vec![1.0; 16]; // set-up may allocate
//! let before = allocations();
//! hot_path(&mut buf);
//! assert_eq!(allocations() - before, 0);
//! ```
//!
//! Allocations and reallocations are counted (a `Vec` growing in place is still a call into
//! the allocator); frees are not. The counter is thread-local, so the test harness's other
//! threads do not disturb it.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

/// Defers to the system allocator and counts calls per thread.
pub struct CountingAlloc;

thread_local! {
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

fn count() {
    ALLOCATIONS.with(|c| c.set(c.get() + 1));
}

// SAFETY: defers every call to the system allocator; only adds a thread-local counter (a
// `const`-initialised `Cell`, which does not allocate).
unsafe impl GlobalAlloc for CountingAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        count();
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

/// Allocations (and reallocations) made so far on this thread, when [`CountingAlloc`] is the
/// global allocator; always 0 otherwise.
#[must_use]
pub fn allocations() -> usize {
    ALLOCATIONS.with(Cell::get)
}
