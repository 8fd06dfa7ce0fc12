//! Scene files: the TOML a user writes, as plain serde data.
//!
//! A scene names the grid, materials, bodies (regions filled with material
//! points), boundary conditions, loads, the analysis and optionally an exact
//! solution. [`Scene::parse`] checks syntax and keys; [`crate::model::Model::build`]
//! checks meaning (E > 0, -1 < nu < 0.5, bodies inside the grid, ...). Both
//! report a [`SceneError`] naming file, line and field.
//!
//! The full schema with every field is documented in `docs/scenes.md`.

mod error;
pub mod region;

pub use error::{
    from_toml, line_column, number, path_of_line, FieldError, Locator, SceneError, MAX_MAGNITUDE, MIN_MAGNITUDE,
};
pub use region::RegionSpec;

use crate::basis::BasisKind;
use serde::Deserialize;
use std::path::Path;

/// A whole scene file.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    pub scene: SceneMeta,
    pub grid: GridSpec,
    #[serde(rename = "material")]
    pub materials: Vec<MaterialSpec>,
    #[serde(rename = "body")]
    pub bodies: Vec<BodySpec>,
    #[serde(default, rename = "dirichlet")]
    pub dirichlet: Vec<DirichletSpec>,
    #[serde(default, rename = "boundary")]
    pub boundaries: Vec<BoundarySpec>,
    #[serde(default, rename = "ibm")]
    pub ibm: Vec<IbmSpec>,
    #[serde(default)]
    pub loads: LoadsSpec,
    pub analysis: AnalysisSpec,
    #[serde(default)]
    pub exact: Option<ExactSpec>,
    #[serde(default)]
    pub record: RecordSpec,
    #[serde(default, rename = "probe")]
    pub probes: Vec<ProbeSpec>,
}

/// `[[probe]]`: a named quantity followed through the run (see
/// [`crate::probe`]). Give exactly one of `at` (a material position: the
/// fields there, or with `point = "nearest"` the material point nearest
/// it at the start), `boundary` (a `[[boundary]]`'s name) or `ibm` (an
/// `[[ibm]]`'s name).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProbeSpec {
    pub name: String,
    #[serde(default)]
    pub at: Option<[f64; 2]>,
    /// With `at`: what answers (default the fields at the position).
    #[serde(default)]
    pub point: Option<ProbeRead>,
    #[serde(default)]
    pub boundary: Option<String>,
    #[serde(default)]
    pub ibm: Option<String>,
}

/// `point = "field" | "nearest"` of a `[[probe]]` with `at`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ProbeRead {
    /// The displacement, velocity and stress fields at the material
    /// position, fitted from the points around it
    /// ([`crate::probe::FieldFit`]).
    #[default]
    Field,
    /// The material point with volume nearest to the position at the start.
    Nearest,
}

/// `[record]`: what the run's recording holds (checked in
/// [`crate::model::record`]). Metrics and events are recorded at every
/// step; the points at a cadence: every `every` steps or, for explicit
/// dynamics, every `dt` seconds of simulated time (default: every step
/// up to a budget of points times frames, see
/// [`crate::model::record::POINT_FRAME_BUDGET`]).
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RecordSpec {
    #[serde(default)]
    pub every: Option<usize>,
    #[serde(default)]
    pub dt: Option<f64>,
    /// Per-point fields recorded with the positions (`sigma_yy`, `speed`,
    /// ...; `"all"` for every one; default the colour field `sigma_yy`).
    #[serde(default)]
    pub fields: Option<FieldNames>,
    /// The points' colour scale: fixed over the run (`"run"`, default) or
    /// each frame's own (`"frame"`).
    #[serde(default)]
    pub colour_range: ColourRange,
    /// Small strain: draw the points at `x0 + s u` with this scale `s`
    /// (default: chosen so the full-load displacement is a tenth of the
    /// bodies' extent, or 1 when it is smaller already).
    #[serde(default)]
    pub deformation_scale: Option<f64>,
}

/// `[record] colour_range`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ColourRange {
    /// One scale for every frame: the envelope of the run's values (while
    /// the run goes on, of the frames so far; the finished recording
    /// recolours every frame with the whole run's).
    #[default]
    Run,
    /// Each frame's own values.
    Frame,
}

/// `fields = "all"` or `fields = ["sigma_yy", "speed"]`.
#[derive(Clone, Debug, Deserialize)]
#[serde(untagged)]
pub enum FieldNames {
    One(String),
    Many(Vec<String>),
}

