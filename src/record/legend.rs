//! The points' colours and the colour bar: the scale a frame is coloured
//! with (its own, or the run's, [`colormap::Scale`]), the bar with its
//! ticks and label, and the end-of-run colouring of earlier frames with
//! the run's final scale.

use super::{order, Frame, RecordError, Recorder};
use crate::colormap;

/// The points' colours on `scale`.
pub(super) fn colours_of(scale: &colormap::Scale, values: &[f64], out: &mut Vec<rerun::Color>) {
    out.clear();
    out.extend(values.iter().map(|&v| {
        let [r, g, b] = scale.colour(v);
        rerun::Color::from_rgb(r, g, b)
    }));
}

/// A colour bar under the grid: the colour map as a row of segments
/// (static, 1.5 cells below the grid) with five labelled ticks, and per
/// frame a two-line label under them naming the field, its unit, the
/// colours' range and the frame's values (centred, so that the view's
/// bounds, fitted to the data, do not cut it).
#[derive(Clone)]
pub(super) struct ColourBar {
    /// Field title with its unit (`sigma_yy (Pa)`).
    title: String,
    x: [f32; 2],
    /// The bar's height and the label's anchor (m).
    y: f32,
    label_y: f32,
    width: f32,
}

impl ColourBar {
    /// Segments of the colour bar.
    const SEGMENTS: usize = 32;

    pub(super) fn new(g: &crate::grid::Grid, title: String) -> ColourBar {
        let max = g.max();
        ColourBar {
            title,
            x: [g.origin[0] as f32, max[0] as f32],
            y: (g.origin[1] - 1.5 * g.h) as f32,
            label_y: (g.origin[1] - 3.5 * g.h) as f32,
            width: (0.5 * g.h) as f32,
        }
    }

    /// The bar of a signed field's map (diverging) or a magnitude's.
    pub(super) fn bar(&self, signed: bool) -> rerun::LineStrips2D {
        let n = Self::SEGMENTS;
        let dx = (self.x[1] - self.x[0]) / n as f32;
        let strips = (0..n).map(|k| {
            let x = self.x[0] + k as f32 * dx;
            [[x, self.y], [x + dx, self.y]]
        });
        let unit = colormap::Scale {
            signed,
            lo: 0.0,
            hi: 1.0,
        };
        let colours = (0..n).map(|k| {
            let [r, g, b] = unit.colour((k as f64 + 0.5) / n as f64);
            rerun::Color::from_rgb(r, g, b)
        });
        rerun::LineStrips2D::new(strips)
            .with_colors(colours)
            .with_radii([rerun::Radius::new_scene_units(0.5 * self.width)])
            .with_draw_order(order::LEGEND)
    }

    /// The label: the field, what the frame's values are (their range,
    /// or `uniform V ± S`), the scale the colours span and how many points
    /// lie beyond it (drawn at its ends, [`colormap::OUTLIERS`]).
    pub(super) fn range(&self, scale: &colormap::Scale, described: &str, beyond: usize) -> rerun::Points2D {
        // Two lines, each narrower than a small grid's view.
        let label = format!(
            "{}: colours {:.3e} .. {:.3e}{}{}\nthis frame {described}",
            self.title,
            scale.lo,
            scale.hi,
            if scale.signed { " (0 grey)" } else { "" },
            match beyond {
                0 => String::new(),
                n => format!(", {n} points beyond (at the ends)"),
            }
        );
        rerun::Points2D::new([[0.5 * (self.x[0] + self.x[1]), self.label_y]])
            .with_labels([label])
            .with_colors([rerun::Color::from_rgb(230, 230, 230)])
            .with_radii([rerun::Radius::new_ui_points(0.5)])
            .with_draw_order(order::LEGEND)
    }
}

