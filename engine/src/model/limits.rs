//! What a scene may ask for: names, counts and the memory budget.

use super::*;

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

pub use crate::procfs::available_memory;

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

/// A coordinate for a message: four decimals when that shows it, else
/// [`number`].
pub(super) fn short(x: f64) -> String {
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
pub(super) fn check_names(scene: &Scene) -> Result<(), FieldError> {
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

/// Tracking points of all boundaries, and vertices of all implicit
/// boundaries, together: each at most [`MAX_CURVE_POINTS`].
pub(super) fn check_curve_totals(scene: &Scene) -> Result<(), FieldError> {
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
    Ok(())
}

/// The memory estimate of a model, grown body by body before each body's
/// points are generated, and the work of generating them.
pub(super) struct Budget {
    max: u64,
    kind: crate::scene::AnalysisKind,
    grid_nodes: u128,
    points: u128,
    active: u128,
    condition: crate::scene::ConditionMode,
    dense_limit: u128,
}

impl Budget {
    pub(super) fn new(scene: &Scene, grid: &Grid, limits: &Limits) -> Result<Budget, FieldError> {
        let b = Budget {
            max: limits.max_memory,
            kind: scene.analysis.kind,
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
    pub(super) fn dense(&self) -> u128 {
        let dofs = 2 * self.active.min(self.grid_nodes);
        let n = match self.condition {
            crate::scene::ConditionMode::Dense => dofs,
            crate::scene::ConditionMode::Auto => dofs.min(self.dense_limit),
            _ => 0,
        };
        3 * 8 * n * n
    }

    pub(super) fn total(&self) -> u128 {
        BASE_BYTES as u128
            + self.grid_nodes * bytes_per_grid_node(self.kind) as u128
            + self.points * bytes_per_point(self.kind) as u128
            + self.active.min(self.grid_nodes) * BYTES_PER_ACTIVE_NODE as u128
            + self.dense()
    }

    pub(super) fn check(&self, field: String, advice: &str) -> Result<(), FieldError> {
        let total = self.total();
        if total <= self.max as u128 {
            return Ok(());
        }
        let dense = self.dense();
        let points = self.points * bytes_per_point(self.kind) as u128;
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
                "the model needs an estimated {} ({} for the program + {} points x {} + {} grid nodes x {} + {} active nodes x {}{}), more than the {} allowed (--max-memory; default half of the available memory); {advice}",
                bytes(total.min(u64::MAX as u128) as u64),
                bytes(BASE_BYTES),
                self.points,
                bytes(bytes_per_point(self.kind)),
                self.grid_nodes,
                bytes(bytes_per_grid_node(self.kind)),
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
    /// Charge body `k`'s points (at most the cells its region's bounding
    /// box covers times its points per cell, or its lattice or polar
    /// count) and return that bound with the field that sets it, or the
    /// field to change.
    pub(super) fn body(
        &mut self,
        k: usize,
        b: &BodySpec,
        region: &Region,
        grid: &Grid,
    ) -> Result<(usize, String), FieldError> {
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
        self.check(field.clone(), advice)?;
        // Below MAX_POINTS, checked above.
        Ok((count as usize, field))
    }
}
