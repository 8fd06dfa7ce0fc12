//! Region specifications in scene files and their conversion to
//! [`geometry::Region`](crate::geometry::Region).
//!
//! ```toml
//! [body.region]
//! shape = "difference"
//! base = { shape = "rectangle", min = [0.0, 0.0], max = [2.0, 2.0] }
//! subtract = [{ shape = "circle", center = [0.0, 0.0], radius = 0.5 }]
//! ```

use super::{number, FieldError};
use crate::boundary::bspline::BSpline;
use crate::geometry::{self, chords_for, Region, P2};
use serde::Deserialize;

/// A region: a primitive shape or a boolean combination, optionally rotated.
#[derive(Clone, Debug, Deserialize)]
#[serde(tag = "shape", rename_all = "kebab-case", deny_unknown_fields)]
pub enum RegionSpec {
    /// Axis-aligned rectangle `[min, max]` (m).
    Rectangle {
        min: P2,
        max: P2,
    },
    /// Simple polygon (any orientation, not self-intersecting).
    Polygon {
        vertices: Vec<P2>,
    },
    /// Disc of `radius` about `center`, flattened to chords within `tolerance` (m; default radius/1e4).
    Circle {
        center: P2,
        radius: f64,
        #[serde(default)]
        tolerance: Option<f64>,
    },
    /// Part of an annulus between `r_inner` and `r_outer`, angles in degrees
    /// counter-clockwise from +x.
    AnnulusSector {
        center: P2,
        r_inner: f64,
        r_outer: f64,
        start_deg: f64,
        end_deg: f64,
        #[serde(default)]
        tolerance: Option<f64>,
    },
    /// The area inside a B-spline through `points` (flattened to
    /// `per_segment` chords per segment, default 64). A closed spline
    /// (default) bounds the region itself; an open one is closed by straight
    /// lines through `close_via` back to its first point. `corners` as for
    /// boundaries.
    Spline {
        points: Vec<P2>,
        #[serde(default = "yes")]
        closed: bool,
        #[serde(default)]
        close_via: Vec<P2>,
        #[serde(default)]
        corners: Vec<usize>,
        #[serde(default)]
        per_segment: Option<usize>,
    },
    Union {
        parts: Vec<RegionSpec>,
    },
    Difference {
        base: Box<RegionSpec>,
        subtract: Vec<RegionSpec>,
    },
    /// The "ghost" emoji of G 5.1-5.3 in a `size x size` box with lower-left
    /// corner `min`: a dome head, straight sides, a zigzag hem of three
    /// points and two round eye holes ([`ghost_outline`]).
    Ghost {
        min: P2,
        size: f64,
    },
    /// `region` rotated by `angle_deg` (counter-clockwise) about `about`.
    Rotated {
        angle_deg: f64,
        about: P2,
        region: Box<RegionSpec>,
    },
}

fn yes() -> bool {
    true
}

/// Most vertices of one polygon, after curves are flattened to chords (the
/// self-intersection test and the triangulation grow with its square).
pub const MAX_VERTICES: usize = 10_000;
/// Most pieces (convex polygons with a sign) a region may have after its
/// unions and differences are expanded: `A u B` has up to
/// `|A| + |B| + |A| |B|` of them.
pub const MAX_PIECES: usize = 20_000;
/// Most parts of a union or subtracted regions of a difference.
pub const MAX_PARTS: usize = 1_000;
/// Most chords per spline segment.
pub const MAX_PER_SEGMENT: usize = 1_024;