impl ColourBar {
    /// Ticks under the bar: five labelled marks from its left end (`lo`)
    /// to its right end (`hi`), zero in the middle of a signed scale.
    pub(super) fn ticks(&self, scale: &colormap::Scale) -> rerun::Points2D {
        let values = scale.ticks(5);
        let n = values.len() as f32 - 1.0;
        let at = (0..values.len()).map(|k| [self.x[0] + (self.x[1] - self.x[0]) * k as f32 / n, self.y]);
        rerun::Points2D::new(at)
            .with_labels(values.iter().map(|v| format!("{v:.2e}")))
            .with_colors([rerun::Color::from_rgb(230, 230, 230)])
            .with_radii([rerun::Radius::new_ui_points(2.0)])
            .with_draw_order(order::LEGEND + 1.0)
    }
}

/// A frame logged with a colour scale the run may later widen: its values
/// (as f32: a colour needs no more) to colour it again.
pub(super) struct Recolour {
    step: i64,
    time: Option<f64>,
    scale: colormap::Scale,
    values: Vec<f32>,
    described: String,
}

/// The most colour values a recording keeps to colour its frames again
/// with the run's final scale (64 MB; eight times the default point-frame
/// budget). Frames past it keep the scale they were drawn with, which an
/// event names.
const RECOLOUR_BUDGET: usize = 16_000_000;

impl Recorder {
    /// The frame's colour scale: its own, or the run's so far (kept, with
    /// the values, to colour the frame again when the run's widens); and
    /// its values in words, with the deformation scale it is drawn at.
    pub(super) fn scale_frame(&mut self, frame: &mut Frame, drawn: f64) {
        let own = colormap::Scale::of(frame.colour.iter().copied(), self.field.signed());
        frame.described = colormap::describe(frame.colour.iter().copied());
        if drawn != 1.0 {
            frame.described = format!("{}; deformation drawn x{drawn:.3e}", frame.described);
        }
        let scale = match self.settings.colour_range {
            crate::model::record::ColourRange::Frame => own,
            crate::model::record::ColourRange::Run => {
                let run = self.scale.map_or(own, |s| s.widen(own));
                self.scale = Some(run);
                let n = frame.colour.len();
                if self.recolour_from.is_none() && self.recolour_values + n <= RECOLOUR_BUDGET {
                    self.recolour_values += n;
                    self.recolour.push(Recolour {
                        step: frame.step,
                        time: frame.time,
                        scale: run,
                        values: frame.colour.iter().map(|&v| v as f32).collect(),
                        described: frame.described.clone(),
                    });
                } else {
                    self.recolour_from.get_or_insert(frame.step);
                }
                run
            }
        };
        frame.scale = scale;
    }
    /// With `colour_range = "run"`: colour every frame logged with a
    /// narrower scale than the run's final one again with it.
    pub(super) fn recolour_frames(&mut self) -> Result<(), RecordError> {
        let Some(run) = self.scale else { return Ok(()) };
        if let Some(step) = self.recolour_from {
            self.event(
                &format!(
                    "the frames from step {step} on keep the colour range they were drawn with \
                     (the run's frames hold more than {RECOLOUR_BUDGET} values to colour again)"
                ),
                "WARN",
            )?;
        }
        let mut colors = Vec::new();
        for f in std::mem::take(&mut self.recolour)
            .into_iter()
            .filter(|f| f.scale != run)
        {
            self.rec.set_time_sequence("step", f.step);
            if let Some(t) = f.time {
                self.rec.set_duration_secs("time", t);
            }
            let values: Vec<f64> = f.values.iter().map(|&v| v as f64).collect();
            colours_of(&run, &values, &mut colors);
            self.check(self.rec.log(
                "points",
                &rerun::Points2D::update_fields().with_colors(colors.iter().copied()),
            ))?;
            self.check(self.rec.log(
                "legend/range",
                &self.legend.range(&run, &f.described, run.beyond(&values)),
            ))?;
            self.check(self.rec.log("legend/ticks", &self.legend.ticks(&run)))?;
        }
        self.rec.reset_time();
        Ok(())
    }
}
