//! The summary after the run table (`mpmlab run`, also with `--quiet`):
//! totals, phase times, dynamics, boundaries and probes of the last step.

use super::table::Table;
use mpmlab::simulation::{Simulation, StepReport};
use mpmlab::units::{Quantity, Units};

/// Every summary line of a run that took at least one step.
pub fn print(sim: &Simulation, table: &Table) {
    let Some(r) = &table.last else { return };
    let u = sim.model().units;
    print_totals(sim, table, r, u);
    print_phases(table);
    if let Some(d) = &r.dynamics {
        let en = u.of(Quantity::Energy);
        out!(
            "dynamics: t = {:.6} s, kinetic {:.6e} {en}, strain {:.6e} {en}, plastic {:.6e} {en}, initial {:.6e} {en}, balance error {:.3e} {en}, momentum ({:.6e}, {:.6e}) {}",
            d.time,
            r.energy.kinetic,
            r.energy.strain,
            r.energy.plastic_dissipation,
            d.initial_energy,
            d.energy_error,
            d.momentum[0],
            d.momentum[1],
            u.of(Quantity::Momentum)
        );
    }
    print_boundaries(r, u);
    for p in &r.probes {
        let cols: Vec<String> = p
            .columns()
            .iter()
            .map(|(k, q, v)| format!("{k} {v:.6e} {}", u.of(*q)))
            .collect();
        out!("probe `{}` (step {}): {}", p.name, r.step, cols.join(", "));
    }
}

/// `summary: ...`: steps, time, the last step's energies, conditioning and
/// errors.
fn print_totals(sim: &Simulation, table: &Table, r: &StepReport, u: Units) {
    let en = u.of(Quantity::Energy);
    let errs: Vec<String> = r
        .errors
        .iter()
        .map(|e| format!("{} = {:.4e}", e.name, e.value))
        .collect();
    out!(
        "summary: {}/{} steps, {:.3} s in steps, final strain energy {:.6e} {en}, work {:.6e} {en}{}{}{}",
        sim.step_index(),
        sim.load_steps(),
        table.total_time,
        r.energy.strain,
        r.energy.external_work,
        // The ghost penalty's share of the work (quasi-static, ghost on).
        if r.energy.ghost != 0.0 {
            format!(", ghost penalty {:.6e} {en}", r.energy.ghost)
        } else {
            String::new()
        },
        r.condition.map_or(String::new(), |c| format!(
            ", {} {:.3e} ({})",
            // Explicit dynamics conditions the mass it solves with,
            // implicit dynamics its tangent K + M / (beta dt^2).
            match &r.dynamics {
                Some(d) if d.integrator.is_none() => format!("cond(M {})", d.mass.label()),
                Some(_) => "cond(K + M/(beta dt^2))".to_string(),
                None => "cond(K)".to_string(),
            },
            c.value,
            c.method.label()
        )),
        if errs.is_empty() {
            String::new()
        } else {
            format!(", {}", errs.join(", "))
        }
    );
}

/// `phases (s): ...`: every phase's time summed over the steps, the
/// cutbacks and the peak memory.
fn print_phases(table: &Table) {
    let p = &table.phases;
    out!(
        "phases (s): mapping {:.3}, pattern {:.3}, assembly {:.3}, factorisation {:.3}, solve {:.3}, \
         condition {:.3}, update {:.3}, other {:.3}; {} cutbacks; peak memory {:.0} MB",
        p.mapping,
        p.pattern,
        p.assembly,
        p.factorisation,
        p.solve,
        p.condition,
        p.update,
        p.other(),
        table.cutbacks,
        mpmlab::sweep::peak_rss_kb() as f64 / 1024.0
    );
}

/// The implicit (IBM) and B-spline boundaries at the last step.
fn print_boundaries(r: &StepReport, u: Units) {
    let (force, len) = (u.of(Quantity::Force), u.of(Quantity::Length));
    for b in &r.ibm {
        out!(
            "implicit boundary `{}` (step {}): reaction ({:.6e}, {:.6e}) {force}, violation {:.2e} {len} (rms {:.2e} {len}), {} cells cut{}",
            b.name,
            r.step,
            b.reaction[0],
            b.reaction[1],
            b.violation,
            b.violation_rms,
            b.cut_cells,
            if b.fit_regularisation > 0.0 {
                format!(", fit regularised (weight {:e})", b.fit_regularisation)
            } else {
                String::new()
            }
        );
    }
    for b in &r.boundaries {
        out!(
            "boundary `{}` (start of step {}): length {:.6} {len}{}, {} cells cut, traction resultant ({:.6e}, {:.6e}) {force}{}",
            b.name,
            r.step,
            b.length,
            b.area.map_or(String::new(), |a| format!(", area {a:.6} {}", u.of(Quantity::Area))),
            b.cells_cut,
            b.resultant[0],
            b.resultant[1],
            if b.lost > 0.0 { format!(", LOST {:.3e} {force} on inactive nodes", b.lost) } else { String::new() }
        );
    }
}
