//! The step table as CSV (`mpmlab run --csv FILE`): one row per step with
//! every reported quantity, headers carrying the scene's units
//! (`strain_energy [J/m]`), probes as `probe:<name>:<key> [unit]`.
//!
//! A row for the initial state (step 0, or the step a resumed run starts
//! from: the load factor or time and the probes; the other columns empty)
//! starts the table, so that a
//! load–displacement curve starts at its origin. Rows are flushed as they
//! are written: a run that is killed keeps the rows of its finished steps.

use crate::probe::ProbeValue;
use crate::runner::Observer;
use crate::simulation::{Simulation, StepFailure, StepReport};
use crate::units::{Quantity, Units};
use std::io::Write;
use std::path::{Path, PathBuf};

/// Writes the step table of a run to a CSV file, as an observer.
pub struct CsvWriter {
    path: PathBuf,
    /// The table's temporary file until [`CsvWriter::finish`].
    staged: Option<crate::output::Staged>,
    out: std::io::BufWriter<std::fs::File>,
    units: Units,
    /// The probes at the start (the first row, written with the header),
    /// and the step and load factor (or time) the run starts from.
    initial: Option<Vec<ProbeValue>>,
    start: (usize, f64),
    header: Vec<String>,
    /// The columns of a table whose run takes no step.
    empty: StepReport,
}

