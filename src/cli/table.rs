//! The run table on stdout (`mpmlab run`): a header at the first step, a
//! row per step (quasi-static or explicit dynamics), probes last.

use mpmlab::format::{factor_label, relative_balance, sci_or_dash};
use mpmlab::runner::Observer;
use mpmlab::simulation::{Simulation, StepReport};

/// A probe's column name in the table: `<name>:<key>`.
fn probe_column(probe: &str, key: &str) -> String {
    format!("{probe}:{key}")
}

/// The probes' columns of the run table: `<name>:<key>`, each at least
/// 11 wide.
fn probe_header(r: &StepReport) -> String {
    r.probes
        .iter()
        .flat_map(|p| p.columns().into_iter().map(move |(k, _, _)| probe_column(&p.name, k)))
        .map(|h| format!(" {h:>11}"))
        .collect()
}

/// The probes' values of a step, under [`probe_header`].
fn probe_cells(r: &StepReport) -> String {
    r.probes
        .iter()
        .flat_map(|p| {
            p.columns()
                .into_iter()
                .map(move |(k, _, v)| (probe_column(&p.name, k).len().max(11), v))
        })
        .map(|(w, v)| format!(" {v:>w$.4e}"))
        .collect()
}

/// Header of the dynamics table (see [`dynamics_row`]).
pub fn dynamics_header(first: &StepReport) -> String {
    let mut h = format!(
        "{:>6} {:>9} {:>8} {:>11} {:>11} {:>11} {:>11} {:>10} {:>10} {:>10} {:>10}",
        "step",
        "time s",
        "unknowns",
        "kinetic J",
        "strain J",
        "plastic J",
        "balance/W0",
        "cond M~",
        "cond M",
        "cond Mlump",
        "CFL s/m"
    );
    if first.dynamics.as_ref().is_some_and(|d| d.integrator.is_some()) {
        h.push_str(&format!(" {:>5} {:>10}", "iters", "cond(K)"));
    }
    for e in &first.errors {
        h.push_str(&format!(" {:>16}", e.name));
    }
    h.push_str(&format!(" {:>8}", "total s"));
    h.push_str(&probe_header(first));
    h
}

/// One dynamic step: energies, the balance error over the initial energy,
/// and (on condition steps) the mass condition numbers and the CFL number
/// of the mass in use; implicit dynamics adds its Newton iterations and
/// the tangent's condition number.
pub fn dynamics_row(r: &StepReport) -> String {
    let d = r.dynamics.as_ref().expect("a dynamics report");
    let e = &r.energy;
    let balance = sci_or_dash(relative_balance(d), 3);
    let c = |v: Option<f64>| sci_or_dash(v, 3);
    let cond = d.conditioning.as_ref();
    let cfl = d.cfl();
    let mut s = format!(
        "{:>6} {:>9.4} {:>8} {:>11.4e} {:>11.4e} {:>11.4e} {:>11} {:>10} {:>10} {:>10} {:>10}",
        r.step,
        d.time,
        r.unknowns,
        e.kinetic,
        e.strain,
        e.plastic_dissipation,
        balance,
        c(cond.map(|c| c.mass_stabilised.value)),
        c(cond.map(|c| c.mass_consistent.value)),
        c(cond.map(|c| c.mass_lumped.value)),
        c(cfl)
    );
    if d.integrator.is_some() {
        s.push_str(&format!(" {:>5} {:>10}", r.iterations, c(r.condition.map(|c| c.value))));
    }
    for e in &r.errors {
        s.push_str(&format!(" {:>16.4e}", e.value));
    }
    s.push_str(&format!(" {:>8.4}", r.timings.total));
    s.push_str(&probe_cells(r));
    s
}