/// Chords for an arc of radius `r` sweeping `sweep` radians within chord
/// error `tol`, at most [`MAX_VERTICES`]; `field` names the tolerance.
fn chord_count(r: f64, tol: f64, sweep: f64, field: &str, given: bool) -> Result<usize, FieldError> {
    if !(tol > 0.0 && tol.is_finite()) {
        return Err(FieldError::new(field, format!("must be positive, got {}", number(tol))));
    }
    // chords_for in floating point, before any conversion to a count.
    let t = (1.0 - (tol / r).min(1.0)).clamp(-1.0, 1.0);
    let n = sweep / (2.0 * t.acos());
    if !(n <= MAX_VERTICES as f64) {
        // Chord error r (1 - cos(a/2)) with a = sweep / MAX_VERTICES.
        let least = r * (1.0 - (0.5 * sweep / MAX_VERTICES as f64).cos());
        return Err(FieldError::new(
            field,
            format!(
                "{} needs more than {MAX_VERTICES} chords for radius {}; use a tolerance of at least {}",
                if given {
                    format!("tolerance {}", number(tol))
                } else {
                    "the default tolerance".into()
                },
                number(r),
                number(least * 1.01)
            ),
        ));
    }
    Ok(chords_for(r, tol, sweep))
}

/// Refuse a boolean combination whose expansion would exceed [`MAX_PIECES`].
fn check_pieces(a: &Region, b: &Region, field: &str) -> Result<(), FieldError> {
    let (na, nb) = (a.pieces.len() as u128, b.pieces.len() as u128);
    if na + nb + na * nb > MAX_PIECES as u128 {
        return Err(FieldError::new(
            field,
            format!(
                "combining regions of {na} and {nb} convex pieces may need up to {} pieces, more than the {MAX_PIECES} supported; use fewer or simpler parts",
                na + nb + na * nb
            ),
        ));
    }
    Ok(())
}

