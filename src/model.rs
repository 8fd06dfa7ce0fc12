//! The model: a validated scene turned into grid, materials, bodies with
//! their material points, boundary conditions, loads and analysis settings.

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
    pub grid: Grid,
    pub materials: Vec<Material>,
    pub bodies: Vec<Body>,
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

/// Estimated bytes per material point while stepping: the point arrays,
/// its stencil (values, gradients, node indices), its constitutive
/// response and its share of the recorded and reported fields. Measured
/// peaks: 1.2 kB per point (a 10^6-point lattice, linear, standard basis,
/// recorded), 1.6 kB (GIMP with Newton; explicit dynamics).
pub const BYTES_PER_POINT: u64 = 4_096;
/// Estimated bytes per grid node, for the per-node arrays every step
/// allocates over the whole grid (dof numbering, prescribed values, nodal
/// displacements and residuals, cell flags).
pub const BYTES_PER_GRID_NODE: u64 = 512;
/// Estimated bytes per node a body may make active: its rows of the sparse
/// stiffness (or mass) matrix and of the Cholesky factor with fill-in
/// (measured: about 3.5 kB per node for 1.6e5 active nodes).
pub const BYTES_PER_ACTIVE_NODE: u64 = 8_192;

/// Resource limits applied when a model is built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    /// Largest memory estimate accepted (bytes).
    pub max_memory: u64,
}

impl Default for Limits {
    /// Half of the memory available now (`MemAvailable` in /proc/meminfo),
    /// or 4 GiB where that cannot be read.
    fn default() -> Self {
        Limits {
            max_memory: available_memory().map_or(4 << 30, |m| m / 2),
        }
    }
}

/// `MemAvailable` of /proc/meminfo (bytes).
pub fn available_memory() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let kb: u64 = text
        .lines()
        .find_map(|l| l.strip_prefix("MemAvailable:"))?
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()?;
    kb.checked_mul(1024)
}

/// Bytes in words: `512 B`, `3.2 MB`, `18.4 GB` (powers of 1000).
pub fn bytes(b: u64) -> String {
    let b = b as f64;
    match b {
        b if b < 1e3 => format!("{b} B"),
        b if b < 1e6 => format!("{:.1} kB", b / 1e3),
        b if b < 1e9 => format!("{:.1} MB", b / 1e6),
        b if b < 1e12 => format!("{:.1} GB", b / 1e9),
        b => format!("{:.1} TB", b / 1e12),
    }
}