impl FieldNames {
    pub fn names(&self) -> Vec<String> {
        match self {
            FieldNames::One(s) => vec![s.clone()],
            FieldNames::Many(v) => v.clone(),
        }
    }
}

/// `[scene]`: name and a one-paragraph description (shown by `mpmlab list`).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneMeta {
    pub name: String,
    #[serde(default)]
    pub description: String,
    /// The unit system the scene's numbers are in (labels only; the
    /// engine needs consistent units): `"SI"` (default), `"mm-N-MPa"`,
    /// `"m-kN-kPa"`.
    #[serde(default)]
    pub units: crate::units::Units,
}

/// `[grid]`: lower-left `origin` (m), `size` = extent (m), cell size `h` (m).
/// `size` must be a whole number of cells.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GridSpec {
    pub origin: [f64; 2],
    pub size: [f64; 2],
    pub h: f64,
}

/// Plane strain (`e_zz = 0`) or plane stress (`s_zz = 0`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Plane {
    #[default]
    Strain,
    Stress,
}

/// Constitutive model of a material.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MaterialModel {
    /// Linear elasticity; under the finite-deformation analysis, Hencky
    /// elasticity (linear Kirchhoff stress in logarithmic strain).
    #[default]
    LinearElastic,
    /// Hencky elasticity with von Mises perfect plasticity (finite
    /// deformation analysis only); needs one of `rho_y`, `sigma_y`, `c_u`.
    VonMises,
}

/// `[[material]]`: Young's modulus `E` (Pa), Poisson's ratio `nu`, mass
/// `density` (kg/m^3).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialSpec {
    pub name: String,
    #[serde(default)]
    pub model: MaterialModel,
    #[serde(rename = "E")]
    pub e: f64,
    pub nu: f64,
    #[serde(default)]
    pub density: f64,
    #[serde(default)]
    pub plane: Plane,
    /// Von Mises strength as G's radius `rho_y = sqrt(2 J2)` of the
    /// Kirchhoff stress at yield (Pa); or give one of:
    #[serde(default)]
    pub rho_y: Option<f64>,
    /// the uniaxial yield stress `sigma_y` (Pa; `rho_y = sqrt(2/3)
    /// sigma_y`), or
    #[serde(default)]
    pub sigma_y: Option<f64>,
    /// the undrained shear strength `c_u` (Pa; yield in pure shear,
    /// `rho_y = sqrt(2) c_u`).
    #[serde(default)]
    pub c_u: Option<f64>,
    /// The old key, read only to be refused with the way to say it now
    /// (it was `rho_y`, which a reader takes for `sigma_y`).
    #[serde(default)]
    pub yield_stress: Option<f64>,
}

/// How a von Mises strength was given, for the run's header.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Strength {
    RhoY(f64),
    SigmaY(f64),
    CU(f64),
}

impl Strength {
    /// G's radius `rho_y = sqrt(2 J2)` at yield (Pa).
    pub fn rho_y(self) -> f64 {
        match self {
            Strength::RhoY(r) => r,
            Strength::SigmaY(s) => (2.0f64 / 3.0).sqrt() * s,
            Strength::CU(c) => 2f64.sqrt() * c,
        }
    }

    /// The three ways of saying it: `rho_y`, `sigma_y`, `c_u` (Pa).
    pub fn all(self) -> [f64; 3] {
        let r = self.rho_y();
        [r, (1.5f64).sqrt() * r, r / 2f64.sqrt()]
    }

    /// The key it was given by.
    pub fn key(self) -> &'static str {
        match self {
            Strength::RhoY(_) => "rho_y",
            Strength::SigmaY(_) => "sigma_y",
            Strength::CU(_) => "c_u",
        }
    }
}

/// Where a body's points go inside each cell.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Placement {
    /// n x n sub-cells clipped against the region; point at the clipped
    /// centroid, volume = clipped area (C Fig. 4).
    #[default]
    Clipped,
    /// n x n sub-cells kept when their centre lies inside the region, point
    /// at the centre with the whole sub-cell area (AMPLE's way): volumes are
    /// exact only for grid-aligned regions, but no point is a sliver.
    #[serde(alias = "centers")]
    Centres,
    /// n x n Gauss-Legendre points with Gauss weights as volumes: the
    /// finite-element limit. Cells must lie wholly inside or outside the region.
    Gauss,
    /// For an annulus-sector region: `radial_points` x `circumferential_points`
    /// points on a polar lattice including both radii and both end angles,
    /// each with its tributary area as volume (B 4.3).
    Polar,
    /// `lattice = [nx, ny]` points in a regular array over the region's
    /// bounding box, independent of the grid (B 4.2), each with the area of
    /// its lattice cell; for a non-rectangular region only the cells whose
    /// centre lies inside are kept (G's ghost discretisations).
    Lattice,
}