impl CsvWriter {
    /// Start the table of the run of `sim` for `path`: written as
    /// `path.partial` (locked: one run at a time) and renamed to `path` by
    /// [`CsvWriter::finish`] ([`crate::output`]); `force` replaces a
    /// `.partial` an earlier run left.
    pub fn create(path: &Path, sim: &Simulation, force: bool) -> Result<CsvWriter, String> {
        let staged =
            crate::output::Staged::claim(path, force).map_err(|e| format!("CSV file {}: {e}", path.display()))?;
        let file = std::fs::OpenOptions::new()
            .write(true)
            .truncate(true)
            .open(staged.partial())
            .map_err(|e| format!("cannot write CSV file {}: {e}", staged.partial().display()))?;
        Ok(CsvWriter {
            path: path.to_path_buf(),
            staged: Some(staged),
            out: std::io::BufWriter::new(file),
            units: sim.model().units,
            initial: Some(sim.probe_values(None)),
            start: (sim.step_index(), sim.time().unwrap_or(sim.load_factor())),
            header: Vec::new(),
            empty: sim.start_report(),
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Remove the table's temporary file: the run never started, and the
    /// file at its path stays as it was.
    pub fn discard(mut self) {
        if let Some(s) = self.staged.take() {
            s.discard();
        }
    }

    /// The table into place: flushed, then renamed from its `.partial`
    /// file to its path. A table of a run that never got here stays as
    /// `.partial`, with every row written so far.
    pub fn finish(mut self) -> Result<(), String> {
        let partial = self.staged.as_ref().map(|s| s.partial().display().to_string());
        // A run that took no step (resumed from its last checkpoint) still
        // gets the header and the row of where it stands.
        let head = if self.initial.is_some() {
            let r = self.empty.clone();
            self.write_head(&r)
        } else {
            Ok(())
        };
        head.and_then(|()| self.out.flush())
            .and_then(|()| self.out.get_ref().sync_all())
            .map_err(|e| {
                format!(
                    "cannot write CSV file {}: {e} (the rows written are in {})",
                    self.path.display(),
                    partial.unwrap_or_default()
                )
            })?;
        match self.staged.take() {
            Some(s) => s.commit(),
            None => Ok(()),
        }
    }

    fn write_row(&mut self, r: &StepReport) -> std::io::Result<()> {
        self.write_head(r)?;
        let cols = columns(r, self.units);
        // A step whose columns differ from the header's (cannot happen for
        // one scene; kept honest rather than misaligned).
        let names: Vec<&String> = cols.iter().map(|c| &c.0).collect();
        if names != self.header.iter().collect::<Vec<_>>() {
            return Err(std::io::Error::other(format!(
                "step {} has other columns than step 1",
                r.step
            )));
        }
        let row: Vec<String> = cols.into_iter().map(|(_, v)| field(&v)).collect();
        writeln!(self.out, "{}", row.join(","))?;
        self.out.flush()
    }

    /// The header (the columns of `r`) and the row of where the run
    /// starts, before the first row.
    fn write_head(&mut self, r: &StepReport) -> std::io::Result<()> {
        let cols = columns(r, self.units);
        if let Some(initial) = self.initial.take() {
            self.header = cols.iter().map(|c| c.0.clone()).collect();
            writeln!(
                self.out,
                "{}",
                self.header.iter().map(|h| field(h)).collect::<Vec<_>>().join(",")
            )?;
            // Where the run starts (step 0, or the step a resumed run
            // starts from).
            let start = StepReport {
                probes: initial,
                ..r.clone()
            };
            let (step, x) = self.start;
            let zero: Vec<String> = columns(&start, self.units)
                .into_iter()
                .map(|(h, v)| match h.as_str() {
                    "step" => step.to_string(),
                    "load_factor" => num(x),
                    h if h.starts_with("time [") => num(x),
                    h if h.starts_with("probe:") => v,
                    _ => String::new(),
                })
                .collect();
            writeln!(self.out, "{}", zero.join(","))?;
        }
        Ok(())
    }
}

impl Observer for CsvWriter {
    fn stepped(&mut self, _sim: &Simulation, r: &StepReport) -> Option<String> {
        self.write_row(r).err().map(|e| match &self.staged {
            Some(s) => format!(
                "CSV file {}: {e} (the rows written so far are kept in {})",
                self.path.display(),
                s.partial().display()
            ),
            None => format!("CSV file {}: {e}", self.path.display()),
        })
    }
    fn failed(&mut self, _sim: &Simulation, _f: &StepFailure) -> Option<String> {
        self.out
            .flush()
            .err()
            .map(|e| format!("CSV file {}: {e}", self.path.display()))
    }
}

/// A number in full precision (round-trips exactly); empty when not finite.
fn num(v: f64) -> String {
    if v.is_finite() {
        format!("{v:e}")
    } else {
        String::new()
    }
}

/// One CSV field, quoted when it must be (RFC 4180).
fn field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// `name [unit]`.
fn with_unit(name: &str, u: Units, q: Quantity) -> String {
    format!("{name} [{}]", u.of(q))
}

/// The columns of a step: `(header, value)`.
pub fn columns(r: &StepReport, u: Units) -> Vec<(String, String)> {
    use Quantity::*;
    let mut c: Vec<(String, String)> = vec![("step".into(), r.step.to_string())];
    let e = &r.energy;
    match &r.dynamics {
        Some(d) => {
            c.push((with_unit("time", u, Time), num(d.time)));
            c.push(("unknowns".into(), r.unknowns.to_string()));
            c.push((with_unit("kinetic_energy", u, Energy), num(e.kinetic)));
            c.push((with_unit("strain_energy", u, Energy), num(e.strain)));
            c.push((with_unit("plastic_dissipation", u, Energy), num(e.plastic_dissipation)));
            c.push((with_unit("initial_energy", u, Energy), num(d.initial_energy)));
            c.push((with_unit("balance_error", u, Energy), num(d.energy_error)));
            c.push((with_unit("momentum_x", u, Momentum), num(d.momentum[0])));
            c.push((with_unit("momentum_y", u, Momentum), num(d.momentum[1])));
            c.push((with_unit("max_grid_speed", u, Velocity), num(d.max_speed)));
            let cond = d.conditioning.as_ref();
            c.push((
                "cond_mass_stabilised".into(),
                num(cond.map_or(f64::NAN, |c| c.mass_stabilised.value)),
            ));
            c.push((
                "cond_mass_consistent".into(),
                num(cond.map_or(f64::NAN, |c| c.mass_consistent.value)),
            ));
            c.push((
                "cond_mass_lumped".into(),
                num(cond.map_or(f64::NAN, |c| c.mass_lumped.value)),
            ));
            c.push(("cutbacks".into(), d.cutbacks.len().to_string()));
        }
        None => {
            c.push(("load_factor".into(), num(r.load_factor)));
            c.push(("unknowns".into(), r.unknowns.to_string()));
            c.push(("iterations".into(), r.iterations.to_string()));
            c.push(("residual".into(), num(r.residuals.last().copied().unwrap_or(f64::NAN))));
            c.push((with_unit("residual_norm", u, Force), num(r.residual_norm)));
            c.push(("cond_K".into(), num(r.condition.map_or(f64::NAN, |c| c.value))));
            c.push((
                "cond_K_method".into(),
                r.condition.map_or(String::new(), |c| c.method.label().to_string()),
            ));
            c.push((
                "cond_K_without_ghost".into(),
                num(r.condition_unstabilised.map_or(f64::NAN, |c| c.value)),
            ));
            c.push((with_unit("strain_energy", u, Energy), num(e.strain)));
            c.push((with_unit("external_work", u, Energy), num(e.external_work)));
            c.push((with_unit("plastic_dissipation", u, Energy), num(e.plastic_dissipation)));
            c.push((with_unit("ghost_energy", u, Energy), num(e.ghost)));
            c.push((with_unit("max_increment", u, Length), num(r.max_increment)));
            let s = r.solver.as_ref();
            c.push((
                "factorisation".into(),
                s.and_then(|s| s.factorisation)
                    .map_or(String::new(), |f| f.label().to_string()),
            ));
            c.push((
                "negative_pivots".into(),
                s.and_then(|s| s.negative_pivots)
                    .map_or(String::new(), |n| n.to_string()),
            ));
            c.push(("cutbacks".into(), s.map_or(0, |s| s.cutbacks.len()).to_string()));
        }
    }
    for x in &r.errors {
        c.push((format!("error:{}", x.name), num(x.value)));
    }
    for b in &r.ibm {
        c.push((with_unit(&format!("ibm:{}:fx", b.name), u, Force), num(b.reaction[0])));
        c.push((with_unit(&format!("ibm:{}:fy", b.name), u, Force), num(b.reaction[1])));
        c.push((
            with_unit(&format!("ibm:{}:violation", b.name), u, Length),
            num(b.violation),
        ));
    }
    for b in &r.boundaries {
        c.push((
            with_unit(&format!("boundary:{}:fx", b.name), u, Force),
            num(b.resultant[0]),
        ));
        c.push((
            with_unit(&format!("boundary:{}:fy", b.name), u, Force),
            num(b.resultant[1]),
        ));
        c.push((
            with_unit(&format!("boundary:{}:length", b.name), u, Length),
            num(b.length),
        ));
    }
    for (name, v) in r.timings.named() {
        c.push((format!("time_{name} [s]"), num(v)));
    }
    for p in &r.probes {
        for (k, q, v) in p.columns() {
            c.push((with_unit(&format!("probe:{}:{k}", p.name), u, q), num(v)));
        }
    }
    c
}