/// A vertex lying on an edge it does not belong to (a figure eight, a
/// spike back along an edge): the polygon is not simple although no two
/// edges cross properly.
fn touches_itself(poly: &[P2]) -> Option<usize> {
    let n = poly.len();
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in poly {
        for d in 0..2 {
            lo[d] = lo[d].min(p[d]);
            hi[d] = hi[d].max(p[d]);
        }
    }
    let tol = 1e-12 * (hi[0] - lo[0]).hypot(hi[1] - lo[1]);
    for (i, v) in poly.iter().enumerate() {
        for j in 0..n {
            let k = (j + 1) % n;
            if j == i || k == i {
                continue;
            }
            let (a, b) = (poly[j], poly[k]);
            // Quick rejection by the edge's box.
            if v[0] < a[0].min(b[0]) - tol
                || v[0] > a[0].max(b[0]) + tol
                || v[1] < a[1].min(b[1]) - tol
                || v[1] > a[1].max(b[1]) + tol
            {
                continue;
            }
            let e = [b[0] - a[0], b[1] - a[1]];
            let len2 = e[0] * e[0] + e[1] * e[1];
            let t = if len2 > 0.0 {
                (((v[0] - a[0]) * e[0] + (v[1] - a[1]) * e[1]) / len2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let d = (v[0] - a[0] - t * e[0]).hypot(v[1] - a[1] - t * e[1]);
            if d <= tol {
                return Some(i);
            }
        }
    }
    None
}

fn finite(field: &str, v: &[f64]) -> Result<(), FieldError> {
    if v.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(FieldError::new(field, "must be finite"))
    }
}

impl RegionSpec {
    /// Build the region; `path` is this spec's field path for errors.
    pub fn build(&self, path: &str) -> Result<Region, FieldError> {
        match self {
            RegionSpec::Rectangle { min, max } => rectangle(min, max, path),
            RegionSpec::Polygon { vertices } => polygon(vertices, path),
            RegionSpec::Circle {
                center,
                radius,
                tolerance,
            } => circle(center, *radius, *tolerance, path),
            RegionSpec::AnnulusSector {
                center,
                r_inner,
                r_outer,
                start_deg,
                end_deg,
                tolerance,
            } => annulus_sector(center, *r_inner, *r_outer, *start_deg, *end_deg, *tolerance, path),
            RegionSpec::Spline {
                points,
                closed,
                close_via,
                corners,
                per_segment,
            } => spline(points, *closed, close_via, corners, *per_segment, path),
            RegionSpec::Union { parts } => union(parts, path),
            RegionSpec::Difference { base, subtract } => difference(base, subtract, path),
            RegionSpec::Ghost { min, size } => ghost(min, *size, path),
            RegionSpec::Rotated {
                angle_deg,
                about,
                region,
            } => rotated(*angle_deg, about, region, path),
        }
    }
}

/// `rectangle`: finite corners with `max` above and right of `min`.
fn rectangle(min: &P2, max: &P2, path: &str) -> Result<Region, FieldError> {
    let f = |name: &str| format!("{path}.{name}");
    finite(&f("min"), min)?;
    finite(&f("max"), max)?;
    if !(max[0] > min[0] && max[1] > min[1]) {
        return Err(FieldError::new(f("max"), "must exceed `min` in both coordinates"));
    }
    Ok(Region::convex(vec![*min, [max[0], min[1]], *max, [min[0], max[1]]]))
}

/// `polygon`: a simple polygon of positive area, one convex piece or
/// triangulated.
fn polygon(vertices: &[P2], path: &str) -> Result<Region, FieldError> {
    let field = format!("{path}.vertices");
    let poly = simple_polygon(vertices, &field)?;
    if geometry::is_convex(&poly) {
        return Ok(Region::convex(poly));
    }
    let tris = geometry::triangulate(&poly)
        .ok_or_else(|| FieldError::new(field.as_str(), "the polygon could not be triangulated"))?;
    Ok(Region {
        pieces: tris
            .into_iter()
            .map(|t| geometry::Piece::new(1.0, t.to_vec()))
            .collect(),
    })
}

/// The polygon's vertices checked (count, finite, simple, positive area)
/// and returned counter-clockwise without collinear vertices; `field`
/// names the vertices.
fn simple_polygon(vertices: &[P2], field: &str) -> Result<Vec<P2>, FieldError> {
    if vertices.len() < 3 {
        return Err(FieldError::new(field, "a polygon needs at least 3 vertices"));
    }
    if vertices.len() > MAX_VERTICES {
        return Err(FieldError::new(
            field,
            format!(
                "{} vertices are more than the {MAX_VERTICES} a polygon may have",
                vertices.len()
            ),
        ));
    }
    finite(field, &vertices.concat())?;
    if geometry::self_intersects(vertices) {
        return Err(FieldError::new(field, "the polygon crosses itself"));
    }
    let poly = geometry::ccw(geometry::drop_collinear(vertices));
    // Dropping collinear vertices can turn a crossing through a
    // shared vertex into a proper one.
    if geometry::self_intersects(&poly) {
        return Err(FieldError::new(field, "the polygon crosses itself"));
    }
    // A vertex on another edge first: a bowtie whose crossing is a
    // vertex has zero area but is really a self-touching outline.
    if let Some(i) = touches_itself(&poly).filter(|_| poly.len() > 3) {
        return Err(FieldError::new(
            field,
            format!(
                "the polygon touches itself at ({}, {}): a vertex lies on another edge",
                number(poly[i][0]),
                number(poly[i][1])
            ),
        ));
    }
    if geometry::area_centroid(&poly).0 <= 0.0 {
        return Err(FieldError::new(field, "the polygon has zero area"));
    }
    Ok(poly)
}

/// `circle`: a disc flattened to chords within `tolerance` (default
/// radius/1e4).
fn circle(center: &P2, radius: f64, tolerance: Option<f64>, path: &str) -> Result<Region, FieldError> {
    let f = |name: &str| format!("{path}.{name}");
    finite(&f("center"), center)?;
    if !(radius > 0.0 && radius.is_finite()) {
        return Err(FieldError::new(f("radius"), "must be positive"));
    }
    let tol = tolerance.unwrap_or(radius * 1e-4);
    let n = chord_count(radius, tol, std::f64::consts::TAU, &f("tolerance"), tolerance.is_some())?;
    let poly = (0..n)
        .map(|k| {
            let t = std::f64::consts::TAU * k as f64 / n as f64;
            [center[0] + radius * t.cos(), center[1] + radius * t.sin()]
        })
        .collect();
    Ok(Region::convex(poly))
}

/// `annulus-sector`: between radii `r_inner` and `r_outer` and angles
/// `start_deg` and `end_deg`, one convex piece per angular chord.
fn annulus_sector(
    center: &P2,
    r_inner: f64,
    r_outer: f64,
    start_deg: f64,
    end_deg: f64,
    tolerance: Option<f64>,
    path: &str,
) -> Result<Region, FieldError> {
    let f = |name: &str| format!("{path}.{name}");
    finite(&f("center"), center)?;
    if !(r_inner >= 0.0) {
        return Err(FieldError::new(f("r_inner"), "must be non-negative"));
    }
    if !(r_outer > r_inner && r_outer.is_finite()) {
        return Err(FieldError::new(f("r_outer"), "must exceed `r_inner`"));
    }
    finite(&f("start_deg"), &[start_deg])?;
    finite(&f("end_deg"), &[end_deg])?;
    let sweep = (end_deg - start_deg).to_radians();
    if !(sweep > 0.0 && sweep <= std::f64::consts::TAU + 1e-12) {
        return Err(FieldError::new(f("end_deg"), "must exceed `start_deg` by at most 360"));
    }
    let tol = tolerance.unwrap_or(r_outer * 1e-4);
    let n = chord_count(r_outer, tol, sweep, &f("tolerance"), tolerance.is_some())?.max(2);
    let at = |r: f64, k: usize| {
        let t = start_deg.to_radians() + sweep * k as f64 / n as f64;
        [center[0] + r * t.cos(), center[1] + r * t.sin()]
    };
    // Each angular slice is a convex trapezoid (or a triangle at r_inner = 0).
    let pieces = (0..n)
        .map(|k| {
            let mut q = vec![at(r_inner, k), at(r_outer, k), at(r_outer, k + 1), at(r_inner, k + 1)];
            if r_inner == 0.0 {
                q.remove(3);
            }
            geometry::Piece::new(1.0, geometry::ccw(q))
        })
        .collect();
    Ok(Region { pieces })
}

/// `spline`: the B-spline flattened to a polygon (closed by `close_via`
/// when open), then built as one.
fn spline(
    points: &[P2],
    closed: bool,
    close_via: &[P2],
    corners: &[usize],
    per_segment: Option<usize>,
    path: &str,
) -> Result<Region, FieldError> {
    let f = |name: &str| format!("{path}.{name}");
    finite(&f("points"), &points.concat())?;
    let per = per_segment.unwrap_or(64);
    if !(1..=MAX_PER_SEGMENT).contains(&per) {
        return Err(FieldError::new(
            f("per_segment"),
            format!("must be between 1 and {MAX_PER_SEGMENT}, got {per}"),
        ));
    }
    let vertices = (points.len() as u128 + 1) * per as u128 + close_via.len() as u128;
    if vertices > MAX_VERTICES as u128 {
        return Err(FieldError::new(
            if per_segment.is_some() { f("per_segment") } else { f("points") },
            format!(
                "{} points at {per} chords per segment make about {vertices} vertices, more than the {MAX_VERTICES} a polygon may have",
                points.len()
            ),
        ));
    }
    let mut marks = vec![false; points.len()];
    for &c in corners {
        *marks
            .get_mut(c)
            .ok_or_else(|| FieldError::new(f("corners"), format!("no point {c}")))? = true;
    }
    let spline =
        BSpline::interpolate(points, closed, &marks).map_err(|e| FieldError::new(f("points"), e.to_string()))?;
    let mut poly = spline.sample(per);
    if closed {
        poly.pop(); // the last sample repeats the first
    } else {
        finite(&f("close_via"), &close_via.concat())?;
        poly.extend(close_via.iter().copied());
    }
    RegionSpec::Polygon { vertices: poly }.build(path)
}

/// `union`: the parts joined in order, each join checked against
/// [`MAX_PIECES`].
fn union(parts: &[RegionSpec], path: &str) -> Result<Region, FieldError> {
    let field = format!("{path}.parts");
    if parts.is_empty() {
        return Err(FieldError::new(field, "a union needs at least one part"));
    }
    if parts.len() > MAX_PARTS {
        return Err(FieldError::new(
            field,
            format!("{} parts are more than the {MAX_PARTS} a union may have", parts.len()),
        ));
    }
    let mut r = parts[0].build(&format!("{path}.parts[0]"))?;
    for (k, p) in parts.iter().enumerate().skip(1) {
        let field = format!("{path}.parts[{k}]");
        let q = p.build(&field)?;
        check_pieces(&r, &q, &field)?;
        r = r.union(&q);
    }
    Ok(r)
}

/// `difference`: `base` less each of `subtract` in order, each step
/// checked against [`MAX_PIECES`].
fn difference(base: &RegionSpec, subtract: &[RegionSpec], path: &str) -> Result<Region, FieldError> {
    if subtract.len() > MAX_PARTS {
        return Err(FieldError::new(
            format!("{path}.subtract"),
            format!(
                "{} regions are more than the {MAX_PARTS} a difference may subtract",
                subtract.len()
            ),
        ));
    }
    let mut r = base.build(&format!("{path}.base"))?;
    for (k, p) in subtract.iter().enumerate() {
        let field = format!("{path}.subtract[{k}]");
        let q = p.build(&field)?;
        check_pieces(&r, &q, &field)?;
        r = r.difference(&q);
    }
    Ok(r)
}

/// `ghost`: [`ghost_outline`] less its eyes, built as a difference.
fn ghost(min: &P2, size: f64, path: &str) -> Result<Region, FieldError> {
    finite(&format!("{path}.min"), min)?;
    if !(size > 0.0 && size.is_finite()) {
        return Err(FieldError::new(format!("{path}.size"), "must be positive"));
    }
    let (outline, eyes) = ghost_outline(*min, size);
    RegionSpec::Difference {
        base: Box::new(RegionSpec::Polygon { vertices: outline }),
        subtract: eyes
            .into_iter()
            .map(|(center, radius)| RegionSpec::Circle {
                center,
                radius,
                tolerance: None,
            })
            .collect(),
    }
    .build(path)
}

/// `rotated`: `region` turned by `angle_deg` about `about`.
fn rotated(angle_deg: f64, about: &P2, region: &RegionSpec, path: &str) -> Result<Region, FieldError> {
    finite(&format!("{path}.angle_deg"), &[angle_deg])?;
    finite(&format!("{path}.about"), about)?;
    Ok(region
        .build(&format!("{path}.region"))?
        .rotated(*about, angle_deg.to_radians()))
}

/// Area of the ghost over the area of its box. G 5.2 gives the initial
/// energy W0 = 2.14726 J of two ghosts of density 1000 kg/m^3 moving at
/// |v| = 0.1 sqrt(2) m/s, so each ghost has 2.14726 / 20 = 0.107363 m^2 in
/// a 0.4 m box: a fraction 0.671019.
pub const GHOST_AREA_FRACTION: f64 = 0.671019;

/// Eye radius over the box size.
const GHOST_EYE: f64 = 0.12;

/// The ghost's outline (counter-clockwise) and its eyes `(centre, radius)`.
/// In units of the box: a semicircular head of radius 1/2 on a unit-wide
/// body of height 1/2 whose hem has two triangular notches of depth `t`;
/// `t` is chosen so that the area is [`GHOST_AREA_FRACTION`] of the box.
pub fn ghost_outline(min: P2, size: f64) -> (Vec<P2>, Vec<(P2, f64)>) {
    use std::f64::consts::PI;
    // head + body - notches - eyes = PI/8 + 1/2 - t/2 - 2 PI r_e^2.
    let t = 2.0 * (PI / 8.0 + 0.5 - 2.0 * PI * GHOST_EYE * GHOST_EYE - GHOST_AREA_FRACTION);
    let at = |x: f64, y: f64| [min[0] + size * x, min[1] + size * y];
    let mut outline = vec![at(0.0, 0.0), at(0.25, t), at(0.5, 0.0), at(0.75, t), at(1.0, 0.0)];
    let n = 64;
    for k in 0..=n {
        let a = PI * k as f64 / n as f64;
        outline.push(at(0.5 + 0.5 * a.cos(), 0.5 + 0.5 * a.sin()));
    }
    let eyes = vec![(at(0.32, 0.6), GHOST_EYE * size), (at(0.68, 0.6), GHOST_EYE * size)];
    (outline, eyes)
}
