//! The scene's geometry besides the points, as each frame draws it: the
//! grid-line conditions and gravity (static), the point loads and probes,
//! the implicit and B-spline boundaries, and the deformation scale a
//! small-strain run is drawn at.

use super::{cell_box, drawn_at, order, RecordError, Recorder};
use crate::simulation::Simulation;

impl Recorder {
    /// The grid-line conditions (static: grid lines do not move), each
    /// labelled with its kind and prescribed value, and gravity as an
    /// arrow at the grid's top-left corner.
    pub(super) fn log_conditions(&self, sim: &Simulation) -> Result<(), RecordError> {
        use crate::model::GridTarget;
        let m = sim.model();
        let (g, u) = (&m.grid, m.units);
        let len = u.of(crate::units::Quantity::Length);
        let max = g.max();
        for (k, c) in m.dirichlet.iter().enumerate() {
            let named: Vec<String> = c
                .value
                .iter()
                .zip(["u_x", "u_y"])
                .filter_map(|(v, n)| v.map(|v| format!("{n} = {v}")))
                .collect();
            let kind = if named.len() == 2 { "fixed" } else { "roller" };
            let (strip, place) = match c.target {
                GridTarget::Line { axis: 0, index } => {
                    let x = g.origin[0] + index as f64 * g.h;
                    (vec![[x, g.origin[1]], [x, max[1]]], format!("x = {x}"))
                }
                GridTarget::Line { index, .. } => {
                    let y = g.origin[1] + index as f64 * g.h;
                    (vec![[g.origin[0], y], [max[0], y]], format!("y = {y}"))
                }
                GridTarget::Node(n) => {
                    let x = g.node_position(n);
                    (vec![x, x], format!("node ({}, {})", x[0], x[1]))
                }
            };
            let label = format!("{kind} {place}: {} {len} (grid line condition)", named.join(", "));
            let strip: Vec<[f32; 2]> = strip.iter().map(|p| [p[0] as f32, p[1] as f32]).collect();
            self.check(
                self.rec.log_static(
                    format!("grid/conditions/{k}"),
                    &rerun::LineStrips2D::new([strip])
                        .with_colors([rerun::Color::from_rgb(204, 121, 167)])
                        .with_radii([rerun::Radius::new_ui_points(2.0)])
                        .with_labels([label])
                        .with_draw_order(order::CONDITIONS),
                ),
            )?;
        }
        if m.gravity != [0.0; 2] {
            let n = m.gravity[0].hypot(m.gravity[1]);
            let a = 2.0 * g.h / n;
            self.check(
                self.rec.log_static(
                    "loads/gravity",
                    &rerun::Arrows2D::from_vectors([[(a * m.gravity[0]) as f32, (a * m.gravity[1]) as f32]])
                        .with_origins([[(g.origin[0] + g.h) as f32, (max[1] - g.h) as f32]])
                        .with_labels([format!(
                            "gravity ({}, {}) {len}/{}^2",
                            m.gravity[0],
                            m.gravity[1],
                            u.of(crate::units::Quantity::Time)
                        )])
                        .with_colors([rerun::Color::from_rgb(86, 180, 233)])
                        .with_draw_order(order::LOADS),
                ),
            )?;
        }
        Ok(())
    }
    /// The point loads (arrows two cells long at their points, labelled
    /// with the force at load factor 1) and the probes at their positions
    /// (labelled), drawn with the points at deformation scale `s`.
    pub(super) fn log_loads_and_probes(&self, sim: &Simulation, s: f64) -> Result<(), RecordError> {
        let m = sim.model();
        let pts = sim.points();
        let drawn = |x0: [f64; 2], u: [f64; 2]| drawn_at(x0, [x0[0] + u[0], x0[1] + u[1]], s);
        let force = m.units.of(crate::units::Quantity::Force);
        for (k, l) in m.point_loads.iter().enumerate() {
            let n = l.force[0].hypot(l.force[1]);
            if n == 0.0 {
                continue;
            }
            let a = 2.0 * m.grid.h / n;
            self.check(
                self.rec.log(
                    format!("loads/point/{k}"),
                    &rerun::Arrows2D::from_vectors([[(a * l.force[0]) as f32, (a * l.force[1]) as f32]])
                        .with_origins([drawn(pts.x0[l.point], pts.displacement(l.point))])
                        .with_labels([format!("F ({:.3e}, {:.3e}) {force}", l.force[0], l.force[1])])
                        .with_colors([rerun::Color::from_rgb(86, 180, 233)])
                        .with_draw_order(order::LOADS),
                ),
            )?;
        }
        let mut at = Vec::new();
        let mut names = Vec::new();
        for (p, v) in m.probes.iter().zip(sim.probe_values(None)) {
            let x0 = match p.target {
                crate::probe::ProbeTarget::Point(q) => pts.x0[q],
                _ => match p.at {
                    Some(a) => a,
                    None => continue,
                },
            };
            at.push(drawn(x0, v.u));
            names.push(format!("probe {}", p.name));
        }
        if !at.is_empty() {
            self.check(
                self.rec.log(
                    "probes",
                    &rerun::Points2D::new(at)
                        .with_labels(names)
                        .with_colors([rerun::Color::from_rgb(240, 228, 66)])
                        .with_radii([rerun::Radius::new_ui_points(4.0)])
                        .with_draw_order(order::PROBES),
                ),
            )?;
        }
        Ok(())
    }
    /// The implicit boundaries (labelled with name and kind) and the cells
    /// they cut; the B-spline boundaries (red and labelled when they carry
    /// a traction) with their control points, drawn with the points at
    /// deformation scale `drawn`.
    pub(super) fn log_boundaries(&self, sim: &Simulation, drawn: f64) -> Result<(), RecordError> {
        let g = &sim.model().grid;
        for b in &sim.ibm_boundaries() {
            let line: Vec<[f32; 2]> = b.points.iter().map(|p| [p[0] as f32, p[1] as f32]).collect();
            self.check(
                self.rec.log(
                    format!("ibm/{}/line", b.name),
                    &rerun::LineStrips2D::new([line])
                        .with_colors([rerun::Color::from_rgb(40, 200, 220)])
                        .with_radii([rerun::Radius::new_ui_points(2.5)])
                        .with_labels([format!(
                            "{} (implicit {})",
                            b.name,
                            match b.kind {
                                crate::scene::DirichletKind::Roller => "roller",
                                crate::scene::DirichletKind::Fixed => "fixed",
                            }
                        )])
                        .with_draw_order(order::BOUNDARY),
                ),
            )?;
            let cut: Vec<[[f32; 2]; 5]> = b.cut_cells(g).iter().map(|&c| cell_box(g, c)).collect();
            self.check(
                self.rec.log(
                    format!("ibm/{}/cut_cells", b.name),
                    &rerun::LineStrips2D::new(cut)
                        .with_colors([rerun::Color::from_rgb(0, 110, 120)])
                        .with_radii([rerun::Radius::new_ui_points(1.0)])
                        .with_draw_order(order::CUT_CELLS),
                ),
            )?;
        }
        for ((name, spline), b) in sim.boundary_splines().into_iter().zip(&sim.model().boundaries) {
            let Some(s) = spline else { continue };
            // A loaded boundary: red, thicker and labelled as loaded.
            let (color, width, label) = if b.traction.is_some() {
                (rerun::Color::from_rgb(230, 80, 60), 3.0, format!("{name} (traction)"))
            } else {
                (rerun::Color::from_rgb(230, 230, 230), 1.5, name.to_string())
            };
            // Drawn with the points: at a small-strain deformation scale
            // other than 1, through the tracking points as drawn.
            let curve: Vec<[f32; 2]> = if drawn == 1.0 {
                s.sample(16).iter().map(|p| [p[0] as f32, p[1] as f32]).collect()
            } else {
                let pts = sim.points();
                b.points.iter().map(|&p| drawn_at(pts.x0[p], pts.x[p], drawn)).collect()
            };
            self.check(
                self.rec.log(
                    format!("boundaries/{name}/curve"),
                    &rerun::LineStrips2D::new([curve])
                        .with_colors([color])
                        .with_radii([rerun::Radius::new_ui_points(width)])
                        .with_labels([label])
                        .with_draw_order(order::BOUNDARY),
                ),
            )?;
            // The control points are the true curve's: none in a scaled
            // drawing.
            let control: Vec<[f32; 2]> = if drawn == 1.0 {
                s.segments
                    .iter()
                    .flat_map(|seg| seg.iter().map(|p| [p[0] as f32, p[1] as f32]))
                    .collect()
            } else {
                Vec::new()
            };
            self.check(
                self.rec.log(
                    format!("boundaries/{name}/control_points"),
                    &rerun::Points2D::new(control)
                        .with_colors([rerun::Color::from_rgb(240, 200, 40)])
                        .with_radii([rerun::Radius::new_ui_points(2.5)])
                        .with_draw_order(order::CONTROL_POINTS),
                ),
            )?;
        }
        Ok(())
    }
    /// Small strain: the scale the points' displacements are drawn at
    /// (the scene's, or [`crate::model::record::deformation_scale`] of the
    /// first state with a displacement, said in an event); 1 otherwise.
    pub(super) fn deformation_scale(&mut self, sim: &Simulation) -> Result<f64, RecordError> {
        if sim.model().analysis.kind != crate::scene::AnalysisKind::QuasiStaticLinear {
            return Ok(1.0);
        }
        if let Some(s) = self.deformation {
            return Ok(s);
        }
        let pts = sim.points();
        let u_max = (0..pts.len())
            .map(|p| pts.displacement(p))
            .map(|u| u[0].hypot(u[1]))
            .fold(0.0, f64::max);
        let s = match self.settings.deformation_scale {
            Some(s) => s,
            None if u_max > 0.0 && sim.load_factor() > 0.0 => {
                let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
                for x in &pts.x0 {
                    for c in 0..2 {
                        lo[c] = lo[c].min(x[c]);
                        hi[c] = hi[c].max(x[c]);
                    }
                }
                let size = (hi[0] - lo[0]).hypot(hi[1] - lo[1]);
                crate::model::record::deformation_scale(u_max, sim.load_factor(), size)
            }
            None => return Ok(1.0),
        };
        self.deformation = Some(s);
        // Said when the drawing is not true to scale (each frame's label
        // says it too).
        if s != 1.0 {
            self.event(
                &format!(
                    "small strain: the points are drawn at x0 + {s} u{}",
                    if self.settings.deformation_scale.is_some() {
                        " (the scene's deformation_scale)"
                    } else {
                        " (the full-load displacement drawn as a tenth of the bodies' extent; \
                         [record] deformation_scale sets it)"
                    }
                ),
                rerun::TextLogLevel::INFO,
            )?;
        }
        Ok(s)
    }
}