/// `[[body]]`: a region filled with points of one material.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BodySpec {
    pub name: String,
    pub material: String,
    /// n: the body gets n x n points per cell.
    pub points_per_cell: usize,
    #[serde(default)]
    pub basis: BasisKind,
    #[serde(default)]
    pub placement: Placement,
    pub region: RegionSpec,
    /// Lattice placement only: points along x and y.
    #[serde(default)]
    pub lattice: Option<[usize; 2]>,
    /// Polar placement only: points along the radius.
    #[serde(default)]
    pub radial_points: Option<usize>,
    /// Polar placement only: points along the circumference.
    #[serde(default)]
    pub circumferential_points: Option<usize>,
    /// Dynamics: initial velocity (m/s) ...
    #[serde(default)]
    pub velocity: [f64; 2],
    /// ... plus `L (x - velocity_centre)` with this velocity gradient `L`
    /// (1/s, rows `[[dvx/dx, dvx/dy], [dvy/dx, dvy/dy]]`) ...
    #[serde(default)]
    pub velocity_gradient: Option<[[f64; 2]; 2]>,
    #[serde(default)]
    pub velocity_centre: [f64; 2],
    /// ... plus a vibration mode's velocity field ([`VelocityMode`]).
    #[serde(default)]
    pub velocity_mode: Option<VelocityMode>,
}

/// The velocity field of the first axial mode of a bar fixed at `origin`
/// and free at `origin + length axis`: `v(x) = amplitude sin(pi s / (2
/// length))` with `s = (x - origin) . axis` (m), `axis` a unit vector (it
/// is normalised). Its exact motion in a 1D bar (`nu = 0`) is `u = v(X)
/// sin(omega t) / omega`, `omega = pi c / (2 length)`, `c = sqrt(E/rho)`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VelocityMode {
    /// Velocity at the free end (m/s, a vector).
    pub amplitude: [f64; 2],
    /// The fixed end (m).
    pub origin: [f64; 2],
    /// Along the bar, from the fixed end.
    pub axis: [f64; 2],
    /// The bar's length (m).
    pub length: f64,
}

impl VelocityMode {
    /// The mode's velocity at `x` (m/s).
    pub fn at(&self, x: [f64; 2]) -> [f64; 2] {
        let n = self.axis[0].hypot(self.axis[1]);
        let s = ((x[0] - self.origin[0]) * self.axis[0] + (x[1] - self.origin[1]) * self.axis[1]) / n;
        let f = (std::f64::consts::FRAC_PI_2 * s / self.length).sin();
        [self.amplitude[0] * f, self.amplitude[1] * f]
    }
}

/// `[[ibm]]`: a Dirichlet condition on a straight line or polyline at any
/// inclination, imposed by the implicit boundary method (C section 3). The
/// material lies on one side (found from the bodies' regions, or given).
/// Values are totals at load factor 1, applied in proportion.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IbmSpec {
    pub name: String,
    pub kind: DirichletKind,
    /// Polyline vertices (at least 2), in order; or
    #[serde(default)]
    pub points: Vec<[f64; 2]>,
    /// the curve of the B-spline `[[boundary]]` of this name (tracked each
    /// step, flattened to `per_segment` chords per spline segment).
    #[serde(default)]
    pub boundary: Option<String>,
    #[serde(default = "default_ibm_chords")]
    pub per_segment: usize,
    /// For `fixed`: the prescribed displacement (m); zero when omitted.
    #[serde(default)]
    pub displacement: Option<[f64; 2]>,
    /// For `fixed`: prescribe the scene's exact displacement field instead,
    /// with nodal values by the global least-squares fit B (36).
    #[serde(default)]
    pub exact_field: bool,
    /// With `exact_field`: Tikhonov weight `eps` pulling each nodal value
    /// towards the exact field at the node, relative to the mean diagonal of
    /// the fit. Unset: automatic, the plain least-squares fit B (36), and
    /// [`crate::ibm::AUTO_FIT_REGULARISATION`] only in a step where the
    /// plain fit is singular (a node barely touches the boundary); 0: the
    /// plain fit always, failing with a report where it is singular.
    #[serde(default)]
    pub fit_regularisation: Option<f64>,
    /// For `fixed` with a uniform `displacement`, or a straight `roller`
    /// with a `normal_displacement`: the boundary itself moves with the
    /// prescribed displacement (a rigid footing pushed in, a platen).
    #[serde(default)]
    pub moves: bool,
    /// For `roller`: the prescribed displacement along the inward normal (m).
    #[serde(default)]
    pub normal_displacement: Option<f64>,
    #[serde(default)]
    pub material_side: Option<MaterialSide>,
    /// Gauss points along each piece of the band (across it: 3).
    #[serde(default = "default_ibm_gauss")]
    pub gauss_points: usize,
}