/// Parse a memory size: bytes, or with a suffix `k`, `M`, `G`, `T`
/// (powers of 1024, optionally followed by `B` or `iB`).
pub fn parse_bytes(s: &str) -> Result<u64, String> {
    let t = s.trim();
    let digits = t.find(|c: char| !(c.is_ascii_digit() || c == '.')).unwrap_or(t.len());
    let (num, unit) = t.split_at(digits);
    let x: f64 = num
        .parse()
        .map_err(|_| format!("`{s}` is not a size (examples: 512M, 4G, 1000000)"))?;
    let scale: f64 = match unit.trim().trim_end_matches("iB").trim_end_matches('B') {
        "" => 1.0,
        "k" | "K" => 1024.0,
        "m" | "M" => 1024.0 * 1024.0,
        "g" | "G" => 1024.0 * 1024.0 * 1024.0,
        "t" | "T" => 1024.0 * 1024.0 * 1024.0 * 1024.0,
        _ => return Err(format!("`{s}`: unknown unit `{unit}` (use k, M, G or T)")),
    };
    let b = x * scale;
    if !(1.0..1.8e19).contains(&b) {
        return Err(format!("`{s}` is not a usable memory size"));
    }
    Ok(b as u64)
}

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

    fn build_unlocated(scene: &Scene, limits: &Limits) -> Result<Model, FieldError> {
        check_names(scene)?;
        let grid = build_grid(scene)?;
        let mut budget = Budget::new(scene, &grid, limits)?;

        let mut materials: Vec<Material> = Vec::new();
        if scene.materials.is_empty() {
            return Err(FieldError::new("material", "at least one [[material]] is needed"));
        }
        let finite_kind = scene.analysis.kind != crate::scene::AnalysisKind::QuasiStaticLinear;
        for (k, m) in scene.materials.iter().enumerate() {
            let f = |n: &str| format!("material[{k}].{n}");
            if materials.iter().any(|x| x.name == m.name) {
                return Err(FieldError::new(
                    f("name"),
                    format!("material `{}` is defined twice", m.name),
                ));
            }
            let ys = match m.model {
                MaterialModel::LinearElastic => {
                    if m.yield_stress.is_some() {
                        return Err(FieldError::new(f("yield_stress"), "only for model = \"von-mises\""));
                    }
                    None
                }
                MaterialModel::VonMises => {
                    if !finite_kind {
                        return Err(FieldError::new(
                            f("model"),
                            "von Mises plasticity needs kind = \"quasi-static-finite\" or \"explicit-dynamics\"",
                        ));
                    }
                    match m.yield_stress {
                        Some(y) if y > 0.0 && y.is_finite() => Some(y),
                        _ => {
                            return Err(FieldError::new(
                                f("yield_stress"),
                                "von Mises needs a positive yield_stress",
                            ))
                        }
                    }
                }
            };
            if finite_kind && m.plane != crate::scene::Plane::Strain {
                return Err(FieldError::new(
                    f("plane"),
                    "the finite-deformation and explicit analyses are plane strain",
                ));
            }
            // Explicit dynamics needs no stiffness matrix: E = 0 is a
            // stress-free material (G 5.1.2's stretching ghost).
            let explicit = scene.analysis.kind == crate::scene::AnalysisKind::ExplicitDynamics;
            if !((m.e > 0.0 || (explicit && m.e == 0.0)) && m.e.is_finite()) {
                return Err(FieldError::new(
                    f("E"),
                    format!(
                        "Young's modulus must be positive{}, got {}",
                        if explicit { " or zero" } else { "" },
                        number(m.e)
                    ),
                ));
            }
            if !(m.nu > -1.0 && m.nu < 0.5) {
                return Err(FieldError::new(
                    f("nu"),
                    format!("Poisson's ratio must lie in (-1, 0.5), got {}", number(m.nu)),
                ));
            }
            if !(m.density >= 0.0 && m.density.is_finite()) {
                return Err(FieldError::new(f("density"), "must be non-negative"));
            }
            materials.push(Material {
                name: m.name.clone(),
                elastic: LinearElastic {
                    e: m.e,
                    nu: m.nu,
                    density: m.density,
                    plane: m.plane,
                },
                yield_stress: ys,
            });
        }

        if scene.bodies.is_empty() {
            return Err(FieldError::new("body", "at least one [[body]] is needed"));
        }
        let mut bodies = Vec::new();
        let mut regions = Vec::new();
        let mut ranges = Vec::new();
        let mut points = Points::default();
        for (k, b) in scene.bodies.iter().enumerate() {
            let f = |n: &str| format!("body[{k}].{n}");
            let material = materials
                .iter()
                .position(|m| m.name == b.material)
                .ok_or_else(|| FieldError::new(f("material"), format!("no material named `{}`", b.material)))?;
            if !(1..=64).contains(&b.points_per_cell) {
                return Err(FieldError::new(f("points_per_cell"), "must be between 1 and 64"));
            }
            if b.placement == Placement::Gauss && b.basis != BasisKind::Standard {
                return Err(FieldError::new(
                    f("placement"),
                    "gauss placement needs the standard basis",
                ));
            }
            let region = b.region.build(&f("region"))?;
            let (min, max) = region.bounds();
            let gmax = grid.max();
            let tol = 1e-9 * grid.h;
            if !(min[0] >= grid.origin[0] - tol
                && min[1] >= grid.origin[1] - tol
                && max[0] <= gmax[0] + tol
                && max[1] <= gmax[1] + tol)
            {
                return Err(FieldError::new(
                    f("region"),
                    format!(
                        "the region [{}, {}] x [{}, {}] extends outside the grid [{}, {}] x [{}, {}]: its points would lie outside the grid",
                        short(min[0]), short(max[0]), short(min[1]), short(max[1]),
                        short(grid.origin[0]), short(gmax[0]), short(grid.origin[1]), short(gmax[1])
                    ),
                ));
            }
            budget.body(k, b, &region, &grid)?;
            let before = points.len();
            let density = materials[material].density();
            if b.placement == Placement::Polar {
                polar_points(b, density, k, &mut points).map_err(|(field, m)| FieldError::new(f(field), m))?;
            } else if b.placement == Placement::Lattice {
                lattice_points(b, &region, density, k, &mut points)
                    .map_err(|(field, m)| FieldError::new(f(field), m))?;
            } else {
                generate_points(&grid, &region, b.points_per_cell, b.placement, density, k, &mut points)
                    .map_err(|m| FieldError::new(f("placement"), m))?;
            }
            if points.len() == before {
                return Err(FieldError::new(
                    f("region"),
                    "the body is empty: no cell overlaps its region",
                ));
            }
            let moving = b.velocity != [0.0; 2] || b.velocity_gradient.is_some();
            if moving && scene.analysis.kind != crate::scene::AnalysisKind::ExplicitDynamics {
                return Err(FieldError::new(
                    f("velocity"),
                    "initial velocities need kind = \"explicit-dynamics\"",
                ));
            }
            let l = b.velocity_gradient.unwrap_or([[0.0; 2]; 2]);
            if !b
                .velocity
                .iter()
                .chain(l.iter().flatten())
                .chain(&b.velocity_centre)
                .all(|v| v.is_finite())
            {
                return Err(FieldError::new(f("velocity"), "velocities must be finite"));
            }
            let c = b.velocity_centre;
            for p in before..points.len() {
                let d = [points.x[p][0] - c[0], points.x[p][1] - c[1]];
                points.v[p] = [
                    b.velocity[0] + l[0][0] * d[0] + l[0][1] * d[1],
                    b.velocity[1] + l[1][0] * d[0] + l[1][1] * d[1],
                ];
            }
            if b.basis == BasisKind::Gimp {
                for p in before..points.len() {
                    let (x, l) = (points.x[p], points.lp[p]);
                    if x[0] - l[0] < grid.origin[0] - tol
                        || x[1] - l[1] < grid.origin[1] - tol
                        || x[0] + l[0] > gmax[0] + tol
                        || x[1] + l[1] > gmax[1] + tol
                    {
                        return Err(FieldError::new(
                            f("region"),
                            "GIMP point domains reach outside the grid",
                        ));
                    }
                }
            }
            ranges.push(before..points.len());
            regions.push(region.clone());
            bodies.push(Body {
                name: b.name.clone(),
                material,
                basis: b.basis,
                points_per_cell: b.points_per_cell,
                region_area: region.area(),
            });
        }

        let mut dirichlet = Vec::new();
        for (k, d) in scene.dirichlet.iter().enumerate() {
            let f = |n: &str| format!("dirichlet[{k}].{n}");
            let (target, axis) = match (d.x, d.y, d.node) {
                (Some(x), None, None) => (
                    GridTarget::Line {
                        axis: 0,
                        index: grid
                            .line_index(0, x)
                            .ok_or_else(|| FieldError::new(f("x"), format!("x = {} is not a grid line", number(x))))?,
                    },
                    0,
                ),
                (None, Some(y), None) => (
                    GridTarget::Line {
                        axis: 1,
                        index: grid
                            .line_index(1, y)
                            .ok_or_else(|| FieldError::new(f("y"), format!("y = {} is not a grid line", number(y))))?,
                    },
                    1,
                ),
                (None, None, Some(at)) => {
                    if d.kind != DirichletKind::Fixed {
                        return Err(FieldError::new(f("kind"), "a condition on one node must be `fixed`"));
                    }
                    let (i, j) = (grid.line_index(0, at[0]), grid.line_index(1, at[1]));
                    let (Some(i), Some(j)) = (i, j) else {
                        return Err(FieldError::new(
                            f("node"),
                            format!("[{}, {}] is not a grid node", number(at[0]), number(at[1])),
                        ));
                    };
                    (GridTarget::Node(grid.node(i, j)), 0)
                }
                _ => {
                    return Err(FieldError::new(
                        format!("dirichlet[{k}]"),
                        "give exactly one of `x`, `y` or `node`",
                    ))
                }
            };
            let value = match d.kind {
                DirichletKind::Fixed => {
                    if d.normal_displacement.is_some() {
                        return Err(FieldError::new(
                            f("normal_displacement"),
                            "only for rollers; use `displacement`",
                        ));
                    }
                    let u = d.displacement.unwrap_or([0.0; 2]);
                    if !u.iter().all(|v| v.is_finite()) {
                        return Err(FieldError::new(f("displacement"), "must be finite"));
                    }
                    [Some(u[0]), Some(u[1])]
                }
                DirichletKind::Roller => {
                    if d.displacement.is_some() {
                        return Err(FieldError::new(
                            f("displacement"),
                            "only for fixed; use `normal_displacement`",
                        ));
                    }
                    let u = d.normal_displacement.unwrap_or(0.0);
                    if !u.is_finite() {
                        return Err(FieldError::new(f("normal_displacement"), "must be finite"));
                    }
                    let mut v = [None, None];
                    v[axis] = Some(u);
                    v
                }
            };
            dirichlet.push(GridDirichlet { target, value });
        }

        let gravity = scene.loads.gravity.unwrap_or([0.0; 2]);
        if !gravity.iter().all(|g| g.is_finite()) {
            return Err(FieldError::new("loads.gravity", "must be finite"));
        }
        let mut point_loads = Vec::new();
        if scene.loads.point.len() > MAX_POINT_LOADS {
            return Err(FieldError::new(
                "loads.point",
                format!(
                    "{} point loads are more than the {MAX_POINT_LOADS} supported",
                    scene.loads.point.len()
                ),
            ));
        }
        if (scene.loads.point.len() as u128) * (points.len() as u128) > MAX_GENERATION_WORK {
            return Err(FieldError::new(
                "loads.point",
                format!(
                    "finding the nearest of {} points for each of {} point loads is more than the {MAX_GENERATION_WORK} tests allowed; use fewer point loads",
                    points.len(),
                    scene.loads.point.len()
                ),
            ));
        }
        for (k, l) in scene.loads.point.iter().enumerate() {
            if !l.at.iter().all(|v| v.is_finite()) {
                return Err(FieldError::new(format!("loads.point[{k}].at"), "must be finite"));
            }
            if !l.force.iter().all(|v| v.is_finite()) {
                return Err(FieldError::new(format!("loads.point[{k}].force"), "must be finite"));
            }
            if grid.cell_of(l.at).is_none() {
                return Err(FieldError::new(format!("loads.point[{k}].at"), "lies outside the grid"));
            }
            let point = (0..points.len())
                .filter(|&p| points.vol[p] > 0.0)
                .min_by(|&a, &b| dist2(points.x[a], l.at).total_cmp(&dist2(points.x[b], l.at)))
                .expect("bodies are non-empty");
            point_loads.push(PointLoad { point, force: l.force });
        }

        let a = &scene.analysis;
        if !(1..=1_000_000).contains(&a.load_steps) {
            return Err(FieldError::new("analysis.load_steps", "must be between 1 and 1000000"));
        }
        if !(a.tolerance > 0.0 && a.tolerance < 1.0) {
            return Err(FieldError::new("analysis.tolerance", "must lie in (0, 1)"));
        }
        if !(1..=1000).contains(&a.max_iterations) {
            return Err(FieldError::new("analysis.max_iterations", "must be between 1 and 1000"));
        }
        if !(a.gamma_k >= 0.0 && a.gamma_k.is_finite()) {
            return Err(FieldError::new("analysis.gamma_k", "must be zero (off) or positive"));
        }
        if a.fbar && a.kind != crate::scene::AnalysisKind::QuasiStaticFinite {
            return Err(FieldError::new(
                "analysis.fbar",
                "F-bar modifies the finite-deformation (Newton) path only: kind = \"quasi-static-finite\"",
            ));
        }
        if a.dense_limit > MAX_DENSE_LIMIT {
            return Err(FieldError::new(
                "analysis.dense_limit",
                format!("must be at most {MAX_DENSE_LIMIT}, got {}", a.dense_limit),
            ));
        }
        if !a.blowup_factor.is_finite() {
            return Err(FieldError::new("analysis.blowup_factor", "must be finite"));
        }

        let exact = match &scene.exact {
            None => None,
            Some(ExactSpec::FreeMotion {}) => {
                let duration = match (scene.analysis.kind, scene.analysis.duration) {
                    (crate::scene::AnalysisKind::ExplicitDynamics, Some(d)) => d,
                    _ => {
                        return Err(FieldError::new(
                            "exact.name",
                            "free-motion needs kind = \"explicit-dynamics\" with a duration",
                        ))
                    }
                };
                let strained = bodies
                    .iter()
                    .zip(&scene.bodies)
                    .any(|(b, spec)| materials[b.material].elastic.e != 0.0 && spec.velocity_gradient.is_some());
                if strained {
                    return Err(FieldError::new(
                        "exact.name",
                        "free motion with a velocity gradient is exact only for stress-free (E = 0) bodies",
                    ));
                }
                let fields = scene
                    .bodies
                    .iter()
                    .map(|b| {
                        (
                            b.velocity,
                            b.velocity_gradient.unwrap_or([[0.0; 2]; 2]),
                            b.velocity_centre,
                        )
                    })
                    .collect();
                Some(ExactSolution::FreeMotion { fields, duration })
            }
            Some(spec) => Some(build_exact(spec, &materials, &bodies, gravity)?),
        };

        // Tracking points of all boundaries, and vertices of all implicit
        // boundaries, together.
        let mut total = 0usize;
        for (k, b) in scene.boundaries.iter().enumerate() {
            total = total.saturating_add(b.points.as_ref().map_or(0, Vec::len));
            if total > MAX_CURVE_POINTS {
                return Err(FieldError::new(
                    format!("boundary[{k}].points"),
                    format!("the boundaries have more than the {MAX_CURVE_POINTS} tracking points supported in all"),
                ));
            }
        }
        let mut total = 0usize;
        for (k, b) in scene.ibm.iter().enumerate() {
            total = total.saturating_add(b.points.len());
            if total > MAX_CURVE_POINTS {
                return Err(FieldError::new(
                    format!("ibm[{k}].points"),
                    format!("the implicit boundaries have more than the {MAX_CURVE_POINTS} points supported in all"),
                ));
            }
        }
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

        if a.kind == crate::scene::AnalysisKind::ExplicitDynamics {
            validate_explicit(a, &dirichlet)?;
            // Explicit dynamics divides by mass: every material needs density.
            if let Some(k) = materials.iter().position(|m| !(m.density() > 0.0)) {
                return Err(FieldError::new(
                    format!("material[{k}].density"),
                    "explicit dynamics needs a positive density",
                ));
            }
            // Static exact solutions grow with the load factor; explicit
            // loads act in full from the start, so only free motion applies.
            if matches!(scene.exact, Some(ref e) if !matches!(e, ExactSpec::FreeMotion {})) {
                return Err(FieldError::new(
                    "exact.name",
                    "explicit dynamics supports the free-motion exact solution only",
                ));
            }
        } else if a.duration.is_some() {
            return Err(FieldError::new(
                "analysis.duration",
                "only for kind = \"explicit-dynamics\"",
            ));
        }
        let mut a = a.clone();
        if let Some(d) = a.delta {
            if !(d > 0.0 && d <= grid.h) {
                return Err(FieldError::new("analysis.delta", "must lie in (0, h]"));
            }
            a.delta_over_h = d / grid.h;
        }
        if !(a.delta_over_h > 0.0 && a.delta_over_h <= 1.0) {
            return Err(FieldError::new("analysis.delta_over_h", "must lie in (0, 1]"));
        }
        let mut ibm = Vec::new();
        for (k, spec) in scene.ibm.iter().enumerate() {
            let f = |n: &str| format!("ibm[{k}].{n}");
            if a.kind == crate::scene::AnalysisKind::ExplicitDynamics {
                // C (17)-(27) enforce the condition through the band's
                // stiffness in an implicit equilibrium solve; an explicit
                // step solves only M a = f and has no stiffness to carry it.
                return Err(FieldError::new(
                    f("kind"),
                    "the implicit boundary method (Cortis et al. 2018) acts through the stiffness of an implicit \
                     solve; explicit dynamics has none: use a quasi-static analysis or grid-line supports",
                ));
            }
            let (poly, spline) = match (&spec.boundary, spec.points.is_empty()) {
                (Some(name), true) => {
                    let idx = boundaries
                        .iter()
                        .position(|b| &b.name == name)
                        .ok_or_else(|| FieldError::new(f("boundary"), format!("no [[boundary]] named `{name}`")))?;
                    if !(1..=256).contains(&spec.per_segment) {
                        return Err(FieldError::new(f("per_segment"), "must be between 1 and 256"));
                    }
                    let s = boundaries[idx]
                        .spline(&points)
                        .map_err(|e| FieldError::new(f("boundary"), e.to_string()))?;
                    if s.segments.len().saturating_mul(spec.per_segment) > MAX_CURVE_POINTS {
                        return Err(FieldError::new(
                            f("per_segment"),
                            format!(
                                "{} segments x {} chords are more than the {MAX_CURVE_POINTS} vertices a polyline may have",
                                s.segments.len(),
                                spec.per_segment
                            ),
                        ));
                    }
                    (s.sample(spec.per_segment), Some((idx, spec.per_segment)))
                }
                (None, false) => (spec.points.clone(), None),
                _ => {
                    return Err(FieldError::new(
                        format!("ibm[{k}]"),
                        "give exactly one of `points` or `boundary`",
                    ))
                }
            };
            if spec.points.len() > MAX_CURVE_POINTS {
                return Err(FieldError::new(
                    f("points"),
                    format!(
                        "{} points are more than the {MAX_CURVE_POINTS} a polyline may have",
                        spec.points.len()
                    ),
                ));
            }
            if poly.len() < 2 || !poly.iter().flatten().all(|v| v.is_finite()) {
                return Err(FieldError::new(
                    f("points"),
                    "a polyline needs at least 2 finite points",
                ));
            }
            // The boundary's cells and its band must be cells of the grid.
            let gmax = grid.max();
            let tol = 1e-9 * grid.h;
            if let Some((i, p)) = poly.iter().enumerate().find(|(_, p)| {
                !(p[0] >= grid.origin[0] - tol
                    && p[1] >= grid.origin[1] - tol
                    && p[0] <= gmax[0] + tol
                    && p[1] <= gmax[1] + tol)
            }) {
                let what = if spec.boundary.is_some() {
                    format!(
                        "the curve of boundary `{}`",
                        spec.boundary.as_deref().unwrap_or_default()
                    )
                } else {
                    format!("point {i}")
                };
                return Err(FieldError::new(
                    if spec.boundary.is_some() {
                        f("boundary")
                    } else {
                        f("points")
                    },
                    format!(
                        "{what} at ({}, {}) lies outside the grid [{}, {}] x [{}, {}]",
                        short(p[0]),
                        short(p[1]),
                        short(grid.origin[0]),
                        short(gmax[0]),
                        short(grid.origin[1]),
                        short(gmax[1])
                    ),
                ));
            }
            if poly.windows(2).any(|w| w[0] == w[1]) {
                return Err(FieldError::new(f("points"), "consecutive points coincide"));
            }
            if !(1..=20).contains(&spec.gauss_points) {
                return Err(FieldError::new(f("gauss_points"), "must be between 1 and 20"));
            }
            let value = match spec.kind {
                DirichletKind::Fixed => {
                    if spec.normal_displacement.is_some() {
                        return Err(FieldError::new(
                            f("normal_displacement"),
                            "only for rollers; use `displacement`",
                        ));
                    }
                    let u = spec.displacement.unwrap_or([0.0; 2]);
                    if !u.iter().all(|v| v.is_finite()) {
                        return Err(FieldError::new(f("displacement"), "must be finite"));
                    }
                    u
                }
                DirichletKind::Roller => {
                    if spec.displacement.is_some() {
                        return Err(FieldError::new(
                            f("displacement"),
                            "only for fixed; use `normal_displacement`",
                        ));
                    }
                    let u = spec.normal_displacement.unwrap_or(0.0);
                    if !u.is_finite() {
                        return Err(FieldError::new(f("normal_displacement"), "must be finite"));
                    }
                    [u, 0.0]
                }
            };
            if !(spec.fit_regularisation >= 0.0 && spec.fit_regularisation < 1.0) {
                return Err(FieldError::new(f("fit_regularisation"), "must lie in [0, 1)"));
            }
            if spec.exact_field {
                if spec.kind != DirichletKind::Fixed || spec.displacement.is_some() {
                    return Err(FieldError::new(
                        f("exact_field"),
                        "only for fixed boundaries without `displacement`",
                    ));
                }
                if exact.is_none() {
                    return Err(FieldError::new(f("exact_field"), "needs an [exact] solution"));
                }
            }
            let mut b = IbmBoundary {
                name: spec.name.clone(),
                kind: spec.kind,
                points: poly.clone(),
                side: 1.0,
                value,
                gauss_points: spec.gauss_points,
                exact_field: spec.exact_field,
                fit_regularisation: spec.fit_regularisation,
                moves: spec.moves,
                spline,
            };
            if spec.moves {
                // A moving roller translates along its one normal.
                let straight = poly.windows(3).all(|w| {
                    let (a, b) = (
                        [w[1][0] - w[0][0], w[1][1] - w[0][1]],
                        [w[2][0] - w[1][0], w[2][1] - w[1][1]],
                    );
                    (a[0] * b[1] - a[1] * b[0]).abs() <= 1e-9 * a[0].hypot(a[1]) * b[0].hypot(b[1])
                        && a[0] * b[0] + a[1] * b[1] > 0.0
                });
                let ok = match spec.kind {
                    DirichletKind::Fixed => !spec.exact_field,
                    DirichletKind::Roller => straight && spec.boundary.is_none(),
                };
                if !ok {
                    return Err(FieldError::new(
                        f("moves"),
                        "only fixed boundaries with a uniform displacement, or straight rollers, can move",
                    ));
                }
            }
            b.side = match spec.material_side {
                Some(MaterialSide::Left) => 1.0,
                Some(MaterialSide::Right) => -1.0,
                None => {
                    let mid = poly.len() / 2 - 1;
                    let (p0, p1) = (poly[mid], poly[mid + 1]);
                    let m = [0.5 * (p0[0] + p1[0]), 0.5 * (p0[1] + p1[1])];
                    let n = b.normal(p0, p1); // left normal for side = +1
                    let inside = |x: P2| regions.iter().any(|r| r.contains(x));
                    let mut side = None;
                    for eps in [0.01, 0.05, 0.25, 0.5, 1.0] {
                        let d = eps * grid.h;
                        match (
                            inside([m[0] + d * n[0], m[1] + d * n[1]]),
                            inside([m[0] - d * n[0], m[1] - d * n[1]]),
                        ) {
                            (true, false) => side = Some(1.0),
                            (false, true) => side = Some(-1.0),
                            _ => continue,
                        }
                        break;
                    }
                    side.ok_or_else(|| {
                        FieldError::new(
                            f("material_side"),
                            "cannot tell which side the material is on; give material_side",
                        )
                    })?
                }
            };
            ibm.push(b);
        }

        Ok(Model {
            name: scene.scene.name.clone(),
            description: scene.scene.description.trim().to_string(),
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
        })
    }
}

