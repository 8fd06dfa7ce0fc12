//! What the viewer shows of a recording: the stored layout (a rerun
//! blueprint), the units in its titles, the styles of the series and the
//! drawing order and orientation of the scene.
//!
//! Orientation: rerun's 2D views draw y downward. The scene's entities
//! (`points`, `grid`, `boundaries`, `ibm`, `legend`) are logged in physical
//! coordinates, each under a static `Transform3D` that scales y by -1, so
//! physical up is up on the screen. A point's `positions` (shown when it is
//! hovered) are the true coordinates; the view's own "hover position" is in
//! the drawn space, with y negated. The scene view's title says so.
//!
//! Drawing order (higher on top): grid, occupied cells, active cells, cells
//! an implicit boundary cuts, ghost faces, points, grid conditions,
//! boundaries, control points, loads, probes, the colour bar.

use crate::field::Field;
use crate::units::Units;
use rerun::blueprint::{
    BarChartView, Blueprint, ContainerLike, Grid, Horizontal, SelectionPanel, Spatial2DView, Tabs, TextDocumentView,
    TextLogView, TimePanel, TimeSeriesView,
};

/// A quantity the recording shows with a unit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Quantity {
    Length,
    Energy,
    Force,
    Time,
    Speed,
    Momentum,
    /// A per-point field.
    Field(Field),
}

/// The unit shown with `q` in titles, legends and labels, in the scene's
/// unit system (forces, energies and momenta per unit thickness). Every
/// unit string of a recording comes from here.
pub fn unit(units: Units, q: Quantity) -> &'static str {
    use crate::units::Quantity as Q;
    match q {
        Quantity::Length => units.of(Q::Length),
        Quantity::Energy => units.of(Q::Energy),
        Quantity::Force => units.of(Q::Force),
        Quantity::Time => units.of(Q::Time),
        Quantity::Speed => units.of(Q::Velocity),
        Quantity::Momentum => units.of(Q::Momentum),
        Quantity::Field(f) => match f {
            Field::SigmaXx | Field::SigmaYy | Field::SigmaXy => units.of(Q::Stress),
            Field::DisplacementMagnitude => units.of(Q::Length),
            Field::Speed => units.of(Q::Velocity),
            Field::PlasticStrain | Field::Error => "",
        },
    }
}

/// `name (unit)`, or `name` for a dimensionless quantity.
pub fn titled(name: &str, units: Units, q: Quantity) -> String {
    match unit(units, q) {
        "" => name.to_string(),
        u => format!("{name} ({u})"),
    }
}

/// Drawing order of the scene's layers (rerun's `DrawOrder`: higher on top).
pub mod order {
    pub const GRID: f32 = 1.0;
    pub const OCCUPIED: f32 = 2.0;
    pub const ACTIVE: f32 = 3.0;
    pub const CUT_CELLS: f32 = 4.0;
    pub const GHOST_FACES: f32 = 9.0;
    pub const POINTS: f32 = 10.0;
    pub const CONDITIONS: f32 = 25.0;
    pub const LOADS: f32 = 32.0;
    pub const PROBES: f32 = 33.0;
    pub const BOUNDARY: f32 = 30.0;
    pub const CONTROL_POINTS: f32 = 31.0;
    pub const LEGEND: f32 = 40.0;
}

/// The scene's top-level entities, each flipped so that physical up is up.
pub const SCENE_ROOTS: [&str; 7] = ["points", "grid", "boundaries", "ibm", "legend", "loads", "probes"];

/// The static transform of every scene root: y scaled by -1.
pub fn y_up() -> rerun::Transform3D {
    rerun::Transform3D::from_scale([1.0, -1.0, 1.0])
}

/// A colour-blind safe palette (Okabe and Ito), for series drawn together.
pub mod palette {
    pub const SKY: [u8; 3] = [86, 180, 233];
    pub const ORANGE: [u8; 3] = [230, 159, 0];
    pub const GREEN: [u8; 3] = [0, 158, 115];
    pub const VERMILLION: [u8; 3] = [213, 94, 0];
    pub const BLUE: [u8; 3] = [0, 114, 178];
    pub const PINK: [u8; 3] = [204, 121, 167];
    pub const YELLOW: [u8; 3] = [240, 228, 66];
    pub const WHITE: [u8; 3] = [230, 230, 230];
}

/// The look of one time series: its entity, legend name and colour, and
/// whether each value is marked whatever the run's length (a series
/// sampled every few steps: a line alone bridges its gaps unseen).
pub struct Series {
    pub path: String,
    pub name: String,
    pub color: [u8; 3],
    pub marked: bool,
}