fn default_ibm_chords() -> usize {
    16
}

fn default_ibm_gauss() -> usize {
    2
}

/// Which layer of a body's points a boundary passes through.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LayerSide {
    /// Per column of points (equal x), the highest; ordered by x.
    Top,
    /// Per column, the lowest; ordered by x.
    Bottom,
    /// Per row (equal y), the leftmost; ordered by y.
    Left,
    /// Per row, the rightmost; ordered by y.
    Right,
    /// Per ray from `center` (equal angle), the nearest; ordered by angle.
    Inner,
    /// Per ray, the farthest; ordered by angle.
    Outer,
}

/// Which side of the curve's direction of travel the material lies on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MaterialSide {
    Left,
    Right,
}

/// A traction on a boundary, at load factor 1.
#[derive(Clone, Debug, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum TractionSpec {
    /// Fixed traction vector (Pa).
    Vector { value: [f64; 2] },
    /// Pressure (Pa) normal to the current curve, pushing into the material.
    Pressure { value: f64 },
    /// `s_exact(x) n` from the scene's `[exact]` solution.
    ExactStress,
}

/// `[[boundary]]`: a B-spline through zero-volume tracking points or
/// through a layer of a body's points, rebuilt every step.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoundarySpec {
    pub name: String,
    /// The body whose displacement the boundary follows.
    pub body: String,
    /// Explicit tracking points (zero volume and mass).
    #[serde(default)]
    pub points: Option<Vec<[f64; 2]>>,
    /// Or: a layer of the body's own points.
    #[serde(default)]
    pub layer: Option<LayerSide>,
    /// Centre for `inner` and `outer` layers.
    #[serde(default)]
    pub center: Option<[f64; 2]>,
    #[serde(default)]
    pub closed: bool,
    /// Indices of points that are corners.
    #[serde(default)]
    pub corners: Vec<usize>,
    /// Gauss points per piece of curve for the traction integral.
    #[serde(default = "default_gauss_points")]
    pub gauss_points: usize,
    #[serde(default)]
    pub traction: Option<TractionSpec>,
    /// Side of the material; found from the body's region when omitted.
    #[serde(default)]
    pub material_side: Option<MaterialSide>,
}

fn default_gauss_points() -> usize {
    3
}

/// Kind of a grid-aligned Dirichlet condition.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DirichletKind {
    /// Both displacement components prescribed.
    Fixed,
    /// The component normal to the line prescribed, the tangential free.
    Roller,
}

/// `[[dirichlet]]`: a condition on every active node of the grid line
/// `x = c` or `y = c`, or on the single grid node `node = [x, y]` (a roller
/// there needs `x` or `y` to say its normal, so use `fixed` for nodes). Values are totals at load factor 1 (m), applied in
/// proportion to the load factor; zero when omitted.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DirichletSpec {
    pub kind: DirichletKind,
    #[serde(default)]
    pub x: Option<f64>,
    #[serde(default)]
    pub y: Option<f64>,
    /// Or a single grid node at this position.
    #[serde(default)]
    pub node: Option<[f64; 2]>,
    /// For `fixed`: the prescribed displacement vector.
    #[serde(default)]
    pub displacement: Option<[f64; 2]>,
    /// For `roller`: the prescribed displacement along the axis normal to the line.
    #[serde(default)]
    pub normal_displacement: Option<f64>,
}

/// `[loads]`: gravity (m/s^2, times each material's density) and point loads.
/// All loads are totals at load factor 1.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LoadsSpec {
    #[serde(default)]
    pub gravity: Option<[f64; 2]>,
    #[serde(default)]
    pub point: Vec<PointLoadSpec>,
}

