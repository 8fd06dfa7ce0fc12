//! `[record]`: how much of a run its recording holds. Metrics and events
//! go in at every step (they are small); the points (and the other
//! per-step geometry of the scene view) only at a cadence, with the
//! per-point values of the chosen fields.

use crate::field::Field;
use crate::scene::{AnalysisKind, FieldError, RecordSpec};

/// Point frames a run's recording holds at most under the default
/// cadence, counted in points times frames: about 50 MB before
/// compression with the default fields (24 bytes a point), whatever the
/// scene's size. Runs below it record their points at every step. Sized so
/// that recording the 102,400-point explicit block (about 40 ms a step)
/// costs at most a tenth of its run (`cargo bench --bench record`).
pub const POINT_FRAME_BUDGET: u64 = 2_000_000;

/// When the points are recorded (besides the first and last step of a
/// run, the state before a failed step and where a run is stopped).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Cadence {
    /// Every `ceil(load_steps x points / POINT_FRAME_BUDGET)` steps.
    #[default]
    Auto,
    /// Every this many steps.
    Every(usize),
    /// Explicit dynamics: at the first step past each multiple of this
    /// simulated time (s).
    Dt(f64),
}

/// What a recording holds.
#[derive(Clone, Debug, PartialEq)]
pub struct RecordSettings {
    pub cadence: Cadence,
    /// Per-point values recorded with the positions (which are always
    /// recorded, with colours and radii).
    pub fields: Vec<Field>,
    /// The colour scale: one over the whole run, or each frame's own.
    pub colour_range: ColourRange,
    /// Small strain: the drawn positions are `x0 + s u` with this `s`
    /// (`None`: chosen from the first step, [`deformation_scale`]).
    pub deformation_scale: Option<f64>,
}

pub use crate::scene::ColourRange;

/// The deformation scale a small-strain recording draws with when the
/// scene gives none: the displacement extrapolated to the full load
/// (`u_max / lambda`, the analysis being linear) drawn as a tenth of the
/// bodies' extent `size`, or true scale when it is already smaller (a
/// linear analysis at a load of the order of E moves a hole's edges by
/// more than its radius: drawn true, the hole collapses to a slit).
pub fn deformation_scale(u_max: f64, lambda: f64, size: f64) -> f64 {
    let full = u_max / lambda.max(f64::MIN_POSITIVE);
    if size > 0.0 && full > 0.1 * size && full.is_finite() {
        0.1 * size / full
    } else {
        1.0
    }
}

impl Default for RecordSettings {
    /// The default cadence and the field the viewer colours the points by.
    fn default() -> Self {
        RecordSettings {
            cadence: Cadence::Auto,
            fields: DEFAULT_FIELDS.to_vec(),
            colour_range: ColourRange::Run,
            deformation_scale: None,
        }
    }
}

/// The fields recorded by default: the one the points are coloured by.
pub const DEFAULT_FIELDS: [Field; 1] = [Field::SigmaYy];

/// The names `fields` accepts besides the field keys.
pub const FIELD_WORDS: [&str; 2] = ["all", "positions"];

/// Fields from their names (`all` for every field; `positions` is always
/// recorded and may be named).
pub fn parse_fields<S: AsRef<str>>(names: &[S]) -> Result<Vec<Field>, String> {
    let mut out: Vec<Field> = Vec::new();
    for n in names {
        let n = n.as_ref().trim();
        match n {
            "all" => return Ok(Field::ALL.to_vec()),
            "positions" => {}
            _ => {
                let Some(f) = Field::ALL.into_iter().find(|f| f.key() == n) else {
                    let known: Vec<&str> = Field::ALL.iter().map(|f| f.key()).chain(FIELD_WORDS).collect();
                    return Err(format!("unknown field `{n}`; known: {}", known.join(", ")));
                };
                if !out.contains(&f) {
                    out.push(f);
                }
            }
        }
    }
    // In the order of `Field::ALL`, as recordings of every field hold them.
    out.sort_by_key(|f| Field::ALL.iter().position(|g| g == f));
    Ok(out)
}

/// Check a cadence against the analysis.
pub fn check_cadence(c: Cadence, kind: AnalysisKind) -> Result<(), (&'static str, String)> {
    match c {
        Cadence::Auto => Ok(()),
        Cadence::Every(n) if !(1..=1_000_000).contains(&n) => {
            Err(("every", "must be between 1 and 1000000 (steps)".into()))
        }
        Cadence::Every(_) => Ok(()),
        Cadence::Dt(t) if !(t > 0.0 && t.is_finite()) => Err(("dt", "must be a positive time (s)".into())),
        Cadence::Dt(_) if !kind.is_dynamic() => Err((
            "dt",
            "a cadence in simulated time is for kind = \"explicit-dynamics\" or \"dynamic-implicit\"; use `every` (steps)"
                .into(),
        )),
        Cadence::Dt(_) => Ok(()),
    }
}