impl Series {
    pub fn new(path: impl Into<String>, name: impl Into<String>, color: [u8; 3]) -> Series {
        Series {
            path: path.into(),
            name: name.into(),
            color,
            marked: false,
        }
    }

    /// The series with every value marked.
    pub fn marked(mut self) -> Series {
        self.marked = true;
        self
    }
}

/// The probe series of one unit: the panel's title and the series' paths.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ProbePanel {
    pub title: String,
    pub paths: Vec<String>,
}

/// Runs of at most this many steps mark every value of a series (a line
/// alone through one value draws nothing).
pub const MARKED_STEPS: usize = 100;

/// What a run records, which decides the panels of its layout.
#[derive(Clone, Debug, Default)]
pub struct Contents {
    /// The scene's unit system (titles).
    pub units: Units,
    /// The `[[probe]]`s' series, one panel per unit (displacements,
    /// velocities, stresses, forces).
    pub probes: Vec<ProbePanel>,
    /// Explicit dynamics (energies against time, no Newton residuals).
    pub dynamic: bool,
    /// Finite deformation with Newton iterations (else one linear solve a step).
    pub newton: bool,
    /// Condition numbers are computed.
    pub condition: bool,
    /// Ghost stabilisation: a second condition number, without it.
    pub ghost: bool,
    /// Errors against an exact solution.
    pub exact: bool,
    /// The colour field's title (`sigma_yy (Pa)`).
    pub colour: String,
}

impl Contents {
    /// The series each panel shows, with their names and colours (logged
    /// as static `SeriesLines`, and `SeriesPoints` for short runs).
    pub fn series(&self) -> Vec<Series> {
        use palette::*;
        let mut s = Vec::new();
        let e = |p: &str| format!("metrics/energy/{p}");
        if self.dynamic {
            s.push(Series::new(e("kinetic"), "kinetic", SKY));
            s.push(Series::new(e("strain"), "strain", ORANGE));
            s.push(Series::new(e("plastic_dissipation"), "plastic", VERMILLION));
            s.push(Series::new(e("total"), "kinetic + strain", WHITE));
            s.push(Series::new(e("balance_error_relative"), "balance error / W0", PINK));
            if self.condition {
                s.push(Series::new("metrics/log10/condition/mass_stabilised", "stabilised", GREEN).marked());
                s.push(Series::new("metrics/log10/condition/mass_lumped", "lumped", SKY).marked());
                s.push(Series::new("metrics/log10/condition/mass_consistent", "consistent", VERMILLION).marked());
            }
        } else {
            s.push(Series::new(e("strain"), "strain", ORANGE));
            s.push(Series::new(e("external_work"), "external work", GREEN));
            s.push(Series::new(e("plastic_dissipation"), "plastic", VERMILLION));
            s.push(Series::new(e("ghost"), "ghost penalty", SKY));
            s.push(Series::new(
                e("balance_error"),
                "strain + plastic - external work",
                PINK,
            ));
            s.push(
                Series::new(
                    "metrics/log10/condition/stiffness",
                    if self.ghost { "with ghost" } else { "stiffness" },
                    GREEN,
                )
                .marked(),
            );
            s.push(
                Series::new(
                    "metrics/log10/condition/stiffness_unstabilised",
                    "without ghost",
                    VERMILLION,
                )
                .marked(),
            );
            s.push(Series::new("metrics/newton/iterations", "iterations", SKY));
        }
        s
    }

    /// The series of the error measures, named as the exact solution names
    /// them (known at the first step).
    pub fn error_series(names: &[&str]) -> Vec<Series> {
        use palette::*;
        let colours = [BLUE, ORANGE, GREEN, VERMILLION, SKY, PINK, YELLOW];
        names
            .iter()
            .enumerate()
            .map(|(k, name)| Series::new(format!("metrics/log10/error/{name}"), *name, colours[k % colours.len()]))
            .collect()
    }