/// Header of the quasi-static table (see [`row`]).
pub fn header(first: Option<&StepReport>) -> String {
    let mut h = format!(
        "{:>5} {:>7} {:>8} {:>5} {:>10} {:>10} {:>18} {:>11} {:>11} {:>11}",
        "step", "load", "unknowns", "iters", "residual", "cond(K)", "method", "strain U", "work W", "ghost G"
    );
    if first.is_some_and(|r| r.condition_unstabilised.is_some()) {
        h.push_str(&format!(" {:>12}", "cond no-ghost"));
    }
    for e in first.map(|r| r.errors.as_slice()).unwrap_or(&[]) {
        h.push_str(&format!(" {:>15}", e.name));
    }
    h.push_str(&format!(" {:>9} {:>4}", "factor", "cuts"));
    h.push_str(&format!(
        " {:>7} {:>7} {:>7} {:>7} {:>7} {:>7} {:>7} {:>8}",
        "map s", "pat s", "asm s", "fact s", "solve s", "cond s", "upd s", "total s"
    ));
    if let Some(r) = first {
        h.push_str(&probe_header(r));
    }
    h
}

/// One quasi-static step: load, Newton iterations, conditioning, energies,
/// errors, the factor used, cutbacks and the phases' times.
pub fn row(r: &StepReport) -> String {
    let (cond, method) = r.condition.map_or(("-".to_string(), "off"), |c| {
        (format!("{:.3e}", c.value), c.method.label())
    });
    let mut s = format!(
        "{:>5} {:>7.4} {:>8} {:>5} {:>10.3e} {:>10} {:>18} {:>11.4e} {:>11.4e} {:>11.4e}",
        r.step,
        r.load_factor,
        r.unknowns,
        r.iterations,
        r.residuals.last().copied().unwrap_or(f64::NAN),
        cond,
        method,
        r.energy.strain,
        r.energy.external_work,
        r.energy.ghost
    );
    if let Some(c) = r.condition_unstabilised {
        s.push_str(&format!(" {:>12.3e}", c.value));
    }
    for e in &r.errors {
        s.push_str(&format!(" {:>15.4e}", e.value));
    }
    let cuts = r.solver.as_ref().map_or(0, |s| s.cutbacks.len());
    let factor = r.solver.as_ref().map_or("-".to_string(), factor_label);
    s.push_str(&format!(" {:>9} {:>4}", factor, cuts));
    let t = &r.timings;
    s.push_str(&format!(
        " {:>7.4} {:>7.4} {:>7.4} {:>7.4} {:>7.4} {:>7.4} {:>7.4} {:>8.4}",
        t.mapping, t.pattern, t.assembly, t.factorisation, t.solve, t.condition, t.update, t.total
    ));
    s.push_str(&probe_cells(r));
    s
}

/// The run table on stdout, as an observer of the runner.
pub struct Table {
    quiet: bool,
    /// The last step's report.
    pub last: Option<StepReport>,
    pub total_time: f64,
    /// Every phase's time summed over the steps, and the cutbacks taken.
    pub phases: mpmlab::report::Timings,
    pub cutbacks: usize,
}

impl Table {
    /// A table that prints its rows unless `quiet` (cutbacks always).
    pub fn new(quiet: bool) -> Table {
        Table {
            quiet,
            last: None,
            total_time: 0.0,
            phases: Default::default(),
            cutbacks: 0,
        }
    }
}

impl Observer for Table {
    fn stepped(&mut self, _sim: &Simulation, r: &StepReport) -> Option<String> {
        if !self.quiet {
            match (&r.dynamics, self.last.is_none()) {
                (Some(_), true) => out!("{}", dynamics_header(r)),
                (None, true) => out!("{}", header(Some(r))),
                _ => {}
            }
            out!("{}", if r.dynamics.is_some() { dynamics_row(r) } else { row(r) });
        }
        for c in r.cutbacks() {
            out!(
                "       cutback in step {}: {} failed and was halved: {}",
                r.step,
                r.cutback_span(c),
                c.reason
            );
        }
        if let Some(a) = r.solver.as_ref().and_then(|s| s.attainable) {
            out!("       step {}: {a}", r.step);
        }
        self.total_time += r.timings.total;
        self.phases.add(&r.timings);
        self.cutbacks += r.cutbacks().len();
        self.last = Some(r.clone());
        None
    }
}