/// `[[loads.point]]`: force `force` (N per unit thickness) applied through the
/// basis functions at the material point nearest to `at`, following that
/// point as it moves.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PointLoadSpec {
    pub at: [f64; 2],
    pub force: [f64; 2],
}

/// The analysis type.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum AnalysisKind {
    /// Small strain, one linear solve per load step on the current
    /// configuration (B, C).
    #[default]
    QuasiStaticLinear,
    /// Finite deformation, updated Lagrangian, Newton-Raphson per load step
    /// (G section 2, AMPLE); plane strain.
    QuasiStaticFinite,
    /// Explicit dynamics (G 2.3): `load_steps` time steps over `duration`,
    /// finite deformation (Hencky, von Mises), plane strain.
    ExplicitDynamics,
    /// Implicit dynamics: `load_steps` Newmark time steps over `duration`
    /// (trapezoidal or Bossak, `integrator`), updated Lagrangian, Newton
    /// in every step with the mass as one more contribution of the
    /// implicit core; every method of the Newton path combines with it.
    DynamicImplicit,
}

impl AnalysisKind {
    /// Whether the analysis steps through time (`duration`, velocities,
    /// kinetic energy): explicit or implicit dynamics.
    pub fn is_dynamic(self) -> bool {
        matches!(self, AnalysisKind::ExplicitDynamics | AnalysisKind::DynamicImplicit)
    }

    /// Whether its steps are Newton iterations on the finite-deformation
    /// residual: quasi-static finite deformation and implicit dynamics.
    pub fn is_newton(self) -> bool {
        matches!(self, AnalysisKind::QuasiStaticFinite | AnalysisKind::DynamicImplicit)
    }
}

/// The time integrator of implicit dynamics.
#[derive(Clone, Copy, Debug, Default, PartialEq, Deserialize, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Integrator {
    /// Newmark's trapezoidal rule (average acceleration, `beta = 1/4`,
    /// `gamma = 1/2`): second order, unconditionally stable, no numerical
    /// damping.
    #[default]
    Trapezoidal,
    /// Bossak's alpha method (Wood, Bossak and Zienkiewicz 1980; Kratos'
    /// default): the inertia at `(1 - alpha) a_{n+1} + alpha a_n`,
    /// `gamma = 1/2 - alpha`, `beta = (1 - alpha)^2 / 4`, `alpha` in
    /// `[-1/3, 0]` (`analysis.bossak_alpha`): second order, damps the
    /// highest frequencies, more as `alpha` falls.
    Bossak,
}

impl Integrator {
    /// `trapezoidal`, `Bossak`.
    pub fn label(self) -> &'static str {
        match self {
            Integrator::Trapezoidal => "trapezoidal",
            Integrator::Bossak => "Bossak",
        }
    }
}

/// Which cells count as active for the ghost face set (G 4.2).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum GhostCells {
    /// Every cell a point's basis reaches (GIMP: every cell a domain
    /// overlaps), so nodes that domains barely touch are held by faces.
    #[default]
    Reached,
    /// Cells holding a point (G 3.1's populated elements): cells that only a
    /// GIMP domain reaches count as unpopulated.
    Populated,
}

/// Mass matrix of explicit dynamics (G 2.3, 3.3).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MassKind {
    /// Row sums on the diagonal: `M_bar = diag(sum_p m_p S_vp)`.
    Lumped,
    /// `M = sum_p m_p S_p^T S_p`: singular-prone as points barely touch nodes.
    Consistent,
    /// `M + gamma_M J_G` (G (20)).
    #[default]
    #[serde(alias = "stabilized")]
    Stabilised,
}

/// When the stress is updated in an explicit step.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum StressUpdate {
    /// Update stress first, from the start-of-step grid velocities.
    #[default]
    Usf,
    /// Update stress last, from the end-of-step grid velocities.
    Usl,
    /// Modified USL (Sulsky et al.): update stress last, from the updated
    /// point velocities mapped back to the grid with the same mass.
    Musl,
}

/// How points take the grid's new velocities.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum VelocityUpdate {
    /// Add the interpolated grid acceleration: `v_p += dt sum_v S_vp a_v`.
    #[default]
    Flip,
    /// Overwrite with the interpolated grid velocity: `v_p = sum_v S_vp v_v`.
    Pic,
}