    /// The viewer's default layout: the scene on the left; on the right a
    /// grid of the panels this run has (Newton residuals of the current
    /// step, condition numbers, energies, errors) and the event log with
    /// the scene file and the recording's description as tabs.
    pub fn blueprint(&self) -> Blueprint {
        let scene = Spatial2DView::new(format!(
            "scene, y up (hover position: y negated; a point's positions are true); colour: {}",
            self.colour
        ))
        .with_origin("/")
        .with_contents([
            "/points",
            "/grid/**",
            "/boundaries/**",
            "/ibm/**",
            "/legend/**",
            "/loads/**",
            "/probes/**",
        ]);
        let mut panels: Vec<ContainerLike> = Vec::new();
        // The x axis of every time series is the time panel's timeline:
        // the titles name it.
        let x = if self.dynamic {
            format!("against time ({})", unit(self.units, Quantity::Time))
        } else {
            "against load step".to_string()
        };
        let energy = format!("{} {x}", titled("energy", self.units, Quantity::Energy));
        if self.dynamic {
            panels.push(
                TimeSeriesView::new(energy.clone())
                    .with_contents([
                        "/metrics/energy/kinetic",
                        "/metrics/energy/strain",
                        "/metrics/energy/plastic_dissipation",
                        "/metrics/energy/total",
                    ])
                    .into(),
            );
            panels.push(
                TimeSeriesView::new(format!("energy balance error / W0 (G 5.2) {x}"))
                    .with_contents(["/metrics/energy/balance_error_relative"])
                    .into(),
            );
            if self.condition {
                panels.push(
                    TimeSeriesView::new(format!(
                        "log10 condition number of the mass: stabilised, lumped, consistent {x} \
                         (marked where sampled; singular ones are events)"
                    ))
                    .with_contents([
                        "/metrics/log10/condition/mass_stabilised",
                        "/metrics/log10/condition/mass_lumped",
                        "/metrics/log10/condition/mass_consistent",
                    ])
                    .into(),
                );
            }
        } else {
            let residual = if self.newton {
                "Newton residual history of the step at the cursor: log10 |r|/|r0| against iteration"
            } else {
                "linear solve's residual history of the step at the cursor: log10 |K du - r|/|r| against refinement"
            };
            panels.push(
                BarChartView::new(residual)
                    .with_origin("/metrics/newton/residual_history")
                    .into(),
            );
            if self.newton {
                panels.push(
                    TimeSeriesView::new(format!("Newton iterations per step {x}"))
                        .with_contents(["/metrics/newton/iterations"])
                        .into(),
                );
            }
            if self.condition {
                panels.push(
                    TimeSeriesView::new(if self.ghost {
                        format!("log10 condition number, with and without ghost {x} (singular ones are events)")
                    } else {
                        format!("log10 condition number of the stiffness {x} (singular ones are events)")
                    })
                    .with_contents([
                        "/metrics/log10/condition/stiffness",
                        "/metrics/log10/condition/stiffness_unstabilised",
                    ])
                    .into(),
                );
            }
            panels.push(
                TimeSeriesView::new(energy.clone())
                    .with_contents([
                        "/metrics/energy/strain",
                        "/metrics/energy/external_work",
                        "/metrics/energy/plastic_dissipation",
                        "/metrics/energy/ghost",
                        "/metrics/energy/balance_error",
                    ])
                    .into(),
            );
        }
        if self.exact {
            panels.push(
                TimeSeriesView::new(format!("log10 error vs exact solution {x}"))
                    .with_origin("/metrics/log10/error")
                    .into(),
            );
        }
        for p in &self.probes {
            panels.push(
                TimeSeriesView::new(format!("{} {x}", p.title))
                    .with_contents(p.paths.iter().map(|q| format!("/{q}")))
                    .into(),
            );
        }
        panels.push(
            Tabs::new([
                TextLogView::new("events").with_origin("/events").into(),
                TextDocumentView::new("scene file").with_origin("/scene").into(),
                TextDocumentView::new("recording").with_origin("/recording").into(),
            ])
            .into(),
        );
        let rows = panels.len().div_ceil(2);
        let right = Grid::new(panels).with_grid_columns(2).with_row_shares(vec![1.0; rows]);
        // The selection and time panels start collapsed (the time panel to
        // its play bar, on `time` for explicit dynamics, else on `step`,
        // following the data: a file opens on its last step): the views
        // get the room. The blueprint panel stays, with the list
        // of open recordings.
        use rerun::blueprint::components::{PanelState, PlayState};
        Blueprint::new(Horizontal::new([scene.into(), right.into()]).with_column_shares([0.5, 0.5]))
            .with_selection_panel(SelectionPanel::new().with_state(PanelState::Collapsed))
            .with_time_panel(
                TimePanel::new()
                    .with_state(PanelState::Collapsed)
                    .with_timeline(if self.dynamic { "time" } else { "step" })
                    .with_play_state(PlayState::Following),
            )
    }
}