/// Validate `[record]`.
pub(super) fn build(spec: &RecordSpec, kind: AnalysisKind) -> Result<RecordSettings, FieldError> {
    let cadence = match (spec.every, spec.dt) {
        (Some(_), Some(_)) => {
            return Err(FieldError::new(
                "record.dt",
                "give either `every` (steps) or `dt` (time), not both",
            ))
        }
        (Some(n), None) => Cadence::Every(n),
        (None, Some(t)) => Cadence::Dt(t),
        (None, None) => Cadence::Auto,
    };
    check_cadence(cadence, kind).map_err(|(f, m)| FieldError::new(format!("record.{f}"), m))?;
    let fields = match &spec.fields {
        None => DEFAULT_FIELDS.to_vec(),
        Some(names) => parse_fields(&names.names()).map_err(|m| FieldError::new("record.fields", m))?,
    };
    if let Some(s) = spec.deformation_scale {
        if !(s > 0.0 && s.is_finite()) {
            return Err(FieldError::new("record.deformation_scale", "must be a positive number"));
        }
        if kind != AnalysisKind::QuasiStaticLinear {
            return Err(FieldError::new(
                "record.deformation_scale",
                "only small-strain analyses (kind = \"quasi-static-linear\") draw a scaled deformation: \
                 the others draw the configuration they solve on",
            ));
        }
    }
    Ok(RecordSettings {
        cadence,
        fields,
        colour_range: spec.colour_range,
        deformation_scale: spec.deformation_scale,
    })
}

/// A cadence resolved for one run: which steps hold points.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plan {
    /// Points every this many steps (`None` under a time cadence).
    pub every: Option<usize>,
    /// Time cadence: (step length, interval) in seconds.
    pub dt: Option<(f64, f64)>,
    pub load_steps: usize,
}

impl Plan {
    /// Resolve `cadence` for a run of `load_steps` steps of `points`
    /// points, each `step_dt` long (explicit dynamics).
    pub fn new(cadence: Cadence, load_steps: usize, points: usize, step_dt: Option<f64>) -> Plan {
        let (every, dt) = match (cadence, step_dt) {
            (Cadence::Every(n), _) => (Some(n.max(1)), None),
            (Cadence::Dt(t), Some(s)) if s > 0.0 => (None, Some((s, t))),
            (Cadence::Dt(_), _) => (Some(1), None),
            (Cadence::Auto, _) => {
                let work = load_steps as u64 * points as u64;
                (Some(work.div_ceil(POINT_FRAME_BUDGET).max(1) as usize), None)
            }
        };
        Plan { every, dt, load_steps }
    }

    /// Whether step `k` (0: the initial state) holds points.
    pub fn holds_points(&self, k: usize) -> bool {
        if k == 0 || k >= self.load_steps {
            return true;
        }
        match (self.every, self.dt) {
            (Some(n), _) => k.is_multiple_of(n),
            (None, Some((s, t))) => {
                // The first step at or past each multiple of t (a small
                // tolerance so that t = n s lands on step n exactly).
                let slot = |k: usize| ((k as f64 * s) / t * (1.0 + 1e-12)).floor();
                slot(k) > slot(k - 1)
            }
            (None, None) => true,
        }
    }

    /// Point frames of a complete run.
    pub fn frames(&self) -> usize {
        (0..=self.load_steps).filter(|&k| self.holds_points(k)).count()
    }

    /// The cadence in words.
    pub fn describe(&self) -> String {
        match (self.every, self.dt) {
            (Some(1), _) => "every step".into(),
            (Some(n), _) => format!("every {n} steps"),
            (None, Some((_, t))) => format!("every {t} s of simulated time"),
            (None, None) => "every step".into(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_nth_first_and_last() {
        let p = Plan::new(Cadence::Every(3), 10, 5, None);
        let held: Vec<usize> = (0..=10).filter(|&k| p.holds_points(k)).collect();
        assert_eq!(held, [0, 3, 6, 9, 10]);
        assert_eq!(p.frames(), 5);
    }

    #[test]
    fn time_cadence_lands_on_whole_steps() {
        // Steps of 1e-4 s, points every 3e-4 s: steps 3, 6, 9 and the last.
        let p = Plan::new(Cadence::Dt(3e-4), 10, 5, Some(1e-4));
        let held: Vec<usize> = (0..=10).filter(|&k| p.holds_points(k)).collect();
        assert_eq!(held, [0, 3, 6, 9, 10]);
        // Steps of 0.4 s, points every 1 s: the first step past each second.
        let p = Plan::new(Cadence::Dt(1.0), 6, 5, Some(0.4));
        let held: Vec<usize> = (0..=6).filter(|&k| p.holds_points(k)).collect();
        assert_eq!(held, [0, 3, 5, 6]);
    }

    #[test]
    fn auto_keeps_small_runs_whole_and_caps_large_ones() {
        // 2 million point frames: 1000 steps of 2000 points fit whole; 100
        // steps of the 102,400-point block keep every ceil(5.12) = 6th.
        assert_eq!(Plan::new(Cadence::Auto, 1000, 2000, None).every, Some(1));
        assert_eq!(Plan::new(Cadence::Auto, 1000, 2001, None).every, Some(2));
        assert_eq!(Plan::new(Cadence::Auto, 100, 102_400, None).every, Some(6));
        let big = Plan::new(Cadence::Auto, 4000, 102_400, None);
        assert!(
            big.frames() as u64 * 102_400 <= 2 * POINT_FRAME_BUDGET,
            "{}",
            big.frames()
        );
    }

    #[test]
    fn field_names() {
        assert_eq!(parse_fields(&["all"]).unwrap(), Field::ALL.to_vec());
        assert_eq!(parse_fields(&["positions"]).unwrap(), vec![]);
        assert_eq!(
            parse_fields(&["speed", "sigma_xx", "speed"]).unwrap(),
            vec![Field::SigmaXx, Field::Speed]
        );
        assert!(parse_fields(&["colour"])
            .unwrap_err()
            .contains("unknown field `colour`"));
    }
}