impl MassKind {
    /// The name a user reads: `lumped`, `consistent`, `stabilised`.
    pub fn label(self) -> &'static str {
        match self {
            MassKind::Lumped => "lumped",
            MassKind::Consistent => "consistent",
            MassKind::Stabilised => "stabilised",
        }
    }
}

impl StressUpdate {
    /// `USF`, `USL`, `MUSL`.
    pub fn label(self) -> &'static str {
        match self {
            StressUpdate::Usf => "USF",
            StressUpdate::Usl => "USL",
            StressUpdate::Musl => "MUSL",
        }
    }
}

impl VelocityUpdate {
    /// `FLIP`, `PIC`.
    pub fn label(self) -> &'static str {
        match self {
            VelocityUpdate::Flip => "FLIP",
            VelocityUpdate::Pic => "PIC",
        }
    }
}

/// How condition numbers are computed each step.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ConditionMode {
    /// Dense eigenvalues up to `dense_limit` unknowns, Lanczos above.
    #[default]
    Auto,
    Dense,
    Lanczos,
    Off,
}

/// `[analysis]`
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AnalysisSpec {
    #[serde(default)]
    pub kind: AnalysisKind,
    pub load_steps: usize,
    /// Largest accepted relative residual: `|K du - r| / |r|` of the linear
    /// solve, or for Newton `|f_ext - f_int - f_G| / (|f_ext| + |reactions|)`.
    #[serde(default = "default_tolerance")]
    pub tolerance: f64,
    /// Newton iterations per load step at most (finite deformation).
    #[serde(default = "default_max_iterations")]
    pub max_iterations: usize,
    /// How many times in a row a failing increment may be halved and
    /// retried from the last good state: the Newton load increment
    /// (finite deformation) or the time step (explicit dynamics, when it
    /// diverges or turns non-finite). 0: the papers' fixed increments, a
    /// failure ends the run.
    #[serde(default = "default_max_cutbacks")]
    pub max_cutbacks: usize,
    /// Ghost stiffness penalty `gamma_K` (G (27)); 0 switches it off.
    #[serde(default)]
    pub gamma_k: f64,
    /// Newton line search (finite deformation): halve a correction that
    /// makes the residual non-finite or larger.
    #[serde(default)]
    pub line_search: bool,
    /// F-bar against volumetric locking (finite deformation): the
    /// volumetric part of each point's deformation is its cell's mean.
    #[serde(default)]
    pub fbar: bool,
    /// Small strain: whether each load step moves the points
    /// (`x += N du`, `V *= det(I + grad du)`) so that the next step is
    /// solved on the moved configuration (an incremental analysis, the
    /// default), or every step is solved on the starting configuration
    /// (`false`: a linear analysis of one configuration; the points'
    /// displacements still accumulate, their positions are drawn moved).
    #[serde(default = "yes")]
    pub update_points: bool,
    /// Which cells the ghost face set treats as active.
    #[serde(default)]
    pub ghost_cells: GhostCells,
    /// Implicit-boundary bandwidth as a fraction of the cell size (C: 1e-6).
    #[serde(default = "default_delta_over_h")]
    pub delta_over_h: f64,
    /// Or the bandwidth itself (m); overrides `delta_over_h`.
    #[serde(default)]
    pub delta: Option<f64>,
    #[serde(default)]
    pub condition: ConditionMode,
    /// Largest system solved with dense eigenvalues in `auto` mode.
    #[serde(default = "default_dense_limit")]
    pub dense_limit: usize,
    /// Dynamics (explicit or implicit): simulated time (s), split into `load_steps` equal steps.
    #[serde(default)]
    pub duration: Option<f64>,
    /// Dynamics: the mass matrix.
    #[serde(default)]
    pub mass: MassKind,
    /// Dynamics: ghost mass penalty `gamma_M` (kg/m^3; G (20));
    /// default a quarter of the largest material density (G 3.3).
    #[serde(default)]
    pub gamma_m: Option<f64>,
    #[serde(default)]
    pub stress_update: StressUpdate,
    #[serde(default)]
    pub velocity_update: VelocityUpdate,
    /// Implicit dynamics: the time integrator.
    #[serde(default)]
    pub integrator: Integrator,
    /// Implicit dynamics with `integrator = "bossak"`: Bossak's `alpha`,
    /// in `[-1/3, 0]` (0 is the trapezoidal rule).
    #[serde(default = "default_bossak_alpha")]
    pub bossak_alpha: f64,
    /// Explicit dynamics: mass condition numbers and the CFL number every
    /// this many steps (0: never; they need dense or Lanczos eigenvalues).
    #[serde(default = "one")]
    pub condition_every: usize,
    /// Explicit dynamics: a step fails as diverged when the kinetic plus
    /// strain energy exceeds this many times the initial energy plus the
    /// work done on the bodies.
    #[serde(default = "default_blowup")]
    pub blowup_factor: f64,
}

