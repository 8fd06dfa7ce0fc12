//! The model: a validated scene turned into grid, materials, bodies with
//! their material points, boundary conditions, loads and analysis settings.

mod analysis;
mod bodies;
mod boundaries;
mod conditions;
mod exact;
mod ibm;
mod limits;
mod materials;
mod probes;
pub mod record;

use analysis::{resolve_delta, validate_kind, validate_solver};
use boundaries::build_boundary;
use exact::build_exact_solution;
pub use limits::{available_memory, bytes, parse_bytes, Limits};
use limits::{check_curve_totals, check_names, short, Budget};

use crate::basis::BasisKind;
use crate::boundary::bspline::BSpline;
use crate::boundary::{Boundary, Traction};
use crate::exact::ExactSolution;
use crate::geometry::{Region, P2};
use crate::grid::Grid;
use crate::ibm::IbmBoundary;
use crate::material::{LinearElastic, Material};
use crate::points::Points;
use crate::quadrature::gauss_legendre;
use crate::scene::number;
use crate::scene::{
    AnalysisSpec, BodySpec, BoundarySpec, DirichletKind, ExactSpec, FieldError, LayerSide, Locator, MaterialModel,
    MaterialSide, Placement, RegionSpec, Scene, SceneError, TractionSpec,
};

/// A body: a named set of points of one material with one basis.
#[derive(Clone, Debug)]
pub struct Body {
    pub name: String,
    pub material: usize,
    pub basis: BasisKind,
    pub points_per_cell: usize,
    /// Area of the region the points were generated from (m^2).
    pub region_area: f64,
}

/// Where a grid-aligned Dirichlet condition acts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GridTarget {
    /// Every node of grid line `index` along `axis` (`0`: the vertical line
    /// `x = c`; `1`: the horizontal line `y = c`).
    Line { axis: usize, index: usize },
    /// One grid node.
    Node(usize),
}

/// A grid-aligned Dirichlet condition: component `k` of the target nodes is
/// prescribed to `value[k]` (total at load factor 1) where `Some`.
#[derive(Clone, Debug, PartialEq)]
pub struct GridDirichlet {
    pub target: GridTarget,
    pub value: [Option<f64>; 2],
}

/// A point load on material point `point`, total force at load factor 1 (N).
#[derive(Clone, Debug, PartialEq)]
pub struct PointLoad {
    pub point: usize,
    pub force: P2,
}

/// Everything a simulation starts from.
#[derive(Clone, Debug)]
pub struct Model {
    pub name: String,
    pub description: String,
    /// The unit system of the scene's numbers (for labels).
    pub units: crate::units::Units,
    pub grid: Grid,
    pub materials: Vec<Material>,
    pub bodies: Vec<Body>,
    /// The initial points; [`crate::Simulation::new`] moves them into its
    /// state (the model it keeps then holds none).
    pub points: Points,
    pub dirichlet: Vec<GridDirichlet>,
    /// Gravitational acceleration (m/s^2); body force = density * gravity.
    pub gravity: P2,
    pub point_loads: Vec<PointLoad>,
    /// B-spline boundaries (tracked curves, optionally with tractions).
    pub boundaries: Vec<Boundary>,
    /// Implicit-boundary Dirichlet conditions.
    pub ibm: Vec<IbmBoundary>,
    pub analysis: AnalysisSpec,
    pub exact: Option<ExactSolution>,
    /// What a recording of a run holds (`[record]`).
    pub record: record::RecordSettings,
    /// Quantities followed through the run (`[[probe]]`).
    pub probes: Vec<crate::probe::Probe>,
    /// The memory the process may use while stepping (bytes, the
    /// `--max-memory` of the build): a factorisation whose estimate would
    /// take the process beyond it is refused as a step failure.
    pub max_memory: u64,
}

/// Largest grid the engine will build (cells).
pub const MAX_CELLS: usize = 20_000_000;
/// Most material points a model may have.
pub const MAX_POINTS: usize = 10_000_000;
/// Most vertices of an implicit boundary's polyline, and most tracking
/// points of a B-spline boundary.
pub const MAX_CURVE_POINTS: usize = 100_000;
/// Most materials, bodies, boundaries and implicit boundaries (each);
/// grid-aligned conditions may be ten times as many.
pub const MAX_ENTRIES: usize = 1_000;
/// Most point loads.
pub const MAX_POINT_LOADS: usize = 10_000;
/// Largest `dense_limit` (a dense eigenproblem of this many unknowns).
pub const MAX_DENSE_LIMIT: usize = 20_000;
/// Most characters of a name.
pub const MAX_NAME: usize = 100;
/// Most cells (or lattice points) times region pieces that point
/// generation may test against each other.
const MAX_GENERATION_WORK: u128 = 1_000_000_000;

