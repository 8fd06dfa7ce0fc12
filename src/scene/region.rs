//! Region specifications in scene files and their conversion to
//! [`geometry::Region`](crate::geometry::Region).
//!
//! ```toml
//! [body.region]
//! shape = "difference"
//! base = { shape = "rectangle", min = [0.0, 0.0], max = [2.0, 2.0] }
//! subtract = [{ shape = "circle", center = [0.0, 0.0], radius = 0.5 }]
//! ```

use super::FieldError;
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
        let f = |name: &str| format!("{path}.{name}");
        match self {
            RegionSpec::Rectangle { min, max } => {
                finite(&f("min"), min)?;
                finite(&f("max"), max)?;
                if !(max[0] > min[0] && max[1] > min[1]) {
                    return Err(FieldError::new(f("max"), "must exceed `min` in both coordinates"));
                }
                Ok(Region::convex(vec![*min, [max[0], min[1]], *max, [min[0], max[1]]]))
            }
            RegionSpec::Polygon { vertices } => {
                if vertices.len() < 3 {
                    return Err(FieldError::new(f("vertices"), "a polygon needs at least 3 vertices"));
                }
                finite(&f("vertices"), &vertices.concat())?;
                if geometry::self_intersects(vertices) {
                    return Err(FieldError::new(f("vertices"), "the polygon crosses itself"));
                }
                let poly = geometry::ccw(geometry::drop_collinear(vertices));
                if geometry::area_centroid(&poly).0 <= 0.0 {
                    return Err(FieldError::new(f("vertices"), "the polygon has zero area"));
                }
                if geometry::is_convex(&poly) {
                    return Ok(Region::convex(poly));
                }
                let tris = geometry::triangulate(&poly)
                    .ok_or_else(|| FieldError::new(f("vertices"), "the polygon could not be triangulated"))?;
                Ok(Region {
                    pieces: tris
                        .into_iter()
                        .map(|t| geometry::Piece::new(1.0, t.to_vec()))
                        .collect(),
                })
            }
            RegionSpec::Circle {
                center,
                radius,
                tolerance,
            } => {
                finite(&f("center"), center)?;
                if !(*radius > 0.0 && radius.is_finite()) {
                    return Err(FieldError::new(f("radius"), "must be positive"));
                }
                let tol = tolerance.unwrap_or(radius * 1e-4);
                if !(tol > 0.0) {
                    return Err(FieldError::new(f("tolerance"), "must be positive"));
                }
                let n = chords_for(*radius, tol, std::f64::consts::TAU);
                let poly = (0..n)
                    .map(|k| {
                        let t = std::f64::consts::TAU * k as f64 / n as f64;
                        [center[0] + radius * t.cos(), center[1] + radius * t.sin()]
                    })
                    .collect();
                Ok(Region::convex(poly))
            }
            RegionSpec::AnnulusSector {
                center,
                r_inner,
                r_outer,
                start_deg,
                end_deg,
                tolerance,
            } => {
                finite(&f("center"), center)?;
                if !(*r_inner >= 0.0) {
                    return Err(FieldError::new(f("r_inner"), "must be non-negative"));
                }
                if !(r_outer > r_inner && r_outer.is_finite()) {
                    return Err(FieldError::new(f("r_outer"), "must exceed `r_inner`"));
                }
                let sweep = (end_deg - start_deg).to_radians();
                if !(sweep > 0.0 && sweep <= std::f64::consts::TAU + 1e-12) {
                    return Err(FieldError::new(f("end_deg"), "must exceed `start_deg` by at most 360"));
                }
                let tol = tolerance.unwrap_or(r_outer * 1e-4);
                let n = chords_for(*r_outer, tol, sweep).max(2);
                let at = |r: f64, k: usize| {
                    let t = start_deg.to_radians() + sweep * k as f64 / n as f64;
                    [center[0] + r * t.cos(), center[1] + r * t.sin()]
                };
                // Each angular slice is a convex trapezoid (or a triangle at r_inner = 0).
                let pieces = (0..n)
                    .map(|k| {
                        let mut q = vec![
                            at(*r_inner, k),
                            at(*r_outer, k),
                            at(*r_outer, k + 1),
                            at(*r_inner, k + 1),
                        ];
                        if *r_inner == 0.0 {
                            q.remove(3);
                        }
                        geometry::Piece::new(1.0, geometry::ccw(q))
                    })
                    .collect();
                Ok(Region { pieces })
            }
            RegionSpec::Spline {
                points,
                closed,
                close_via,
                corners,
                per_segment,
            } => {
                finite(&f("points"), &points.concat())?;
                let mut marks = vec![false; points.len()];
                for &c in corners {
                    *marks
                        .get_mut(c)
                        .ok_or_else(|| FieldError::new(f("corners"), format!("no point {c}")))? = true;
                }
                let spline = BSpline::interpolate(points, *closed, &marks)
                    .map_err(|e| FieldError::new(f("points"), e.to_string()))?;
                let mut poly = spline.sample(per_segment.unwrap_or(64).max(1));
                if *closed {
                    poly.pop(); // the last sample repeats the first
                } else {
                    finite(&f("close_via"), &close_via.concat())?;
                    poly.extend(close_via.iter().copied());
                }
                RegionSpec::Polygon { vertices: poly }.build(path)
            }
            RegionSpec::Union { parts } => {
                if parts.is_empty() {
                    return Err(FieldError::new(f("parts"), "a union needs at least one part"));
                }
                let mut r = parts[0].build(&format!("{path}.parts[0]"))?;
                for (k, p) in parts.iter().enumerate().skip(1) {
                    r = r.union(&p.build(&format!("{path}.parts[{k}]"))?);
                }
                Ok(r)
            }
            RegionSpec::Difference { base, subtract } => {
                let mut r = base.build(&f("base"))?;
                for (k, p) in subtract.iter().enumerate() {
                    r = r.difference(&p.build(&format!("{path}.subtract[{k}]"))?);
                }
                Ok(r)
            }
            RegionSpec::Ghost { min, size } => {
                finite(&f("min"), min)?;
                if !(*size > 0.0 && size.is_finite()) {
                    return Err(FieldError::new(f("size"), "must be positive"));
                }
                let (outline, eyes) = ghost_outline(*min, *size);
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
            RegionSpec::Rotated {
                angle_deg,
                about,
                region,
            } => {
                finite(&f("angle_deg"), &[*angle_deg])?;
                finite(&f("about"), about)?;
                Ok(region.build(&f("region"))?.rotated(*about, angle_deg.to_radians()))
            }
        }
    }
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