fn one() -> usize {
    1
}

fn yes() -> bool {
    true
}

fn default_bossak_alpha() -> f64 {
    -0.1
}

fn default_blowup() -> f64 {
    100.0
}

fn default_tolerance() -> f64 {
    1e-8
}

fn default_delta_over_h() -> f64 {
    1e-6
}

fn default_max_cutbacks() -> usize {
    4
}

fn default_max_iterations() -> usize {
    10
}

fn default_dense_limit() -> usize {
    1500
}

/// `[exact]`: an analytical solution to measure errors against.
#[derive(Clone, Debug, Deserialize)]
#[serde(tag = "name", rename_all = "kebab-case", deny_unknown_fields)]
pub enum ExactSpec {
    /// Column under self-weight, finite deformation (G (30)): Cauchy
    /// `s_yy = -rho0 g (top - Y)` at the original height `Y`.
    ColumnFinite { base: f64, top: f64 },
    /// Column under self-weight between rollers: `s_yy = -rho g (top - Y)`,
    /// with `base` the supported bottom (m). Uses the body's material and the
    /// scene's gravity.
    ColumnSelfWeight { base: f64, top: f64 },
    /// Uniaxial stress in y with free lateral faces: total strain
    /// `strain_yy`, `u = 0` at `anchor`.
    UniaxialY { strain_yy: f64, anchor: [f64; 2] },
    /// Uniform vertical stress `stress_yy` (Pa) with lateral confinement
    /// (`u_x = 0`), `u_y = 0` on `y = base`.
    ConfinedY {
        stress_yy: f64,
        base: f64,
        /// The block's frame is rotated by this angle about `about`: the
        /// stress is uniform in that frame and `base` a line `y' = base`
        /// there (unrotated coordinates).
        #[serde(default)]
        angle_deg: f64,
        #[serde(default)]
        about: [f64; 2],
    },
    /// Confined compression under finite deformation (Hencky): the block's
    /// frame stretched to `stretch` along y' at load factor 1 (linearly in
    /// the load factor), x' held; `u_y' = 0` on `y' = base`.
    ConfinedYFinite {
        stretch: f64,
        base: f64,
        #[serde(default)]
        angle_deg: f64,
        #[serde(default)]
        about: [f64; 2],
    },
    /// Thick cylinder (Lame) under internal pressure `pressure` (Pa) between
    /// radii `r_inner` and `r_outer` about `center`.
    Lame {
        pressure: f64,
        r_inner: f64,
        r_outer: f64,
        center: [f64; 2],
    },
    /// Infinite plate with a circular hole of `radius` at the origin under
    /// remote stress `stress` along x (Kirsch; B (42)-(46)).
    Kirsch { stress: f64, radius: f64 },
    /// Simple shear `u = (0, shear (x - x0))`, `s_xy = mu shear`.
    SimpleShear { shear: f64, x0: f64 },
    /// Explicit dynamics of stress-free bodies: each point keeps the initial
    /// velocity of its body (`velocity`, `velocity_gradient`), so its
    /// displacement is `t v0(X)` (G 5.1).
    FreeMotion {},
}

/// Largest scene file read (bytes).
pub const MAX_SCENE_BYTES: u64 = 4 << 20;

impl Scene {
    /// Parse scene text; `file` names it in errors. Besides syntax, keys
    /// and types, every real number must be finite and zero or of a
    /// magnitude in [`MIN_MAGNITUDE`, `MAX_MAGNITUDE`].
    pub fn parse(text: &str, file: &str) -> Result<Scene, SceneError> {
        let scene: Scene = toml::from_str(text).map_err(|e| from_toml(file, text, &e))?;
        let locator = Locator::new(text);
        locator.check_numbers().map_err(|e| locator.error(file, e))?;
        Ok(scene)
    }

    /// Read and parse a scene file.
    pub fn load(path: &Path) -> Result<(Scene, String), SceneError> {
        let file = path.display().to_string();
        let text = read_scene_text(path)?;
        let scene = Scene::parse(&text, &file)?;
        Ok((scene, text))
    }
}