/// The memory estimate of a scene, checked against `--max-memory` before
/// any point is made: [`BASE_BYTES`] + points x [`bytes_per_point`] + grid
/// nodes x [`bytes_per_grid_node`] + the nodes the bodies' bounding boxes
/// cover x [`BYTES_PER_ACTIVE_NODE`] + dense eigenvalues. Calibrated on the
/// peaks (`VmHWM`, the `peak memory` of `mpmlab run --quiet`) of runs over
/// a range of sizes, with the constants chosen so that every run's
/// estimate lies 1.1 to 1.6 times above its peak (explicit runs up to 3
/// times: the lumped mass needs no factor); `docs/scenes.md` lists them.
/// The factor itself is estimated again at each step from its symbolic
/// analysis ([`crate::linalg::check_memory`]), where fill-in is known.
///
/// The program itself (code, threads, allocator): 15-17 MB measured.
pub const BASE_BYTES: u64 = 16 << 20;

/// Estimated bytes per material point while stepping: the point arrays,
/// its stencil (values, gradients, node indices), its constitutive response
/// and its share of the recorded and reported fields. Measured: about
/// 0.9 kB (linear, 4 to 16 points per cell, either basis) and 2 kB (finite
/// deformation, which keeps F and the tangent per point).
pub fn bytes_per_point(kind: crate::scene::AnalysisKind) -> u64 {
    match kind {
        crate::scene::AnalysisKind::QuasiStaticFinite | crate::scene::AnalysisKind::DynamicImplicit => 2_048,
        _ => 1_024,
    }
}

/// Estimated bytes per grid node, for the per-node arrays every step
/// allocates over the whole grid (dof numbering, prescribed values, nodal
/// displacements and residuals, cell flags; Newton keeps several per
/// iteration). Measured: 1.2-1.5 kB with Newton.
pub fn bytes_per_grid_node(kind: crate::scene::AnalysisKind) -> u64 {
    match kind {
        crate::scene::AnalysisKind::QuasiStaticFinite | crate::scene::AnalysisKind::DynamicImplicit => 1_536,
        _ => 512,
    }
}

/// Estimated bytes per node a body may make active: its rows of the sparse
/// stiffness (or mass) matrix and of the Cholesky factor with fill-in
/// (measured: 1.5 kB per node at 1e4 nodes, 2.4 kB at 4e4; fill grows
/// slowly with size, which the step's own check covers).
pub const BYTES_PER_ACTIVE_NODE: u64 = 4_096;

impl Model {
    /// Validate a parsed scene and build the model with the default
    /// [`Limits`]. `text` and `file` are the scene's source, used to
    /// locate errors.
    pub fn build(scene: &Scene, text: &str, file: &str) -> Result<Model, SceneError> {
        Self::build_with(scene, text, file, &Limits::default())
    }

    /// [`Model::build`] with explicit resource limits.
    pub fn build_with(scene: &Scene, text: &str, file: &str, limits: &Limits) -> Result<Model, SceneError> {
        Self::build_unlocated(scene, limits).map_err(|e| Locator::new(text).error(file, e))
    }

    /// Parse and build from scene text in one go.
    pub fn from_text(text: &str, file: &str) -> Result<Model, SceneError> {
        let scene = Scene::parse(text, file)?;
        Self::build(&scene, text, file)
    }

