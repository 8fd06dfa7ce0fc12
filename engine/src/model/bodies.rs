//! `[[body]]`: regions filled with material points.

use super::*;

/// The bodies, their regions, each body's range of points, and the points.
#[allow(clippy::type_complexity)]
pub(super) fn build(
    scene: &Scene,
    grid: &Grid,
    materials: &[Material],
    budget: &mut Budget,
) -> Result<(Vec<Body>, Vec<Region>, Vec<std::ops::Range<usize>>, Points), FieldError> {
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
        let (most, field) = budget.body(k, b, &region, grid)?;
        // The points are pushed one by one: reserve them first, so memory
        // that cannot be had is this error, not an abort.
        points.try_reserve(most).map_err(|bytes| {
            FieldError::new(
                field.clone(),
                format!(
                    "cannot allocate {} for up to {most} points of this body; use fewer points",
                    crate::model::bytes(bytes)
                ),
            )
        })?;
        let before = points.len();
        let density = materials[material].density();
        if b.placement == Placement::Polar {
            polar_points(b, density, k, &mut points).map_err(|(field, m)| FieldError::new(f(field), m))?;
        } else if b.placement == Placement::Lattice {
            lattice_points(b, &region, density, k, &mut points).map_err(|(field, m)| FieldError::new(f(field), m))?;
        } else {
            generate_points(grid, &region, b.points_per_cell, b.placement, density, k, &mut points)
                .map_err(|m| FieldError::new(f("placement"), m))?;
        }
        if points.len() == before {
            return Err(FieldError::new(
                f("region"),
                "the body is empty: no cell overlaps its region",
            ));
        }
        if let Some(m) = &b.velocity_mode {
            let finite = m
                .amplitude
                .iter()
                .chain(&m.origin)
                .chain(&m.axis)
                .all(|v| v.is_finite());
            if !(finite && m.length > 0.0 && m.length.is_finite()) || m.axis[0].hypot(m.axis[1]) == 0.0 {
                return Err(FieldError::new(
                    f("velocity_mode"),
                    "needs finite amplitude and origin, a non-zero axis and a positive length",
                ));
            }
        }
        let moving = b.velocity != [0.0; 2] || b.velocity_gradient.is_some() || b.velocity_mode.is_some();
        if moving && !scene.analysis.kind.is_dynamic() {
            return Err(FieldError::new(
                f("velocity"),
                "initial velocities need kind = \"explicit-dynamics\" or \"dynamic-implicit\"",
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
            let mode = b.velocity_mode.as_ref().map_or([0.0; 2], |m| m.at(points.x[p]));
            points.v[p] = [
                b.velocity[0] + l[0][0] * d[0] + l[0][1] * d[1] + mode[0],
                b.velocity[1] + l[1][0] * d[0] + l[1][1] * d[1] + mode[1],
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

    Ok((bodies, regions, ranges, points))
}

/// The smallest piece of a cell (or sub-cell), as a fraction of its area,
/// that clipping turns into a point; smaller pieces are left out.
///
/// A corner of a body cut at a small angle to the grid pokes into the
/// diagonal cell as a triangle of a tiny area. Its point is then the only
/// material of up to three nodes, which it holds with a stiffness as small
/// as its area: the system is singular to round-off. The confined block of
/// C 5.1 turned within 0.6 degrees of each grid axis (560 angles) failed
/// to factorise wherever that tip was 1.7e-12 to 9.2e-11 of a cell, and
/// at no angle where it was larger. Leaving out pieces below 1e-9 of a
/// cell keeps a factor of 10 above that, and loses at most 1e-9 of a
/// cell's area per cell the boundary cuts.
pub(super) const MIN_PIECE: f64 = 1e-9;

/// Fill `region` with points: per cell, `n x n` sub-cells clipped against the
/// region (point at the clipped centroid, volume = clipped area; C Fig. 4),
/// sub-cell centres inside the region ([`Placement::Centres`]), or `n x n`
/// Gauss points ([`Placement::Gauss`]). GIMP half-lengths are the
/// clipped extent scaled so that `4 l_x l_y = V`. Clipped pieces smaller
/// than [`MIN_PIECE`] of their (sub-)cell are left out.
pub(super) fn generate_points(
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
            if cell.area <= MIN_PIECE * h * h {
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
                    if c.area <= MIN_PIECE * sub * sub {
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
pub(super) fn polar_points(
    b: &BodySpec,
    density: f64,
    body: usize,
    pts: &mut Points,
) -> Result<(), (&'static str, String)> {
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
pub(super) fn lattice_points(
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
pub(super) fn layer_points(
    pts: &Points,
    range: std::ops::Range<usize>,
    side: LayerSide,
    center: P2,
    tol: f64,
) -> Vec<usize> {
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
