//! The model: a validated scene turned into grid, materials, bodies with
//! their material points, boundary conditions, loads and analysis settings.

use crate::basis::BasisKind;
use crate::exact::ExactSolution;
use crate::geometry::{Region, P2};
use crate::grid::Grid;
use crate::material::LinearElastic;
use crate::points::Points;
use crate::quadrature::gauss_legendre;
use crate::scene::{
    AnalysisSpec, DirichletKind, ExactSpec, FieldError, Locator, MaterialModel, Placement, Scene, SceneError,
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

/// A grid-aligned Dirichlet condition: on grid line `index` along `axis`
/// (`axis = 0`: the vertical line `x = c`; `1`: the horizontal line `y = c`),
/// component `k` is prescribed to `value[k]` (total at load factor 1) where
/// `Some`.
#[derive(Clone, Debug, PartialEq)]
pub struct DirichletLine {
    pub axis: usize,
    pub index: usize,
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
    pub materials: Vec<LinearElastic>,
    pub material_names: Vec<String>,
    pub bodies: Vec<Body>,
    pub points: Points,
    pub dirichlet: Vec<DirichletLine>,
    /// Gravitational acceleration (m/s^2); body force = density * gravity.
    pub gravity: P2,
    pub point_loads: Vec<PointLoad>,
    pub analysis: AnalysisSpec,
    pub exact: Option<ExactSolution>,
}

/// Largest grid the engine will build (cells).
const MAX_CELLS: usize = 20_000_000;

impl Model {
    /// Validate a parsed scene and build the model. `text` and `file` are the
    /// scene's source, used to locate errors.
    pub fn build(scene: &Scene, text: &str, file: &str) -> Result<Model, SceneError> {
        Self::build_unlocated(scene).map_err(|e| Locator::new(text).error(file, e))
    }

    /// Parse and build from scene text in one go.
    pub fn from_text(text: &str, file: &str) -> Result<Model, SceneError> {
        let scene = Scene::parse(text, file)?;
        Self::build(&scene, text, file)
    }

    fn build_unlocated(scene: &Scene) -> Result<Model, FieldError> {
        let grid = build_grid(scene)?;

        let mut materials = Vec::new();
        let mut material_names: Vec<String> = Vec::new();
        if scene.materials.is_empty() {
            return Err(FieldError::new("material", "at least one [[material]] is needed"));
        }
        for (k, m) in scene.materials.iter().enumerate() {
            let f = |n: &str| format!("material[{k}].{n}");
            if material_names.contains(&m.name) {
                return Err(FieldError::new(
                    f("name"),
                    format!("material `{}` is defined twice", m.name),
                ));
            }
            let MaterialModel::LinearElastic = m.model;
            if !(m.e > 0.0 && m.e.is_finite()) {
                return Err(FieldError::new(
                    f("E"),
                    format!("Young's modulus must be positive, got {}", m.e),
                ));
            }
            if !(m.nu > -1.0 && m.nu < 0.5) {
                return Err(FieldError::new(
                    f("nu"),
                    format!("Poisson's ratio must lie in (-1, 0.5), got {}", m.nu),
                ));
            }
            if !(m.density >= 0.0 && m.density.is_finite()) {
                return Err(FieldError::new(f("density"), "must be non-negative"));
            }
            materials.push(LinearElastic {
                e: m.e,
                nu: m.nu,
                density: m.density,
                plane: m.plane,
            });
            material_names.push(m.name.clone());
        }

        if scene.bodies.is_empty() {
            return Err(FieldError::new("body", "at least one [[body]] is needed"));
        }
        let mut bodies = Vec::new();
        let mut points = Points::default();
        for (k, b) in scene.bodies.iter().enumerate() {
            let f = |n: &str| format!("body[{k}].{n}");
            let material = material_names
                .iter()
                .position(|n| *n == b.material)
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
                        "the region [{:.4}, {:.4}] x [{:.4}, {:.4}] extends outside the grid [{:.4}, {:.4}] x [{:.4}, {:.4}]: its points would lie outside the grid",
                        min[0], max[0], min[1], max[1], grid.origin[0], gmax[0], grid.origin[1], gmax[1]
                    ),
                ));
            }
            let before = points.len();
            let density = materials[material].density;
            generate_points(&grid, &region, b.points_per_cell, b.placement, density, k, &mut points)
                .map_err(|m| FieldError::new(f("placement"), m))?;
            if points.len() == before {
                return Err(FieldError::new(
                    f("region"),
                    "the body is empty: no cell overlaps its region",
                ));
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
            let (axis, c, key) = match (d.x, d.y) {
                (Some(x), None) => (0, x, "x"),
                (None, Some(y)) => (1, y, "y"),
                _ => {
                    return Err(FieldError::new(
                        format!("dirichlet[{k}]"),
                        "give exactly one of `x` or `y`",
                    ))
                }
            };
            let index = grid
                .line_index(axis, c)
                .ok_or_else(|| FieldError::new(f(key), format!("{key} = {c} is not a grid line")))?;
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
            dirichlet.push(DirichletLine { axis, index, value });
        }

        let gravity = scene.loads.gravity.unwrap_or([0.0; 2]);
        if !gravity.iter().all(|g| g.is_finite()) {
            return Err(FieldError::new("loads.gravity", "must be finite"));
        }
        let mut point_loads = Vec::new();
        for (k, l) in scene.loads.point.iter().enumerate() {
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

        let exact = match &scene.exact {
            None => None,
            Some(spec) => Some(build_exact(spec, &materials, &bodies, gravity)?),
        };

        Ok(Model {
            name: scene.scene.name.clone(),
            description: scene.scene.description.trim().to_string(),
            grid,
            materials,
            material_names,
            bodies,
            points,
            dirichlet,
            gravity,
            point_loads,
            analysis: a.clone(),
            exact,
        })
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
            format!("the cell size must be positive, got {}", g.h),
        ));
    }
    if !g.origin.iter().all(|v| v.is_finite()) {
        return Err(FieldError::new("grid.origin", "must be finite"));
    }
    let mut n = [0usize; 2];
    for d in 0..2 {
        let s = g.size[d] / g.h;
        if !(s.is_finite() && s >= 1.0 - 1e-9) || (s - s.round()).abs() > 1e-9 * s.max(1.0) {
            return Err(FieldError::new(
                "grid.size",
                format!(
                    "must be a positive whole number of cells of size h = {}, got {} ({} cells)",
                    g.h, g.size[d], s
                ),
            ));
        }
        n[d] = s.round() as usize;
    }
    if n[0].saturating_mul(n[1]) > MAX_CELLS {
        return Err(FieldError::new(
            "grid.size",
            format!("{} x {} cells is more than the {MAX_CELLS} supported", n[0], n[1]),
        ));
    }
    Ok(Grid {
        origin: g.origin,
        h: g.h,
        nx: n[0],
        ny: n[1],
    })
}

fn build_exact(
    spec: &ExactSpec,
    materials: &[LinearElastic],
    bodies: &[Body],
    gravity: P2,
) -> Result<ExactSolution, FieldError> {
    let material = materials[bodies[0].material];
    if bodies.iter().any(|b| materials[b.material] != material) {
        return Err(FieldError::new(
            "exact",
            "exact solutions need every body to share one material",
        ));
    }
    match *spec {
        ExactSpec::ColumnSelfWeight { base, top } => {
            if !(top > base) {
                return Err(FieldError::new("exact.top", "must exceed `base`"));
            }
            if gravity[0] != 0.0 || !(gravity[1] < 0.0) {
                return Err(FieldError::new(
                    "loads.gravity",
                    "the column solution needs gravity = [0, -g] with g > 0",
                ));
            }
            Ok(ExactSolution::ColumnSelfWeight {
                rho_g: -material.density * gravity[1],
                base,
                top,
                material,
            })
        }
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

/// Fill `region` with points: per cell, `n x n` sub-cells clipped against the
/// region (point at the clipped centroid, volume = clipped area; C Fig. 4), or
/// `n x n` Gauss points for [`Placement::Gauss`]. GIMP half-lengths are the
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
