//! A QP with a fixed sparsity pattern, assembled in place and solved by Clarabel.
//!
//! The MPC writes its matrices through an [`Emitter`]: the same code path runs once at
//! construction in *pattern* mode (collecting `(row, col)` pairs, from which the CSC
//! structure is built) and then at every update in *values* mode (writing each value into
//! the slot its pair was given). The pattern can therefore never drift from the values, and
//! an entry that is zero today stays a structural entry: Clarabel is built with presolve off
//! and without dropping zeros, so `update_P` / `update_A` reuse its symbolic factorisation.

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultInfo, DefaultSettings, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

/// The root timer under which every solve of ours runs (see [`Qp::solve`]).
const OUTER_TIMER: &str = "picopit";

/// Writes matrix entries, either recording the pattern or filling values.
pub struct Emitter<'a> {
    mode: Mode<'a>,
    /// Keep only the upper triangle (for P).
    upper: bool,
}

enum Mode<'a> {
    Pattern(&'a mut Vec<(usize, usize)>),
    Values {
        slots: &'a [usize],
        nzval: &'a mut [f64],
        next: usize,
    },
}

impl<'a> Emitter<'a> {
    pub fn pattern(pairs: &'a mut Vec<(usize, usize)>, upper: bool) -> Self {
        pairs.clear();
        Self {
            mode: Mode::Pattern(pairs),
            upper,
        }
    }

    pub fn values(slots: &'a [usize], nzval: &'a mut [f64], upper: bool) -> Self {
        nzval.fill(0.0);
        Self {
            mode: Mode::Values {
                slots,
                nzval,
                next: 0,
            },
            upper,
        }
    }

    /// Add `v` at `(r, c)` (values at the same place accumulate). For an upper-triangular
    /// matrix, an entry below the diagonal goes to its mirror.
    #[inline]
    pub fn put(&mut self, r: usize, c: usize, v: f64) {
        let (r, c) = if self.upper && r > c { (c, r) } else { (r, c) };
        match &mut self.mode {
            Mode::Pattern(pairs) => pairs.push((r, c)),
            Mode::Values { slots, nzval, next } => {
                nzval[slots[*next]] += v;
                *next += 1;
            }
        }
    }

    /// Number of entries written in values mode; panics (a bug) if the pattern differs.
    pub fn finish(self) {
        if let Mode::Values { slots, next, .. } = self.mode {
            assert_eq!(next, slots.len(), "QP assembly wrote a different pattern");
        }
    }
}

/// A CSC structure built from `(row, col)` pairs, with the slot of every pair.
pub struct Pattern {
    pub matrix: CscMatrix<f64>,
    /// `slots[i]` is the index into `nzval` of the i-th emitted pair.
    pub slots: Vec<usize>,
}

impl Pattern {
    pub fn build(m: usize, n: usize, pairs: &[(usize, usize)]) -> Self {
        let mut order: Vec<usize> = (0..pairs.len()).collect();
        order.sort_by_key(|&i| (pairs[i].1, pairs[i].0));
        let mut colptr = vec![0usize; n + 1];
        let mut rowval = Vec::with_capacity(pairs.len());
        let mut slots = vec![0usize; pairs.len()];
        let mut last: Option<(usize, usize)> = None;
        for &i in &order {
            let (r, c) = pairs[i];
            assert!(r < m && c < n, "QP entry ({r}, {c}) outside {m} x {n}");
            if last != Some((r, c)) {
                rowval.push(r);
                colptr[c + 1] += 1;
                last = Some((r, c));
            }
            slots[i] = rowval.len() - 1;
        }
        for c in 0..n {
            colptr[c + 1] += colptr[c];
        }
        let nnz = rowval.len();
        Self {
            matrix: CscMatrix::new(m, n, colptr, rowval, vec![0.0; nnz]),
            slots,
        }
    }
}

/// Outcome of one QP solve.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum QpStatus {
    Solved,
    /// Solved to Clarabel's reduced tolerances.
    AlmostSolved,
    MaxIterations,
    MaxTime,
    /// Infeasible, numerical error or lack of progress: the step is not usable.
    Failed,
}

impl QpStatus {
    fn from_clarabel(s: SolverStatus) -> Self {
        match s {
            SolverStatus::Solved => Self::Solved,
            SolverStatus::AlmostSolved => Self::AlmostSolved,
            SolverStatus::MaxIterations => Self::MaxIterations,
            SolverStatus::MaxTime | SolverStatus::CallbackTerminated => Self::MaxTime,
            _ => Self::Failed,
        }
    }

    /// Whether the primal solution may be used as a step.
    #[must_use]
    pub fn usable(self) -> bool {
        matches!(self, Self::Solved | Self::AlmostSolved)
    }
}