/// The text of a scene file: a regular file (not a directory, FIFO or
/// device, which could block or never end) of at most [`MAX_SCENE_BYTES`],
/// in UTF-8 (the first invalid byte is located).
pub fn read_scene_text(path: &Path) -> Result<String, SceneError> {
    let file = path.display().to_string();
    let fail = |line: usize, column: usize, field: &str, message: String| SceneError {
        file: file.clone(),
        line,
        column,
        field: field.into(),
        message,
    };
    let bytes = read_regular_file(path, MAX_SCENE_BYTES).map_err(|r| {
        fail(
            0,
            0,
            "(file)",
            match r {
                Refusal::Io(reason) => format!("cannot read: {reason}"),
                Refusal::Directory => "is a directory, not a scene file".into(),
                Refusal::NotRegular(kind) => format!("is not a regular file ({kind}); give a scene file"),
                Refusal::TooLarge(Some(n)) => {
                    format!("is {n} bytes; scene files are limited to {MAX_SCENE_BYTES} bytes")
                }
                Refusal::TooLarge(None) => {
                    format!("is larger than the {MAX_SCENE_BYTES} bytes scene files are limited to")
                }
            },
        )
    })?;
    String::from_utf8(bytes).map_err(|e| {
        let at = e.utf8_error().valid_up_to();
        let valid = std::str::from_utf8(&e.as_bytes()[..at]).unwrap_or_default();
        let (line, column) = line_column(valid, at);
        let field = error::path_of_line(valid, line);
        fail(
            line,
            column,
            if field.is_empty() { "(top level)" } else { &field },
            format!(
                "the file is not UTF-8 text (byte 0x{:02X} at offset {at}); scene files are TOML text",
                e.as_bytes()[at]
            ),
        )
    })
}

/// Why an input file was not read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Refusal {
    /// The operating system's reason, in words.
    Io(String),
    Directory,
    /// Not a regular file: what it is (a FIFO, a device, ...), which could
    /// block a reader or never end.
    NotRegular(&'static str),
    /// Larger than the limit: its size, or None when it grew past the
    /// limit while being read.
    TooLarge(Option<u64>),
}

/// The bytes of the regular file at `path`, of at most `limit` bytes: a
/// directory, FIFO, socket or device is refused before it is opened, and
/// no more than `limit + 1` bytes are ever read.
pub fn read_regular_file(path: &Path, limit: u64) -> Result<Vec<u8>, Refusal> {
    let meta = std::fs::metadata(path).map_err(|e| Refusal::Io(io_reason(&e)))?;
    if meta.is_dir() {
        return Err(Refusal::Directory);
    }
    if !meta.is_file() {
        return Err(Refusal::NotRegular(file_kind(&meta)));
    }
    if meta.len() > limit {
        return Err(Refusal::TooLarge(Some(meta.len())));
    }
    use std::io::Read as _;
    let mut bytes = Vec::new();
    std::fs::File::open(path)
        .and_then(|f| f.take(limit.saturating_add(1)).read_to_end(&mut bytes))
        .map_err(|e| Refusal::Io(io_reason(&e)))?;
    if bytes.len() as u64 > limit {
        return Err(Refusal::TooLarge(None));
    }
    Ok(bytes)
}

/// What a file that is not a regular file is.
fn file_kind(meta: &std::fs::Metadata) -> &'static str {
    use std::os::unix::fs::FileTypeExt as _;
    let t = meta.file_type();
    if t.is_fifo() {
        "a FIFO"
    } else if t.is_socket() {
        "a socket"
    } else if t.is_char_device() {
        "a character device"
    } else if t.is_block_device() {
        "a block device"
    } else {
        "not a regular file"
    }
}

/// An I/O error in words, without the `(os error N)` suffix.
pub fn io_reason(e: &std::io::Error) -> String {
    use std::io::ErrorKind as K;
    match e.kind() {
        K::NotFound => "no such file or directory".into(),
        K::PermissionDenied => "permission denied".into(),
        K::IsADirectory => "is a directory".into(),
        K::StorageFull => "no space left on the device".into(),
        K::ReadOnlyFilesystem => "the file system is read-only".into(),
        _ => {
            let s = e.to_string();
            s.split(" (os error").next().unwrap_or(&s).to_string()
        }
    }
}