    /// Validate and build, section by section in the order the errors are
    /// reported; errors name a field, not yet a line.
    fn build_unlocated(scene: &Scene, limits: &Limits) -> Result<Model, FieldError> {
        check_names(scene)?;
        let grid = build_grid(scene)?;
        let mut budget = Budget::new(scene, &grid, limits)?;

        let materials = materials::build(scene)?;
        let (bodies, regions, ranges, mut points) = bodies::build(scene, &grid, &materials, &mut budget)?;
        let dirichlet = conditions::dirichlet(scene, &grid)?;
        let (gravity, point_loads) = conditions::loads(scene, &grid, &points)?;

        validate_solver(&scene.analysis)?;
        let exact = build_exact_solution(scene, &materials, &bodies, gravity)?;

        check_curve_totals(scene)?;
        let mut boundaries: Vec<Boundary> = Vec::new();
        for (k, spec) in scene.boundaries.iter().enumerate() {
            if boundaries.iter().any(|b| b.name == spec.name) {
                return Err(FieldError::new(
                    format!("boundary[{k}].name"),
                    format!("boundary `{}` is defined twice", spec.name),
                ));
            }
            let b = build_boundary(k, spec, &grid, &bodies, &regions, &ranges, exact.is_some(), &mut points)?;
            boundaries.push(b);
        }

        validate_kind(scene, &dirichlet, &materials)?;
        let a = resolve_delta(&scene.analysis, &grid)?;
        let ibm = ibm::build(scene, &grid, &a, &boundaries, &points, &regions, exact.as_ref())?;
        let record = record::build(&scene.record, a.kind)?;
        let probes = probes::build(scene, &points, &regions, &boundaries, &ibm)?;

        Ok(Model {
            name: scene.scene.name.clone(),
            description: scene.scene.description.trim().to_string(),
            units: scene.scene.units,
            grid,
            materials,
            bodies,
            points,
            dirichlet,
            gravity,
            point_loads,
            boundaries,
            ibm,
            analysis: a,
            exact,
            record,
            probes,
            max_memory: limits.max_memory,
        })
    }
}

impl Model {
    /// The ghost mass penalty `gamma_M` (kg/m^3): the scene's, or a quarter
    /// of the largest material density (G 3.3) in explicit dynamics, a
    /// thousandth of that in implicit dynamics. There the ghost mass only
    /// makes the mass invertible for mapping the points' velocities (the
    /// tangent `K + M / (beta dt^2)` is conditioned by the ghost
    /// stiffness, G (27)), and every Newmark step's FLIP transfer loses
    /// `1/2 dv.gamma_M J_G dv` of kinetic energy ([`crate::implicit`]'s
    /// inertia): on G 5.2's collision at ten times the explicit step the
    /// energy lost falls from 35% at `rho/4` to 1.3% at `rho/4000`,
    /// while the mass' condition number grows from 1.4e2 to 3.6e4.
    pub fn gamma_m(&self) -> f64 {
        self.analysis.gamma_m.unwrap_or_else(|| self.default_gamma_m())
    }

    /// The analysis kind's default `gamma_M` (see [`Model::gamma_m`]).
    pub fn default_gamma_m(&self) -> f64 {
        let scale = match self.analysis.kind {
            crate::scene::AnalysisKind::DynamicImplicit => 0.25e-3,
            _ => 0.25,
        };
        scale * self.materials.iter().map(|m| m.density()).fold(0.0, f64::max)
    }
}

fn dist2(a: P2, b: P2) -> f64 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)
}

fn build_grid(scene: &Scene) -> Result<Grid, FieldError> {
    let g = &scene.grid;
    if !(g.h > 0.0 && g.h.is_finite()) {
        return Err(FieldError::new(
            "grid.h",
            format!("the cell size must be positive, got {}", number(g.h)),
        ));
    }
    if !g.origin.iter().all(|v| v.is_finite()) {
        return Err(FieldError::new("grid.origin", "must be finite"));
    }
    if !g.size.iter().all(|v| v.is_finite()) {
        return Err(FieldError::new("grid.size", "must be finite"));
    }
    // Cell counts stay floating point until they are known to be small.
    let s = [g.size[0] / g.h, g.size[1] / g.h];
    if s.iter().all(|s| s.is_finite() && *s >= 1.0 - 1e-9) && s[0] * s[1] > MAX_CELLS as f64 * (1.0 + 1e-9) {
        return Err(FieldError::new(
            "grid.h",
            format!(
                "a grid of size [{}, {}] with h = {} has {} x {} = {} cells, more than the {MAX_CELLS} supported; use a larger h",
                number(g.size[0]),
                number(g.size[1]),
                number(g.h),
                number(s[0].round()),
                number(s[1].round()),
                number(s[0].round() * s[1].round())
            ),
        ));
    }
    let mut n = [0usize; 2];
    for d in 0..2 {
        let s = s[d];
        if !(s.is_finite() && s >= 1.0 - 1e-9) || (s - s.round()).abs() > 1e-9 * s.max(1.0) {
            return Err(FieldError::new(
                "grid.size",
                format!(
                    "must be a positive whole number of cells of size h = {}, got {} ({} cells)",
                    number(g.h),
                    number(g.size[d]),
                    number(s)
                ),
            ));
        }
        n[d] = s.round() as usize;
    }
    Ok(Grid {
        origin: g.origin,
        h: g.h,
        nx: n[0],
        ny: n[1],
    })
}
