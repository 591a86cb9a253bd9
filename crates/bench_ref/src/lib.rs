//! The reference workload of picopit's benchmark gate.
//!
//! Every bench binary measures the workload before and after its own benches, as
//! `reference/<binary>` and `reference/<binary>_end`. `scripts/bench_gate.py` judges each
//! bench by the ratio of its median to the slower of the two: a machine that is slower, or
//! busy with another tenant for the length of the binary's run, slows both, and the ratio
//! keeps what the code costs.
//!
//! The workload is the kind of arithmetic the product spends its time on, and never changes
//! with it: libm transcendentals (the tyre curves), a dense matrix-vector product (the
//! surrogates' layers) and a short dependent chain (a factorisation's recurrences). It
//! touches 34 KiB, inside L1/L2 on every machine the project runs on.

use criterion::Criterion;
use std::hint::black_box;

/// Length of the state vector and side of the square matrix.
const N: usize = 64;

/// The workload's memory: a state vector and a fixed matrix, built once.
pub struct Workload {
    x: [f64; N],
    a: Vec<f64>,
    y: [f64; N],
}

impl Default for Workload {
    fn default() -> Self {
        Self::new()
    }
}

impl Workload {
    /// The fixed data: a deterministic pattern, the same on every machine.
    #[must_use]
    pub fn new() -> Self {
        let mut x = [0.0; N];
        for (i, v) in x.iter_mut().enumerate() {
            *v = 0.1 + 0.01 * i as f64;
        }
        let a = (0..N * N)
            .map(|k| ((k * 7919) % 1000) as f64 / 1000.0 - 0.5)
            .map(|v| v / N as f64)
            .collect();
        Self { x, a, y: [0.0; N] }
    }

    /// One pass; returns a checksum so that nothing is optimised away. The state stays
    /// bounded (every entry in [−1, 1]) however often it is called.
    pub fn run(&mut self) -> f64 {
        for v in &mut self.x {
            *v = (1.9 * (1.3 * *v).atan()).sin();
        }
        for (row, y) in self.a.chunks_exact(N).zip(self.y.iter_mut()) {
            *y = row.iter().zip(&self.x).map(|(a, x)| a * x).sum::<f64>();
        }
        let mut chain = 0.0;
        for (x, y) in self.x.iter_mut().zip(&self.y) {
            chain = 0.5 * chain + y;
            *x = (0.9 * *x + 0.1 * chain).clamp(-1.0, 1.0);
        }
        chain
    }
}

/// Where in a bench binary's run the reference is measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum At {
    /// Before the binary's own benches: `reference/<binary>`.
    Start,
    /// After them: `reference/<binary>_end`.
    End,
}

/// Registers the reference with `c`: call it first and last in each bench binary's group.
pub fn bench(c: &mut Criterion, binary: &str, at: At) {
    let id = match at {
        At::Start => binary.to_string(),
        At::End => format!("{binary}_end"),
    };
    let mut w = Workload::new();
    let mut group = c.benchmark_group("reference");
    group.bench_function(id, |b| b.iter(|| black_box(w.run())));
    group.finish();
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_workload_is_deterministic_and_bounded() {
        let (mut a, mut b) = (Workload::new(), Workload::new());
        let mut last = 0.0;
        for _ in 0..10_000 {
            last = a.run();
            assert_eq!(last, b.run());
        }
        assert!(last.is_finite());
        assert!(a.x.iter().all(|v| (-1.0..=1.0).contains(v)));
    }
}