/// The Clarabel solver with its data, updated in place.
pub struct Qp {
    pub n: usize,
    pub m: usize,
    solver: DefaultSolver<f64>,
    /// With equilibration on, Clarabel's scaling is computed from the data it is built with
    /// and reused by every update; the solver is therefore rebuilt once, at the first solve,
    /// from real data (during the controller's warm-up), and never again.
    rebuild: Option<Rebuild>,
    pub p_slots: Vec<usize>,
    pub a_slots: Vec<usize>,
    pub p_val: Vec<f64>,
    pub a_val: Vec<f64>,
    pub q: Vec<f64>,
    pub b: Vec<f64>,
    /// The structure of P (upper triangle), for evaluating the objective.
    p_colptr: Vec<usize>,
    p_rowval: Vec<usize>,
    /// A point at which [`Qp::objective_at_z`] evaluates the objective.
    pub z: Vec<f64>,
    /// The per-solve time limit, enforced by a termination callback (see [`Qp::solve`]).
    deadline: Arc<Deadline>,
}

/// What the termination callback compares Clarabel's clock against: the solve stops once
/// `info.solve_time − start > limit` (both in seconds, stored as `f64` bits).
#[derive(Debug, Default)]
struct Deadline {
    start: AtomicU64,
    limit: AtomicU64,
}

impl Deadline {
    fn new(limit: f64) -> Arc<Self> {
        let d = Arc::new(Self::default());
        d.limit.store(limit.to_bits(), Ordering::Relaxed);
        d
    }

    fn expired(&self, info: &DefaultInfo<f64>) -> bool {
        let start = f64::from_bits(self.start.load(Ordering::Relaxed));
        let limit = f64::from_bits(self.limit.load(Ordering::Relaxed));
        info.solve_time - start > limit
    }
}

/// Install the time-limit callback on a freshly built solver.
fn arm(solver: &mut DefaultSolver<f64>, deadline: &Arc<Deadline>) {
    let d = Arc::clone(deadline);
    solver.set_termination_callback(move |info: &DefaultInfo<f64>| d.expired(info));
    prewarm_timers(solver);
}

/// Every timer name Clarabel 0.11.1 uses inside a solve (`timeit!` in its sources).
const CLARABEL_TIMERS: [&str; 11] = [
    "setup",
    "presolve",
    "equilibration",
    "kktinit",
    "solve",
    "default start",
    "IP iteration",
    "scale cones",
    "kkt update",
    "kkt solve",
    "post-process",
];

/// Create Clarabel's nested timer entries now, under our root timer, for every name at the
/// two levels below "solve": a solve that takes a path for the first time (a refinement, a
/// rarely used branch) then finds its timer and allocates nothing.
fn prewarm_timers(solver: &mut DefaultSolver<f64>) {
    if let Some(t) = solver.timers.as_mut() {
        t.start_as_current(OUTER_TIMER);
        t.start_as_current("solve");
        for a in CLARABEL_TIMERS {
            t.start_as_current(a);
            for b in CLARABEL_TIMERS {
                t.start_as_current(b);
                t.stop_current();
            }
            t.stop_current();
        }
        t.stop_current();
        t.stop_current();
    }
}

/// What rebuilding the solver from real data needs: P and A patterns, settings, cones.
type Rebuild = (
    CscMatrix<f64>,
    CscMatrix<f64>,
    DefaultSettings<f64>,
    Vec<SupportedConeT<f64>>,
);

/// Clarabel settings for the MPC's QPs. Clarabel's own `time_limit` stays infinite: the
/// limit `s.time_limit` is enforced per solve by [`Qp`]'s termination callback.
pub fn clarabel_settings(s: &crate::settings::QpSettings) -> DefaultSettings<f64> {
    DefaultSettings {
        max_iter: s.max_iter,
        time_limit: f64::INFINITY,
        verbose: false,
        tol_gap_abs: s.tol_gap,
        tol_gap_rel: s.tol_gap,
        tol_feas: s.tol_feas,
        tol_ktratio: 1e-5,
        equilibrate_enable: s.equilibrate,
        presolve_enable: false,
        input_sparse_dropzeros: false,
        direct_solve_method: "qdldl".to_owned(),
        iterative_refinement_enable: s.iterative_refinement,
        max_threads: 1,
        ..DefaultSettings::default()
    }
}

