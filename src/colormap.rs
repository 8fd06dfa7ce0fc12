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
