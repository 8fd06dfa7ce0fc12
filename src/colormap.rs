//! A perceptually ordered colour map (viridis, piecewise linear through 9
//! stops) for colouring points by a field, shared by the TUI and recordings.

const STOPS: [[u8; 3]; 9] = [
    [68, 1, 84],
    [71, 44, 122],
    [59, 81, 139],
    [44, 113, 142],
    [33, 144, 141],
    [39, 173, 129],
    [92, 200, 99],
    [170, 220, 50],
    [253, 231, 37],
];

/// Colour of `t` in [0, 1] (clamped; NaN maps to grey).
pub fn viridis(t: f64) -> [u8; 3] {
    if !t.is_finite() {
        return [128, 128, 128];
    }
    let s = t.clamp(0.0, 1.0) * (STOPS.len() - 1) as f64;
    let k = (s.floor() as usize).min(STOPS.len() - 2);
    let f = s - k as f64;
    let (a, b) = (STOPS[k], STOPS[k + 1]);
    [0, 1, 2].map(|i| (a[i] as f64 + f * (b[i] as f64 - a[i] as f64)).round() as u8)
}

/// Range `(min, max)` of the finite values; `(0, 0)` when there are none.
/// The two are equal for a constant field.
pub fn range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if lo > hi {
        return (0.0, 0.0);
    }
    (lo, hi)
}

/// Position of `v` in `[lo, hi]` as a number in [0, 1] (0.5 for a constant field).
pub fn unit(v: f64, lo: f64, hi: f64) -> f64 {
    if hi > lo {
        ((v - lo) / (hi - lo)).clamp(0.0, 1.0)
    } else {
        0.5
    }
}

/// A diverging map (after Moreland's cool-warm), blue through a light grey
/// centre to red, for signed fields: every colour stays readable on the
/// viewer's dark background and on a light one.
const DIVERGING: [[u8; 3]; 5] = [
    [59, 76, 192],
    [141, 176, 254],
    [221, 221, 221],
    [244, 154, 123],
    [180, 4, 38],
];

/// Piecewise-linear interpolation through `stops` at `t` in [0, 1].
fn through(stops: &[[u8; 3]], t: f64) -> [u8; 3] {
    let s = t.clamp(0.0, 1.0) * (stops.len() - 1) as f64;
    let k = (s.floor() as usize).min(stops.len() - 2);
    let f = s - k as f64;
    let (a, b) = (stops[k], stops[k + 1]);
    [0, 1, 2].map(|i| (a[i] as f64 + f * (b[i] as f64 - a[i] as f64)).round() as u8)
}

/// How a field's values map to colours: a diverging map over a range
/// centred at zero for a signed field, the upper four fifths of viridis
/// (its darkest fifth vanishes on a dark background) from zero for a
/// magnitude. A uniform field is one colour, never a stretched gradient.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Scale {
    pub signed: bool,
    pub lo: f64,
    pub hi: f64,
}

/// The share of the points whose values may lie beyond a frame's scale
/// (drawn at its ends): a few points far off the field (a clipped sliver
/// of volume at a hole's edge, a node held by almost no material) would
/// otherwise stretch the map until the field itself is one colour.
pub const OUTLIERS: f64 = 0.005;

impl Scale {
    /// The scale of `values`: `[-m, m]` for a signed field, `[min(0, lo),
    /// m]` for a magnitude, with `m` the largest `|v|` (magnitude: `v`)
    /// once the [`OUTLIERS`] share of the largest is set aside.
    pub fn of(values: impl Iterator<Item = f64>, signed: bool) -> Scale {
        let mut v: Vec<f64> = values.filter(|v| v.is_finite()).collect();
        if v.is_empty() {
            return Scale::spanning(0.0, 0.0, signed);
        }
        let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
        if signed {
            v.iter_mut().for_each(|x| *x = x.abs());
        }
        // The value below which all but the largest OUTLIERS share lie.
        let k = ((v.len() as f64) * (1.0 - OUTLIERS)).ceil() as usize;
        let k = k.clamp(1, v.len()) - 1;
        let (_, m, _) = v.select_nth_unstable_by(k, f64::total_cmp);
        let m = *m;
        if signed {
            Scale::spanning(-m, m, true)
        } else {
            Scale::spanning(lo.min(m), m, false)
        }
    }

    /// How many of `values` lie outside the scale (drawn at its ends).
    pub fn beyond(&self, values: &[f64]) -> usize {
        values.iter().filter(|v| **v < self.lo || **v > self.hi).count()
    }

    fn spanning(lo: f64, hi: f64, signed: bool) -> Scale {
        if signed {
            let m = lo.abs().max(hi.abs());
            Scale { signed, lo: -m, hi: m }
        } else {
            Scale {
                signed,
                lo: lo.min(0.0),
                hi: hi.max(0.0),
            }
        }
    }