impl Qp {
    /// Build the solver from the patterns (values all zero but the diagonal of P, which
    /// Clarabel's regularisation makes harmless) and the cones: `n_eq` equality rows first,
    /// then nonnegative rows.
    pub fn new(
        p: Pattern,
        a: Pattern,
        n_eq: usize,
        settings: DefaultSettings<f64>,
        time_limit: f64,
    ) -> Result<Self, String> {
        let n = p.matrix.n;
        let m = a.matrix.m;
        let cones = [
            SupportedConeT::ZeroConeT(n_eq),
            SupportedConeT::NonnegativeConeT(m - n_eq),
        ];
        let q = vec![0.0; n];
        let b = vec![1.0; m];
        let p_val = p.matrix.nzval.clone();
        let p_colptr = p.matrix.colptr.clone();
        let p_rowval = p.matrix.rowval.clone();
        let a_val = a.matrix.nzval.clone();
        let rebuild = settings.equilibrate_enable.then(|| {
            (
                p.matrix.clone(),
                a.matrix.clone(),
                settings.clone(),
                cones.to_vec(),
            )
        });
        let mut solver = DefaultSolver::new(&p.matrix, &q, &a.matrix, &b, &cones, settings)
            .map_err(|e| e.to_string())?;
        if !solver.is_data_update_allowed() {
            return Err("Clarabel refuses in-place data updates".to_owned());
        }
        let deadline = Deadline::new(time_limit);
        arm(&mut solver, &deadline);
        Ok(Self {
            n,
            m,
            solver,
            rebuild,
            p_slots: p.slots,
            a_slots: a.slots,
            p_val,
            a_val,
            q,
            b,
            p_colptr,
            p_rowval,
            z: vec![0.0; n],
            deadline,
        })
    }

    /// Set the per-solve time limit (s).
    pub fn set_time_limit(&mut self, limit: f64) {
        self.deadline
            .limit
            .store(limit.to_bits(), Ordering::Relaxed);
    }

    /// Push the current values into the solver and solve (within the time limit given at
    /// construction).
    pub fn solve(&mut self) -> QpStatus {
        if let Some((mut p, mut a, settings, cones)) = self.rebuild.take() {
            p.nzval.copy_from_slice(&self.p_val);
            a.nzval.copy_from_slice(&self.a_val);
            match DefaultSolver::new(&p, &self.q, &a, &self.b, &cones, settings) {
                Ok(s) => {
                    self.solver = s;
                    arm(&mut self.solver, &self.deadline);
                }
                Err(_) => return QpStatus::Failed,
            }
        }
        let ok = self.solver.update_P(&self.p_val).is_ok()
            && self.solver.update_A(&self.a_val).is_ok()
            && self.solver.update_q(&self.q).is_ok()
            && self.solver.update_b(&self.b).is_ok();
        if !ok {
            return QpStatus::Failed;
        }
        // Clarabel's `Info::reset` resets its root "solve" timer, which clears the nested
        // timer maps and makes the next solve allocate them again (one `HashMap` per solve,
        // clarabel 0.11.1 `src/timers/timers.rs`). Running every solve under our own root
        // timer nests Clarabel's "solve" one level down, where the reset does not reach, so
        // the maps are built at the first solve and reused. The outer timer then accumulates
        // over all solves, and so does `info.solve_time`: the time limit is measured from the
        // value it has when this solve starts.
        if let Some(t) = self.solver.timers.as_mut() {
            t.start_as_current(OUTER_TIMER);
            let start = t.total_time().as_secs_f64();
            self.deadline
                .start
                .store(start.to_bits(), Ordering::Relaxed);
        }
        self.solver.solve();
        if let Some(t) = self.solver.timers.as_mut() {
            t.stop_current();
        }
        let sol = &self.solver.solution;
        let status = QpStatus::from_clarabel(sol.status);
        if status.usable() && sol.x.iter().any(|v| !v.is_finite()) {
            return QpStatus::Failed;
        }
        status
    }

    /// Replace the Clarabel settings (not on the hot path: it allocates).
    pub fn update_settings(&mut self, settings: DefaultSettings<f64>) -> Result<(), String> {
        if let Some(r) = self.rebuild.as_mut() {
            r.2 = settings.clone();
        }
        self.solver
            .update_settings(settings)
            .map_err(|e| e.to_string())
    }

    /// `½ zᵀ P z + qᵀ z` at `self.z`, with the current (not yet solved) data.
    pub fn objective_at_z(&self) -> f64 {
        let z = &self.z;
        let mut v = 0.0;
        for c in 0..self.n {
            for i in self.p_colptr[c]..self.p_colptr[c + 1] {
                let r = self.p_rowval[i];
                let w = self.p_val[i] * z[r] * z[c];
                v += if r == c { 0.5 * w } else { w };
            }
            v += self.q[c] * z[c];
        }
        v
    }

    pub fn x(&self) -> &[f64] {
        &self.solver.solution.x
    }

    pub fn iterations(&self) -> u32 {
        self.solver.solution.iterations
    }

    pub fn objective(&self) -> f64 {
        self.solver.solution.obj_val
    }
}