/// Settings an explicit-dynamics analysis needs.
fn validate_explicit(a: &AnalysisSpec, dirichlet: &[GridDirichlet]) -> Result<(), FieldError> {
    match a.duration {
        Some(d) if d > 0.0 && d.is_finite() => {}
        Some(_) => return Err(FieldError::new("analysis.duration", "must be positive")),
        None => {
            return Err(FieldError::new(
                "analysis.duration",
                "explicit dynamics needs the simulated time `duration` (s)",
            ))
        }
    }
    if let Some(g) = a.gamma_m {
        if !(g >= 0.0 && g.is_finite()) {
            return Err(FieldError::new("analysis.gamma_m", "must be zero (off) or positive"));
        }
    }
    if !(a.blowup_factor > 1.0) {
        return Err(FieldError::new("analysis.blowup_factor", "must exceed 1"));
    }
    if dirichlet.iter().any(|d| d.value.iter().flatten().any(|v| *v != 0.0)) {
        return Err(FieldError::new(
            "dirichlet",
            "explicit dynamics supports fixed and roller supports only (zero values)",
        ));
    }
    Ok(())
}

impl Model {
    /// The ghost mass penalty `gamma_M` (kg/m^3): the scene's, or a quarter
    /// of the largest material density (G 3.3).
    pub fn gamma_m(&self) -> f64 {
        self.analysis
            .gamma_m
            .unwrap_or_else(|| 0.25 * self.materials.iter().map(|m| m.density()).fold(0.0, f64::max))
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

/// A coordinate for a message: four decimals when that shows it, else
/// [`number`].
fn short(x: f64) -> String {
    let a = x.abs();
    if x == 0.0 || (1e-3..1e9).contains(&a) {
        format!("{x:.4}")
    } else {
        number(x)
    }
}

/// What a scene may name, and where.
fn check_name(field: &str, name: &str) -> Result<(), FieldError> {
    if name.trim().is_empty() {
        return Err(FieldError::new(field, "must not be empty"));
    }
    if name.chars().count() > MAX_NAME {
        return Err(FieldError::new(
            field,
            format!(
                "is {} characters long; names have at most {MAX_NAME}",
                name.chars().count()
            ),
        ));
    }
    if name.chars().any(|c| c.is_control() || c == '/' || c == '\\') {
        return Err(FieldError::new(
            field,
            "must not contain `/`, `\\` or control characters (names become recording paths)",
        ));
    }
    Ok(())
}

/// Names are well-formed, and unique across materials, bodies, B-spline
/// boundaries and implicit boundaries: a name refers to one thing.
fn check_names(scene: &Scene) -> Result<(), FieldError> {
    for (table, n, cap) in [
        ("material", scene.materials.len(), MAX_ENTRIES),
        ("body", scene.bodies.len(), MAX_ENTRIES),
        ("boundary", scene.boundaries.len(), MAX_ENTRIES),
        ("ibm", scene.ibm.len(), MAX_ENTRIES),
        ("dirichlet", scene.dirichlet.len(), 10 * MAX_ENTRIES),
    ] {
        if n > cap {
            return Err(FieldError::new(
                format!("{table}[{cap}]"),
                format!("{n} [[{table}]] entries are more than the {cap} supported"),
            ));
        }
    }
    check_name("scene.name", &scene.scene.name)?;
    if scene.scene.name.starts_with('.') {
        return Err(FieldError::new(
            "scene.name",
            "must not start with `.` (it names recording files)",
        ));
    }
    let mut seen: std::collections::HashMap<&str, String> = std::collections::HashMap::new();
    let named = scene
        .materials
        .iter()
        .enumerate()
        .map(|(k, m)| (format!("material[{k}]"), &m.name))
        .chain(
            scene
                .bodies
                .iter()
                .enumerate()
                .map(|(k, b)| (format!("body[{k}]"), &b.name)),
        )
        .chain(
            scene
                .boundaries
                .iter()
                .enumerate()
                .map(|(k, b)| (format!("boundary[{k}]"), &b.name)),
        )
        .chain(
            scene
                .ibm
                .iter()
                .enumerate()
                .map(|(k, b)| (format!("ibm[{k}]"), &b.name)),
        );
    for (at, name) in named {
        let field = format!("{at}.name");
        check_name(&field, name)?;
        if let Some(first) = seen.get(name.as_str()) {
            return Err(FieldError::new(
                field,
                format!("the name `{name}` is already used by {first}; names must be unique"),
            ));
        }
        seen.insert(name.as_str(), at);
    }
    Ok(())
}

/// The memory estimate of a model, grown body by body before each body's
/// points are generated, and the work of generating them.
struct Budget {
    max: u64,
    grid_nodes: u128,
    points: u128,
    active: u128,
    condition: crate::scene::ConditionMode,
    dense_limit: u128,
}

impl Budget {
    fn new(scene: &Scene, grid: &Grid, limits: &Limits) -> Result<Budget, FieldError> {
        let b = Budget {
            max: limits.max_memory,
            grid_nodes: grid.num_nodes() as u128,
            points: 0,
            active: 0,
            condition: scene.analysis.condition,
            dense_limit: scene.analysis.dense_limit as u128,
        };
        b.check("grid.h".into(), "use a larger grid h or a smaller grid size")?;
        Ok(b)
    }

    /// Bytes of a dense eigenproblem over the estimated unknowns (the
    /// matrix, its eigenvectors and workspace).
    fn dense(&self) -> u128 {
        let dofs = 2 * self.active.min(self.grid_nodes);
        let n = match self.condition {
            crate::scene::ConditionMode::Dense => dofs,
            crate::scene::ConditionMode::Auto => dofs.min(self.dense_limit),
            _ => 0,
        };
        3 * 8 * n * n
    }

    fn total(&self) -> u128 {
        self.grid_nodes * BYTES_PER_GRID_NODE as u128
            + self.points * BYTES_PER_POINT as u128
            + self.active.min(self.grid_nodes) * BYTES_PER_ACTIVE_NODE as u128
            + self.dense()
    }

    fn check(&self, field: String, advice: &str) -> Result<(), FieldError> {
        let total = self.total();
        if total <= self.max as u128 {
            return Ok(());
        }
        let dense = self.dense();
        let points = self.points * BYTES_PER_POINT as u128;
        // Name what dominates: dense eigenvalues, the points or the grid.
        let (field, advice) = if dense >= points && dense * 2 >= total {
            (
                "analysis.condition".to_string(),
                "use condition = \"lanczos\" or \"off\", or a smaller dense_limit",
            )
        } else if points * 2 >= total {
            (field, advice)
        } else {
            ("grid.h".to_string(), "use a larger grid h")
        };
        Err(FieldError::new(
            field,
            format!(
                "the model needs an estimated {} ({} points x {} + {} grid nodes x {} + {} active nodes x {}{}), more than the {} allowed (--max-memory; default half of the available memory); {advice}",
                bytes(total.min(u64::MAX as u128) as u64),
                self.points,
                bytes(BYTES_PER_POINT),
                self.grid_nodes,
                bytes(BYTES_PER_GRID_NODE),
                self.active.min(self.grid_nodes),
                bytes(BYTES_PER_ACTIVE_NODE),
                if dense > 0 {
                    format!(" + dense eigenvalues {}", bytes(dense.min(u64::MAX as u128) as u64))
                } else {
                    String::new()
                },
                bytes(self.max)
            ),
        ))
    }

    /// Add body `k` (its region built): its points (an upper bound) and the
    /// nodes its region's bounding box covers; refuse it when the counts
    /// exceed the caps, the generation work is too large, or the estimate
    /// exceeds the budget.
    fn body(&mut self, k: usize, b: &BodySpec, region: &Region, grid: &Grid) -> Result<(), FieldError> {
        let f = |n: &str| format!("body[{k}].{n}");
        let (min, max) = region.bounds();
        let h = grid.h;
        let cells = |d: usize, nc: usize| -> u128 {
            let lo = ((min[d] - grid.origin[d]) / h).floor().clamp(0.0, nc as f64);
            let hi = ((max[d] - grid.origin[d]) / h).ceil().clamp(0.0, nc as f64);
            (hi - lo).max(0.0) as u128
        };
        let (cx, cy) = (cells(0, grid.nx), cells(1, grid.ny));
        let pieces = region.pieces.len().max(1) as u128;
        let (count, field, advice, work) = match b.placement {
            Placement::Polar => {
                let (nr, nc) = (
                    b.radial_points.unwrap_or(0) as u128,
                    b.circumferential_points.unwrap_or(0) as u128,
                );
                (
                    nr * nc,
                    f("radial_points"),
                    "use fewer radial_points or circumferential_points",
                    0,
                )
            }
            Placement::Lattice => {
                let [nx, ny] = b.lattice.unwrap_or([0, 0]);
                let n = nx as u128 * ny as u128;
                let rectangle = matches!(b.region, RegionSpec::Rectangle { .. });
                (
                    n,
                    f("lattice"),
                    "use a coarser lattice",
                    if rectangle { 0 } else { n * pieces },
                )
            }
            _ => {
                let n = b.points_per_cell as u128;
                (
                    cx * cy * n * n,
                    f("points_per_cell"),
                    "use fewer points_per_cell or a larger grid h",
                    cx * cy * pieces,
                )
            }
        };
        if self.points + count > MAX_POINTS as u128 {
            return Err(FieldError::new(
                field,
                format!(
                    "this body would have up to {count} points{}, more than the {MAX_POINTS} a model may have; {advice}",
                    if self.points > 0 { format!(" besides the {} before it", self.points) } else { String::new() }
                ),
            ));
        }
        if work > MAX_GENERATION_WORK {
            return Err(FieldError::new(
                f("region"),
                format!(
                    "placing points would test {} cells or lattice points against {pieces} region pieces, more than the {MAX_GENERATION_WORK} tests allowed; simplify the region or {advice}",
                    work / pieces
                ),
            ));
        }
        self.points += count;
        // GIMP domains reach one node row further each way.
        self.active += (cx + 3) * (cy + 3);
        self.check(field, advice)
    }
}

fn build_exact(
    spec: &ExactSpec,
    materials: &[Material],
    bodies: &[Body],
    gravity: P2,
) -> Result<ExactSolution, FieldError> {
    let values: Vec<f64> = match *spec {
        ExactSpec::ColumnFinite { base, top } | ExactSpec::ColumnSelfWeight { base, top } => vec![base, top],
        ExactSpec::UniaxialY { strain_yy, anchor } => vec![strain_yy, anchor[0], anchor[1]],
        ExactSpec::ConfinedY {
            stress_yy,
            base,
            angle_deg,
            about,
        } => vec![stress_yy, base, angle_deg, about[0], about[1]],
        ExactSpec::ConfinedYFinite {
            stretch,
            base,
            angle_deg,
            about,
        } => vec![stretch, base, angle_deg, about[0], about[1]],
        ExactSpec::Lame {
            pressure,
            r_inner,
            r_outer,
            center,
        } => vec![pressure, r_inner, r_outer, center[0], center[1]],
        ExactSpec::Kirsch { stress, radius } => vec![stress, radius],
        ExactSpec::SimpleShear { shear, x0 } => vec![shear, x0],
        ExactSpec::FreeMotion {} => Vec::new(),
    };
    if !values.iter().all(|v| v.is_finite()) {
        return Err(FieldError::new("exact", "parameters must be finite"));
    }
    let material = materials[bodies[0].material].elastic;
    if bodies.iter().any(|b| materials[b.material].elastic != material) {
        return Err(FieldError::new(
            "exact",
            "exact solutions need every body to share one material",
        ));
    }
    match *spec {
        ExactSpec::ColumnSelfWeight { base, top } => Ok(ExactSolution::ColumnSelfWeight {
            rho_g: column_weight(base, top, gravity, &material)?,
            base,
            top,
            material,
        }),
        ExactSpec::ColumnFinite { base, top } => Ok(ExactSolution::ColumnFinite {
            rho_g: column_weight(base, top, gravity, &material)?,
            base,
            top,
        }),
        ExactSpec::ConfinedY {
            stress_yy,
            base,
            angle_deg,
            about,
        } => Ok(ExactSolution::ConfinedY {
            stress_yy,
            base,
            angle: angle_deg.to_radians(),
            about,
            material,
        }),
        ExactSpec::ConfinedYFinite {
            stretch,
            base,
            angle_deg,
            about,
        } => {
            if !(stretch > 0.0 && stretch.is_finite()) {
                return Err(FieldError::new("exact.stretch", "must be positive"));
            }
            Ok(ExactSolution::ConfinedFinite {
                stretch,
                base,
                angle: angle_deg.to_radians(),
                about,
                material,
            })
        }
        ExactSpec::Lame {
            pressure,
            r_inner,
            r_outer,
            center,
        } => {
            if !(r_inner > 0.0 && r_outer > r_inner) {
                return Err(FieldError::new("exact.r_outer", "need 0 < r_inner < r_outer"));
            }
            Ok(ExactSolution::Lame {
                p: pressure,
                a: r_inner,
                b: r_outer,
                center,
                material,
            })
        }
        ExactSpec::Kirsch { stress, radius } => {
            if !(radius > 0.0) {
                return Err(FieldError::new("exact.radius", "must be positive"));
            }
            Ok(ExactSolution::Kirsch {
                s: stress,
                a: radius,
                material,
            })
        }
        ExactSpec::SimpleShear { shear, x0 } => Ok(ExactSolution::SimpleShear { g: shear, x0, material }),
        ExactSpec::FreeMotion {} => Err(FieldError::new("exact.name", "free-motion is built by the caller")),
        ExactSpec::UniaxialY { strain_yy, anchor } => {
            if !strain_yy.is_finite() || !anchor.iter().all(|a| a.is_finite()) {
                return Err(FieldError::new("exact", "parameters must be finite"));
            }
            Ok(ExactSolution::UniaxialY {
                strain_yy,
                anchor,
                material,
            })
        }
    }
}

/// The unit weight `rho g` of a column solution, checking its geometry and gravity.
fn column_weight(base: f64, top: f64, gravity: P2, material: &LinearElastic) -> Result<f64, FieldError> {
    if !(top > base) {
        return Err(FieldError::new("exact.top", "must exceed `base`"));
    }
    if gravity[0] != 0.0 || !(gravity[1] < 0.0) {
        return Err(FieldError::new(
            "loads.gravity",
            "the column solution needs gravity = [0, -g] with g > 0",
        ));
    }
    Ok(-material.density * gravity[1])
}

/// Fill `region` with points: per cell, `n x n` sub-cells clipped against the
/// region (point at the clipped centroid, volume = clipped area; C Fig. 4),
/// sub-cell centres inside the region ([`Placement::Centres`]), or `n x n`
/// Gauss points ([`Placement::Gauss`]). GIMP half-lengths are the
/// clipped extent scaled so that `4 l_x l_y = V`.
fn generate_points(
    grid: &Grid,
    region: &Region,
    n: usize,
    placement: Placement,
    density: f64,
    body: usize,
    pts: &mut Points,
) -> Result<(), String> {
    let (rmin, rmax) = region.bounds();
    let h = grid.h;
    let range = |d: usize, nc: usize| {
        let lo = ((rmin[d] - grid.origin[d]) / h).floor().max(0.0) as usize;
        let hi = (((rmax[d] - grid.origin[d]) / h).ceil().max(0.0) as usize).min(nc);
        lo..hi
    };
    let sub = h / n as f64;
    let (gx, gw) = gauss_legendre(n);
    for cj in range(1, grid.ny) {
        for ci in range(0, grid.nx) {
            let c0 = grid.cell_min(ci, cj);
            let cell = region.clip(c0, [c0[0] + h, c0[1] + h]);
            let full = cell.area >= h * h * (1.0 - 1e-12);
            if cell.area <= 1e-12 * h * h {
                continue;
            }
            if placement == Placement::Gauss {
                if !full {
                    return Err(format!(
                        "gauss placement needs every cell wholly inside or outside the region; cell ({ci}, {cj}) is {:.3} full",
                        cell.area / (h * h)
                    ));
                }
                for b in 0..n {
                    for a in 0..n {
                        let x = [c0[0] + 0.5 * h * (1.0 + gx[a]), c0[1] + 0.5 * h * (1.0 + gx[b])];
                        let v = 0.25 * h * h * gw[a] * gw[b];
                        pts.push(x, v, density, [0.5 * sub, 0.5 * sub], body);
                    }
                }
                continue;
            }
            for b in 0..n {
                for a in 0..n {
                    let s0 = [c0[0] + a as f64 * sub, c0[1] + b as f64 * sub];
                    let s1 = [s0[0] + sub, s0[1] + sub];
                    if full {
                        pts.push(
                            [s0[0] + 0.5 * sub, s0[1] + 0.5 * sub],
                            sub * sub,
                            density,
                            [0.5 * sub; 2],
                            body,
                        );
                        continue;
                    }
                    if placement == Placement::Centres {
                        let x = [s0[0] + 0.5 * sub, s0[1] + 0.5 * sub];
                        if region.contains(x) {
                            pts.push(x, sub * sub, density, [0.5 * sub; 2], body);
                        }
                        continue;
                    }
                    let c = region.clip(s0, s1);
                    if c.area <= 1e-12 * sub * sub {
                        continue;
                    }
                    let half = [0.5 * (c.max[0] - c.min[0]), 0.5 * (c.max[1] - c.min[1])];
                    let scale = (c.area / (4.0 * half[0] * half[1])).sqrt();
                    let lp = if scale.is_finite() {
                        [half[0] * scale, half[1] * scale]
                    } else {
                        [0.5 * sub; 2]
                    };
                    pts.push(c.centroid, c.area, density, lp, body);
                }
            }
        }
    }
    Ok(())
}

/// Points of a polar placement: a polar lattice of `radial x circumferential`
/// points that includes both radii and both end angles (so the innermost and
/// outermost layers lie on the surfaces, B 4.3), each carrying its tributary
/// area `(r+^2 - r-^2)/2 (t+ - t-)` as volume, where `[r-, r+]` and
/// `[t-, t+]` are the half-way lines to the neighbours clipped to the sector.
fn polar_points(b: &BodySpec, density: f64, body: usize, pts: &mut Points) -> Result<(), (&'static str, String)> {
    let RegionSpec::AnnulusSector {
        center,
        r_inner,
        r_outer,
        start_deg,
        end_deg,
        ..
    } = b.region
    else {
        return Err(("region", "polar placement needs an annulus-sector region".into()));
    };
    let nr = b
        .radial_points
        .ok_or(("radial_points", "polar placement needs `radial_points`".to_string()))?;
    let nc = b.circumferential_points.ok_or((
        "circumferential_points",
        "polar placement needs `circumferential_points`".to_string(),
    ))?;
    if nr < 2 || nc < 2 || nr.checked_mul(nc).is_none_or(|n| n > MAX_POINTS) {
        return Err((
            "radial_points",
            "need at least 2 points each way (and not absurdly many)".into(),
        ));
    }
    let (t0, t1) = (start_deg.to_radians(), end_deg.to_radians());
    let dr = (r_outer - r_inner) / (nr - 1) as f64;
    let dt = (t1 - t0) / (nc - 1) as f64;
    for i in 0..nr {
        let r = r_inner + i as f64 * dr;
        let (rm, rp) = ((r - 0.5 * dr).max(r_inner), (r + 0.5 * dr).min(r_outer));
        for j in 0..nc {
            let t = t0 + j as f64 * dt;
            let (tm, tp) = ((t - 0.5 * dt).max(t0), (t + 0.5 * dt).min(t1));
            let area = 0.5 * (rp * rp - rm * rm) * (tp - tm);
            let l = 0.5 * area.sqrt();
            // Surface points sit a hair (1e-9 of a spacing) inside the
            // material: a point exactly on a grid line at the far side of its
            // body would otherwise be mapped to the empty cell beyond and
            // activate nodes held by nothing else.
            let (rr, tt) = (
                (r.max(r_inner + 1e-9 * dr)).min(r_outer - 1e-9 * dr),
                (t.max(t0 + 1e-9 * dt)).min(t1 - 1e-9 * dt),
            );
            pts.push(
                [center[0] + rr * tt.cos(), center[1] + rr * tt.sin()],
                area,
                density,
                [l, l],
                body,
            );
        }
    }
    Ok(())
}

/// Points of a lattice placement: `nx x ny` points at the centres of equal
/// sub-rectangles of the region's bounding box, kept where the centre lies
/// inside the region (all of them for a rectangle).
fn lattice_points(
    b: &BodySpec,
    region: &Region,
    density: f64,
    body: usize,
    pts: &mut Points,
) -> Result<(), (&'static str, String)> {
    let (min, max) = region.bounds();
    let [nx, ny] = b
        .lattice
        .ok_or(("lattice", "lattice placement needs `lattice = [nx, ny]`".to_string()))?;
    if nx == 0 || ny == 0 || nx.checked_mul(ny).is_none_or(|n| n > MAX_POINTS) {
        return Err(("lattice", "point counts must be positive (and not absurd)".into()));
    }
    let rectangle = matches!(b.region, RegionSpec::Rectangle { .. });
    let (dx, dy) = ((max[0] - min[0]) / nx as f64, (max[1] - min[1]) / ny as f64);
    for j in 0..ny {
        for i in 0..nx {
            let x = [min[0] + (i as f64 + 0.5) * dx, min[1] + (j as f64 + 0.5) * dy];
            if rectangle || region.contains(x) {
                pts.push(x, dx * dy, density, [0.5 * dx, 0.5 * dy], body);
            }
        }
    }
    Ok(())
}

/// Indices of a layer of points (see [`LayerSide`]), in order along it.
fn layer_points(pts: &Points, range: std::ops::Range<usize>, side: LayerSide, center: P2, tol: f64) -> Vec<usize> {
    // Key along the layer (x, y or angle) and depth across it (larger is outer).
    let key_depth = |p: usize| -> (f64, f64) {
        let x = pts.x[p];
        match side {
            LayerSide::Top => (x[0], x[1]),
            LayerSide::Bottom => (x[0], -x[1]),
            LayerSide::Left => (x[1], -x[0]),
            LayerSide::Right => (x[1], x[0]),
            LayerSide::Inner | LayerSide::Outer => {
                let (dx, dy) = (x[0] - center[0], x[1] - center[1]);
                let r = dx.hypot(dy);
                // Angles scaled by the radius keep the tolerance a length.
                (dy.atan2(dx), if side == LayerSide::Outer { r } else { -r })
            }
        }
    };
    let angular = matches!(side, LayerSide::Inner | LayerSide::Outer);
    let ktol = if angular { 1e-9 } else { tol };
    let mut idx: Vec<usize> = range.filter(|&p| pts.vol[p] > 0.0).collect();
    idx.sort_by(|&a, &b| key_depth(a).0.total_cmp(&key_depth(b).0));
    let mut out = Vec::new();
    let mut k = 0;
    while k < idx.len() {
        let k0 = key_depth(idx[k]).0;
        let mut best = idx[k];
        while k < idx.len() && key_depth(idx[k]).0 - k0 <= ktol {
            if key_depth(idx[k]).1 > key_depth(best).1 {
                best = idx[k];
            }
            k += 1;
        }
        out.push(best);
    }
    out
}

#[allow(clippy::too_many_arguments)]
fn build_boundary(
    k: usize,
    spec: &BoundarySpec,
    grid: &Grid,
    bodies: &[Body],
    regions: &[Region],
    ranges: &[std::ops::Range<usize>],
    has_exact: bool,
    points: &mut Points,
) -> Result<Boundary, FieldError> {
    let f = |n: &str| format!("boundary[{k}].{n}");
    let body = bodies
        .iter()
        .position(|b| b.name == spec.body)
        .ok_or_else(|| FieldError::new(f("body"), format!("no body named `{}`", spec.body)))?;
    let idx: Vec<usize> = match (&spec.points, spec.layer) {
        (Some(list), None) => {
            if list.len() > MAX_CURVE_POINTS {
                return Err(FieldError::new(
                    f("points"),
                    format!(
                        "{} points are more than the {MAX_CURVE_POINTS} a boundary may have",
                        list.len()
                    ),
                ));
            }
            let gmax = grid.max();
            let tol = 1e-9 * grid.h;
            let mut idx = Vec::new();
            for (i, p) in list.iter().enumerate() {
                if !(p.iter().all(|v| v.is_finite())
                    && p[0] >= grid.origin[0] - tol
                    && p[1] >= grid.origin[1] - tol
                    && p[0] <= gmax[0] + tol
                    && p[1] <= gmax[1] + tol)
                {
                    return Err(FieldError::new(f("points"), format!("point {i} lies outside the grid")));
                }
                // Zero-volume tracking point: follows the body, carries nothing.
                points.push(*p, 0.0, 0.0, [0.0; 2], body);
                idx.push(points.len() - 1);
            }
            idx
        }
        (None, Some(side)) => {
            let center = spec.center.unwrap_or([0.0; 2]);
            if matches!(side, LayerSide::Inner | LayerSide::Outer) && spec.center.is_none() {
                return Err(FieldError::new(f("center"), "inner and outer layers need a `center`"));
            }
            layer_points(points, ranges[body].clone(), side, center, 1e-9 * grid.h)
        }
        _ => {
            return Err(FieldError::new(
                format!("boundary[{k}]"),
                "give exactly one of `points` or `layer`",
            ))
        }
    };
    let mut corners = vec![false; idx.len()];
    for &c in &spec.corners {
        *corners
            .get_mut(c)
            .ok_or_else(|| FieldError::new(f("corners"), format!("there is no point {c}")))? = true;
    }
    if !(1..=20).contains(&spec.gauss_points) {
        return Err(FieldError::new(f("gauss_points"), "must be between 1 and 20"));
    }
    let traction = match &spec.traction {
        None => None,
        Some(TractionSpec::Vector { value }) => {
            if !value.iter().all(|v| v.is_finite()) {
                return Err(FieldError::new(f("traction"), "must be finite"));
            }
            Some(Traction::Vector(*value))
        }
        Some(TractionSpec::Pressure { value }) => {
            if !value.is_finite() {
                return Err(FieldError::new(f("traction"), "must be finite"));
            }
            Some(Traction::Pressure(*value))
        }
        Some(TractionSpec::ExactStress) => {
            if !has_exact {
                return Err(FieldError::new(
                    f("traction"),
                    "exact-stress traction needs an [exact] solution",
                ));
            }
            Some(Traction::ExactStress)
        }
    };
    let q: Vec<P2> = idx.iter().map(|&p| points.x[p]).collect();
    let spline =
        BSpline::interpolate(&q, spec.closed, &corners).map_err(|e| FieldError::new(f("points"), e.to_string()))?;
    let outward = match spec.material_side {
        Some(MaterialSide::Left) => 1.0,
        Some(MaterialSide::Right) => -1.0,
        None => material_side(&spline, &regions[body], grid.h).ok_or_else(|| {
            FieldError::new(
                f("material_side"),
                "cannot tell which side of the curve the material is on; give material_side = \"left\" or \"right\"",
            )
        })?,
    };
    Ok(Boundary {
        name: spec.name.clone(),
        points: idx,
        closed: spec.closed,
        corners,
        gauss_points: spec.gauss_points,
        traction,
        outward,
    })
}

/// `+1` when the material lies to the left of the curve (outward normal =
/// right normal), `-1` when to the right, by probing the region on both
/// sides of the middle of the curve at growing distances.
fn material_side(s: &BSpline, region: &Region, h: f64) -> Option<f64> {
    let k = s.segments.len() / 2;
    let x = s.point(k, 0.5);
    let n = s.right_normal(k, 0.5);
    for eps in [0.05, 0.1, 0.25, 0.5, 1.0, 2.0] {
        let d = eps * h;
        let right = region.contains([x[0] + d * n[0], x[1] + d * n[1]]);
        let left = region.contains([x[0] - d * n[0], x[1] - d * n[1]]);
        match (left, right) {
            (true, false) => return Some(1.0),
            (false, true) => return Some(-1.0),
            _ => {}
        }
    }
    None
}