    /// The smallest scale holding this one and `other` (a run's scale
    /// over its frames).
    pub fn widen(self, other: Scale) -> Scale {
        Scale::spanning(self.lo.min(other.lo), self.hi.max(other.hi), self.signed)
    }

    /// The colour of `v` (grey for NaN).
    pub fn colour(&self, v: f64) -> [u8; 3] {
        if !v.is_finite() {
            return [128, 128, 128];
        }
        let t = unit(v, self.lo, self.hi);
        if self.signed {
            through(&DIVERGING, t)
        } else {
            viridis(0.2 + 0.8 * t)
        }
    }

    /// `n` evenly spaced tick values from `lo` to `hi` (zero among them
    /// for a signed scale and odd `n`).
    pub fn ticks(&self, n: usize) -> Vec<f64> {
        let n = n.max(2);
        (0..n)
            .map(|k| self.lo + (self.hi - self.lo) * k as f64 / (n - 1) as f64)
            .collect()
    }
}

/// What the values of a frame are, in words: `uniform V ± S` when their
/// spread is below 1e-6 of their size (or all are zero); `V ± S (R of the
/// value)` when it is below 1e-3 (a range printed to four digits would
/// show two equal numbers); else their range.
pub fn describe(values: impl Iterator<Item = f64>) -> String {
    let (lo, hi) = range(values);
    let (mid, spread) = (0.5 * (lo + hi), 0.5 * (hi - lo));
    if spread <= 1e-6 * mid.abs() || hi == lo {
        format!("uniform {mid:.4e} ± {spread:.1e}")
    } else if spread < 1e-3 * mid.abs() {
        format!("{mid:.4e} ± {spread:.1e} ({:.1e} of the value)", spread / mid.abs())
    } else {
        format!("{lo:.3e} .. {hi:.3e}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn signed_fields_centre_zero_and_uniform_fields_are_one_colour() {
        let s = Scale::of([-1.0, 3.0].into_iter(), true);
        assert_eq!((s.lo, s.hi), (-3.0, 3.0));
        assert_eq!(s.colour(0.0), DIVERGING[2]);
        assert_eq!(s.ticks(5), vec![-3.0, -1.5, 0.0, 1.5, 3.0]);
        // A uniform compression is one colour, the map's blue end.
        let u = Scale::of([-2.0, -2.0 + 1e-9].into_iter(), true);
        assert_eq!(u.colour(-2.0), u.colour(-2.0 + 1e-9));
        assert_eq!(u.colour(-2.0), DIVERGING[0]);
        // Zero everywhere: the centre, not a gradient.
        let z = Scale::of([0.0, 0.0].into_iter(), true);
        assert_eq!(z.colour(0.0), DIVERGING[2]);
        assert_eq!(describe([0.0, 0.0].into_iter()), "uniform 0.0000e0 ± 0.0e0");
        assert!(describe([5.0, 5.0 + 1e-6].into_iter()).starts_with("uniform 5.0000e0 ± "));
        assert_eq!(describe([1.0, 2.0].into_iter()), "1.000e0 .. 2.000e0");
        assert_eq!(
            describe([-2.0, -2.0002].into_iter()),
            "-2.0001e0 ± 1.0e-4 (5.0e-5 of the value)"
        );
    }

    #[test]
    fn magnitudes_start_at_zero_on_a_readable_colour() {
        let s = Scale::of([2.0, 4.0].into_iter(), false);
        assert_eq!((s.lo, s.hi), (0.0, 4.0));
        // The darkest colour drawn is viridis at 0.2, not its near-black end.
        let dark = s.colour(0.0);
        assert!(dark.iter().map(|&c| c as u32).sum::<u32>() > 200, "{dark:?}");
        assert_eq!(s.widen(Scale::of([6.0].into_iter(), false)).hi, 6.0);
    }

    #[test]
    fn a_few_points_far_off_do_not_stretch_the_scale() {
        // 1000 values in [-1, 1] and 3 at 100 (0.3% of the points).
        let mut v: Vec<f64> = (0..1000).map(|k| -1.0 + 2.0 * k as f64 / 999.0).collect();
        v.extend([100.0, -100.0, 100.0]);
        // 0.5% of 1003 is 5 values set aside: the three and the two 1s.
        let s = Scale::of(v.iter().copied(), true);
        assert!(s.hi > 0.99 && s.hi < 1.0 && s.lo == -s.hi, "{s:?}");
        assert_eq!(s.beyond(&v), 5);
        assert_eq!(s.colour(100.0), DIVERGING[4]);
        // Below the share, every value counts: 3 points alone.
        let few = Scale::of([1.0, 2.0, 50.0].into_iter(), false);
        assert_eq!(few.hi, 50.0);
    }
}
