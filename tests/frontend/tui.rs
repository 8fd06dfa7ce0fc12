//! The TUI's first screen and a screen after a step, rendered with
//! ratatui's TestBackend.

use crate::common::sim_with;
use mpmlab::tui::app::{Action, App, Command, Update, View};
use mpmlab::tui::draw::draw;
use ratatui::backend::TestBackend;
use ratatui::Terminal;

/// The sweep view drawn at `w x h`, rows joined by newlines.
fn sweep_screen(view: &mpmlab::tui::sweep::SweepView, w: u16, h: u16) -> String {
    let mut t = Terminal::new(TestBackend::new(w, h)).unwrap();
    t.draw(|f| mpmlab::tui::sweep::draw(f, view)).unwrap();
    let buf = t.backend().buffer().clone();
    (0..buf.area.height)
        .map(|y| {
            (0..buf.area.width)
                .map(|x| buf[(x, y)].symbol().to_string())
                .collect::<String>()
                + "\n"
        })
        .collect()
}

fn screen(app: &App) -> Vec<String> {
    screen_at(app, 100, 30)
}

/// The screen's rows at a terminal of `w x h` cells.
fn screen_at(app: &App, w: u16, h: u16) -> Vec<String> {
    let mut t = Terminal::new(TestBackend::new(w, h)).unwrap();
    t.draw(|f| draw(f, app)).unwrap();
    let buf = t.backend().buffer().clone();
    (0..h)
        .map(|y| (0..w).map(|x| buf[(x, y)].symbol().to_string()).collect())
        .collect()
}

fn braille(line: &str) -> usize {
    line.chars().filter(|c| ('\u{2801}'..='\u{28ff}').contains(c)).count()
}

#[test]
fn first_screen_shows_grid_points_and_step_zero() {
    let sim = sim_with("column-small-strain", |_| {});
    let app = App::new(&sim, None);
    let lines = screen(&app);
    let all = lines.join("\n");
    assert!(
        lines[0].contains("column-small-strain") && lines[0].contains("step 0/1"),
        "{}",
        lines[0]
    );
    assert!(all.contains(" points ") && all.contains(" steps ") && all.contains(" last step "));
    assert!(all.contains("step 0: initial state"));
    assert!(all.contains("space step") && all.contains("q quit"));
    // The canvas (left 50 columns) is drawn with braille dots: grid lines
    // and points fill many cells.
    let dots: usize = lines[1..29]
        .iter()
        .map(|l| braille(&l.chars().take(50).collect::<String>()))
        .sum();
    assert!(dots > 100, "{all}");
}

#[test]
fn a_step_updates_the_screen() {
    let mut sim = sim_with("column-small-strain", |_| {});
    let mut app = App::new(&sim, None);
    assert_eq!(app.apply(Action::Step), Some(Command::Step));
    assert!(app.busy);
    // A second press while busy does not queue another step.
    assert_eq!(app.apply(Action::Step), None);
    let r = sim.step().unwrap();
    app.update(Update::Stepped(Box::new(r), Box::new(View::of(&sim, app.view.field))));
    let all = screen(&app).join("\n");
    assert!(all.contains("step 1/1"), "{all}");
    assert!(all.contains("cond(K)") && all.contains("dense"), "{all}");
    assert!(all.contains("syy_normalised"), "{all}");
    // Finished: space does nothing more.
    assert_eq!(app.apply(Action::Step), None);
    app.apply(Action::ToggleHelp);
    assert!(screen(&app).join("\n").contains("take one load step"));
}

#[test]
fn boundaries_are_drawn_and_reported() {
    let mut sim = sim_with("square-traction-aligned", |_| {});
    let mut app = App::new(&sim, None);
    assert_eq!(app.view.boundaries.len(), 1);
    assert!(app.view.boundaries[0].loaded && app.view.boundaries[0].curve.len() > 10);
    let buffer = |app: &App| {
        let mut t = Terminal::new(TestBackend::new(100, 30)).unwrap();
        t.draw(|f| draw(f, app)).unwrap();
        t.backend().buffer().clone()
    };
    let before = buffer(&app);
    app.apply(Action::ToggleControlPoints);
    let after = buffer(&app);
    // Control points add yellow dots to the canvas (on the loaded curve,
    // which is drawn red).
    let count =
        |b: &ratatui::buffer::Buffer, c: ratatui::style::Color| b.content.iter().filter(|cell| cell.fg == c).count();
    assert_eq!(count(&before, ratatui::style::Color::Yellow), 0);
    assert!(count(&after, ratatui::style::Color::Yellow) > 0);
    assert!(count(&before, ratatui::style::Color::LightRed) > 0);
    app.apply(Action::Step);
    let r = sim.step().unwrap();
    app.update(Update::Stepped(Box::new(r), Box::new(View::of(&sim, app.view.field))));
    let all = screen(&app).join("\n");
    assert!(all.contains("top: L 1.0000 m, 2 cells"), "{all}");
}

#[test]
fn gamma_k_is_tuned_from_the_keyboard() {
    let mut sim = sim_with("elastic-beam-ghost", |_| {});
    let mut app = App::new(&sim, None);
    assert!(screen(&app).join("\n").contains("gamma_K 1.200e7 Pa (1.0e0 E)"));
    match app.apply(Action::LowerGammaK) {
        Some(Command::SetGammaK(g)) => assert!((g - 1.2e6).abs() < 1e-6),
        other => panic!("{other:?}"),
    }
    assert_eq!(app.apply(Action::ToggleGhost), Some(Command::SetGammaK(0.0)));
    // The engine answers with its parameters; then ghost can come back.
    let mut p = sim.params().clone();
    p.gamma_k = 0.0;
    app.update(Update::Params(p.clone()));
    assert!(screen(&app).join("\n").contains("ghost off"));
    // Back on at the last value it had (the lowered one).
    match app.apply(Action::ToggleGhost) {
        Some(Command::SetGammaK(g)) => assert!((g - 1.2e6).abs() < 1e-6),
        other => panic!("{other:?}"),
    }
    // A step with ghost shows its residual history in the chart.
    app.apply(Action::Step);
    let r = sim.step().unwrap();
    app.update(Update::Stepped(Box::new(r), Box::new(View::of(&sim, app.view.field))));
    let all = screen(&app).join("\n");
    assert!(
        all.contains("residual per iteration (log10") && all.contains("1e-"),
        "{all}"
    );
    assert!(!app.view.ghost_faces.is_empty());
}

#[test]
fn delta_is_tuned_and_implicit_boundaries_are_drawn() {
    let sim = sim_with("block-roller-30", |_| {});
    let mut app = App::new(&sim, None);
    assert_eq!(app.view.ibm.len(), 4);
    assert!(screen(&app).join("\n").contains("delta/h 1e-6"));
    match app.apply(Action::LowerDelta) {
        Some(Command::SetDeltaOverH(d)) => assert!((d - 1e-7).abs() < 1e-20),
        other => panic!("{other:?}"),
    }
    let mut t = Terminal::new(TestBackend::new(100, 30)).unwrap();
    t.draw(|f| draw(f, &app)).unwrap();
    let cyan = t
        .backend()
        .buffer()
        .content
        .iter()
        .filter(|c| c.fg == ratatui::style::Color::Cyan)
        .count();
    assert!(cyan > 20, "implicit boundaries drawn in cyan: {cyan}");
}

#[test]
fn dynamics_screen_shows_time_energies_and_runs_on() {
    // Explicit dynamics: the title shows simulated time, the chart plots
    // energies against time, and enter keeps asking for steps until paused.
    let mut sim = sim_with("ghost-collision-elastic", |_| {});
    let mut app = App::new(&sim, None);
    assert_eq!(app.apply(Action::RunPause), Some(Command::Step));
    for _ in 0..3 {
        let r = sim.step().unwrap();
        app.update(Update::Stepped(Box::new(r), Box::new(View::of(&sim, app.view.field))));
        // Running: the app asks for the next step by itself.
        assert_eq!(app.pending(), Some(Command::Step));
    }
    let r = sim.step().unwrap();
    app.update(Update::Stepped(Box::new(r), Box::new(View::of(&sim, app.view.field))));
    assert_eq!(app.apply(Action::RunPause), None, "pausing asks for nothing");
    assert_eq!(app.pending(), None);
    let lines = screen(&app);
    let all = lines.join("\n");
    assert!(
        lines[0].contains("step 4/1000") && lines[0].contains("t = 0.0140 s"),
        "{}",
        lines[0]
    );
    // SI, per unit thickness.
    assert!(all.contains("energy (J/m) against time"), "{all}");
    assert!(all.contains("kinetic 2.13"), "{all}");
    assert!(all.contains("gamma_M 2.500e2"), "{all}");
    // gamma_M changes in decades and reaches the engine as a command.
    assert_eq!(app.apply(Action::LowerGammaM), Some(Command::SetGammaM(25.0)));
    // The CFL number shown is the mass in use's, as in the step table:
    // the lumped mass's differs from the stabilised one's.
    let mut sim = sim_with("ghost-collision-elastic", |s| {
        s.analysis.mass = mpmlab::scene::MassKind::Lumped;
        s.analysis.condition_every = 1;
    });
    let mut app = App::new(&sim, None);
    let r = sim.step().unwrap();
    let c = r.dynamics.as_ref().unwrap().conditioning.unwrap();
    let (lumped, stabilised) = (c.cfl_lumped.unwrap(), c.cfl_stabilised.unwrap());
    assert!((lumped / stabilised - 1.0).abs() > 1e-3, "{lumped} {stabilised}");
    app.update(Update::Stepped(Box::new(r), Box::new(View::of(&sim, app.view.field))));
    let all = screen(&app).join("\n");
    // (No-break spaces: a narrow panel wraps before the pair, not inside.)
    let shown = format!(
        "CFL\u{a0}(lumped\u{a0}mass)\u{a0}{}",
        mpmlab::format::sci_or_dash(Some(lumped), 3)
    );
    assert!(all.contains(&shown), "{shown}\n{all}");
}

#[test]
fn implicit_dynamics_screen_shows_time_energies_and_its_knobs() {
    // Implicit dynamics: the same time axis and energies as explicit, the
    // implicit boundary's delta and both ghost penalties live, and
    // gamma_M from zero back to implicit dynamics' own default (rho/4000).
    let mut sim = sim_with("incline-slide-implicit", |_| {});
    let mut app = App::new(&sim, None);
    for _ in 0..3 {
        let r = sim.step().unwrap();
        app.update(Update::Stepped(Box::new(r), Box::new(View::of(&sim, app.view.field))));
    }
    let lines = screen(&app);
    let all = lines.join("\n");
    assert!(
        lines[0].contains("step 3/10") && lines[0].contains("t = 0.0300 s"),
        "{}",
        lines[0]
    );
    assert!(all.contains("energy (J/m) against time"), "{all}");
    assert!(all.contains("delta/h 1e-6"), "{all}");
    assert!(all.contains("gamma_M 2.500e-1"), "{all}");
    assert!(all.contains("ghost off"), "{all}");
    assert!(all.contains("Newmark (trapezoidal): "), "{all}");
    assert!(all.contains("g/G gamma_K · m/M gamma_M"), "{all}");
    assert_eq!(app.apply(Action::RaiseGammaK), Some(Command::SetGammaK(10.0)));
    assert_eq!(app.apply(Action::LowerGammaM), Some(Command::SetGammaM(0.025)));
    match app.apply(Action::LowerDelta) {
        Some(Command::SetDeltaOverH(d)) => assert!((d - 1e-7).abs() < 1e-20),
        other => panic!("{other:?}"),
    }
}

#[test]
fn sweep_view_shows_runs_and_charts() {
    use mpmlab::sweep::RunResult;
    use mpmlab::tui::sweep::SweepView;
    // Three refinements of a first-order method and one failed run.
    let run = |h: f64, e: f64, t: f64, ok: bool| RunResult {
        id: format!("h={h}"),
        settings: vec![("h".into(), h.to_string())],
        completed: ok,
        failed_step: if ok { 0 } else { 3 },
        failure: if ok {
            String::new()
        } else {
            "step 3 failed: singular".into()
        },
        wall_s: t,
        errors: vec![("stress_l2".into(), e)],
        condition: f64::NAN,
        ..Default::default()
    };
    let view = SweepView {
        title: "demo".into(),
        results: vec![
            run(1.0, 1e-1, 1e-3, true),
            run(0.5, 5e-2, 4e-3, true),
            run(0.25, 2.5e-2, 1.6e-2, true),
            run(0.125, f64::NAN, 1e-2, false),
        ],
        scroll: 0,
        show_legend: true,
    };
    let all = sweep_screen(&view, 100, 30);
    let lines: Vec<&str> = all.lines().collect();
    assert!(lines[0].contains("4 runs, 3 completed, 1 failed"), "{}", lines[0]);
    assert!(all.contains("fails at 3") && all.contains("h=0.25"), "{all}");
    assert!(all.contains("stress_l2 against wall time"), "{all}");
    assert!(all.contains("stability map") && all.contains("FAIL"), "{all}");
    // The observed rate of the one group, from its end points: exactly 1.
    assert!(all.contains("rate 1.00"), "{all}");
    // Both charts are drawn (braille or dot markers right of the table).
    let marks: usize = lines[1..29]
        .iter()
        .map(|l| {
            l.chars()
                .skip(50)
                .filter(|c| ('\u{2801}'..='\u{28ff}').contains(c) || *c == '•')
                .count()
        })
        .sum();
    assert!(marks > 5, "{all}");
    // Probes on four refinements get an estimates panel: tip = 2 - h^2
    // (exact 2) has order 2, confirmed by the coarser triple, an estimated
    // error 0.015625 equal to the true one (est/true 1.00), GCI 1.25 x it.
    let probed = |h: f64| RunResult {
        probes: vec![("tip:uy".into(), 2.0 - h * h)],
        exact: vec![("probe:tip:uy".into(), 2.0)],
        ..run(h, 0.1 * h, h, true)
    };
    let estimated = SweepView {
        title: "demo".into(),
        results: vec![probed(1.0), probed(0.5), probed(0.25), probed(0.125)],
        scroll: 0,
        show_legend: true,
    };
    for (w, hgt) in [(100, 30), (160, 48)] {
        let all = sweep_screen(&estimated, w, hgt);
        assert!(all.contains("error estimates at h = 0.125"), "{all}");
        let row = all
            .lines()
            .find(|l| l.contains("tip:uy"))
            .unwrap_or_else(|| panic!("{all}"));
        assert!(
            row.contains("2.00") && row.contains("1.95e-2") && row.contains("1.00"),
            "{row}"
        );
    }
    // A sweep that keeps h (the delta preset): error and condition number
    // against the setting it varies. C: the error falls in proportion to
    // delta/h while cond(K) grows as 1/delta.
    let run = |d: f64| RunResult {
        id: format!("delta_over_h={d}"),
        settings: vec![("delta_over_h".into(), d.to_string())],
        completed: true,
        wall_s: 1e-3,
        errors: vec![("displacement_l2".into(), 0.3 * d)],
        condition: 1e3 / d,
        ..Default::default()
    };
    let view = SweepView {
        title: "delta".into(),
        results: vec![run(1e-1), run(1e-2), run(1e-3)],
        scroll: 0,
        show_legend: true,
    };
    let all = sweep_screen(&view, 160, 48);
    assert!(
        all.contains("displacement_l2 (lines) and cond(K) (dots) against delta_over_h"),
        "{all}"
    );
    assert!(!all.contains("not varied"), "{all}");
    // The error's observed rate against delta/h: exactly 1.
    assert!(all.contains("rate 1.00"), "{all}");
}

#[test]
fn charts_fields_zoom_and_quit_confirmation() {
    let mut sim = sim_with("column-small-strain", |_| {});
    let mut app = App::new(&sim, None);
    app.apply(Action::Step);
    let r = sim.step().unwrap();
    app.update(Update::Stepped(Box::new(r), Box::new(View::of(&sim, app.view.field))));
    // v cycles the chart: residual -> condition -> energy -> error.
    app.apply(Action::NextChart);
    assert!(screen(&app).join("\n").contains("condition number per step"));
    app.apply(Action::NextChart);
    assert!(screen(&app).join("\n").contains("energy per step"));
    app.apply(Action::NextChart);
    assert!(screen(&app).join("\n").contains("errors per step"));
    // f reaches the error against the exact solution (column: |u - u_exact|).
    for _ in 0..6 {
        let Some(Command::SetField(f)) = app.apply(Action::NextField) else {
            panic!()
        };
        app.update(Update::View(Box::new(View::of(&sim, f))));
    }
    assert_eq!(app.view.field, mpmlab::field::Field::Error);
    assert!(app.view.values.iter().all(|v| v.is_finite() && *v >= 0.0));
    // The column's exact solution gives displacements: the error is one, in m.
    assert!(screen(&app).join("\n").contains("|u - u_exact| (m)"));
    // Layers: active cells drawn in blue only when asked.
    let blue = |app: &App| {
        let mut t = Terminal::new(TestBackend::new(100, 30)).unwrap();
        t.draw(|f| draw(f, app)).unwrap();
        t.backend()
            .buffer()
            .content
            .iter()
            .filter(|c| c.fg == ratatui::style::Color::Rgb(60, 120, 200))
            .count()
    };
    assert_eq!(blue(&app), 0);
    app.apply(Action::ToggleActive);
    assert!(blue(&app) > 10);
    app.apply(Action::ToggleGrid);
    assert!(!app.show_grid);
    // Zoom and pan change the view; z fits again.
    app.apply(Action::ZoomIn);
    app.apply(Action::PanRight);
    assert_eq!(app.zoom, 2.0);
    assert!(app.pan[0] > 0.0);
    assert!(screen(&app).join("\n").contains("zoom x2"));
    app.apply(Action::ResetView);
    assert_eq!((app.zoom, app.pan), (1.0, [0.0, 0.0]));
    // q while a step runs asks first; Esc stays; q twice quits.
    app.busy = true;
    assert_eq!(app.apply(Action::Quit), None);
    assert!(app.status.contains("q again quits"));
    app.apply(Action::CloseOverlay);
    assert_eq!(app.apply(Action::Quit), None);
    assert_eq!(app.apply(Action::Quit), Some(Command::Quit));
    assert!(app.quit);
}

#[test]
fn failure_panel_and_redo_with_new_parameters() {
    // G Table 5: the plain GIMP beam (h = 0.25, 2x2 points) fails (after
    // 11 steps in G; its tangents reach condition numbers of 1e20-1e22,
    // where round-off picks the failing step, so the panel is checked
    // against the step the engine names); with gamma_K the redone step
    // completes.
    let mut sim = sim_with("elastic-beam-ghost", |s| {
        s.grid.h = 0.25;
        s.analysis.gamma_k = 0.0;
    });
    let mut app = App::new(&sim, None);
    let (snapshot, failure) = loop {
        let snap = sim.snapshot();
        match sim.step() {
            Ok(r) => app.update(Update::Stepped(Box::new(r), Box::new(View::of(&sim, app.view.field)))),
            Err(f) => break (snap, f),
        }
    };
    let k = failure.step();
    assert_eq!(k, sim.step_index() + 1, "the state is the last good step");
    app.update(Update::Failed(failure.clone()));
    let all = screen(&app).join("\n");
    assert!(
        all.contains(&format!("step {k} failed")) && all.contains("raise the ghost penalty"),
        "{all}"
    );
    assert!(all.contains("r redoes the step"), "{all}");
    // Raise gamma_K, then redo: the engine restores the snapshot and steps.
    assert!(matches!(app.apply(Action::RaiseGammaK), Some(Command::SetGammaK(_))));
    assert_eq!(app.apply(Action::Redo), Some(Command::Redo));
    sim.restore(&snapshot);
    let mut p = sim.params().clone();
    p.gamma_k = 12.0e6;
    sim.set_params(p);
    let after = sim.step();
    assert!(after.is_ok(), "{after:?}");
    app.update(Update::Redone(
        Box::new((Err(failure), after)),
        Box::new(View::of(&sim, app.view.field)),
    ));
    assert!(app.failure.is_none() && !app.busy);
    let all = screen(&app).join("\n");
    assert!(
        all.contains("redo: before / after") && all.contains("FAILED") && all.contains("completed"),
        "{all}"
    );
    assert_eq!(app.reports.last().unwrap().step, k);
    // Esc closes the comparison; stepping goes on.
    app.apply(Action::CloseOverlay);
    assert!(app.redo.is_none());
    assert_eq!(app.apply(Action::Step), Some(Command::Step));
}

#[test]
fn progress_is_shown_and_a_step_can_be_cancelled() {
    use mpmlab::simulation::{Progress, StepFailure};
    let sim = sim_with("elastic-beam-ghost", |_| {});
    let mut app = App::new(&sim, None);
    assert_eq!(app.apply(Action::Step), Some(Command::Step));
    app.update(Update::Progress(Progress {
        step: 1,
        iteration: 2,
        residual: 3.5e-4,
    }));
    let all = screen(&app).join("\n");
    assert!(
        all.contains("iteration 2, residual") && all.contains("3.50e-4"),
        "{all}"
    );
    assert_eq!(app.apply(Action::Cancel), Some(Command::Cancel));
    app.update(Update::Failed(StepFailure::Cancelled {
        step: 1,
        residuals: vec![1.0, 3.5e-4],
    }));
    // A cancelled step is not a failure: no panel, stepping goes on.
    assert!(app.failure.is_none() && !app.show_failure && !app.busy);
    assert!(app.status.contains("cancelled"), "{}", app.status);
    assert_eq!(app.apply(Action::Step), Some(Command::Step));
}

#[test]
fn scene_picker_highlights_the_default() {
    use mpmlab::tui::picker::{draw as draw_picker, Entry, Picker};
    let entry = |name: &str, d: &str| Entry {
        path: format!("scenarios/{name}.toml").into(),
        name: name.into(),
        description: d.into(),
    };
    let mut p = Picker {
        entries: vec![
            entry("block-roller-0", "C 5.1"),
            entry("column-small-strain", "column under self-weight"),
            entry("funnel", "C 5.6"),
        ],
        selected: 1,
        default: 1,
    };
    let render = |p: &Picker| {
        let mut t = Terminal::new(TestBackend::new(100, 30)).unwrap();
        t.draw(|f| draw_picker(f, p)).unwrap();
        let buf = t.backend().buffer().clone();
        (0..buf.area.height)
            .map(|y| {
                (0..buf.area.width)
                    .map(|x| buf[(x, y)].symbol().to_string())
                    .collect::<String>()
            })
            .collect::<Vec<_>>()
    };
    let lines = render(&p);
    let all = lines.join("\n");
    assert!(all.contains("> column-small-strain (default)"), "{all}");
    assert!(all.contains("column under self-weight"), "{all}");
    p.down();
    p.down();
    let all = render(&p).join("\n");
    assert!(all.contains("> funnel") && all.contains("C 5.6"), "{all}");
}

#[test]
fn parameters_are_typed_or_stepped() {
    let sim = sim_with("elastic-beam-ghost", |_| {});
    let mut app = App::new(&sim, None);
    let type_in = |app: &mut App, text: &str| {
        assert_eq!(app.apply(Action::OpenInput), None);
        for c in text.chars() {
            app.apply(Action::Type(c));
        }
        app.apply(Action::Submit)
    };
    assert_eq!(type_in(&mut app, "gamma_k = 5e5"), Some(Command::SetGammaK(5e5)));
    assert_eq!(type_in(&mut app, "tolerance=1e-9"), Some(Command::SetTolerance(1e-9)));
    assert_eq!(
        type_in(&mut app, "max_iterations = 30"),
        Some(Command::SetMaxIterations(30))
    );
    assert_eq!(type_in(&mut app, "delta_over_h = 2"), None);
    assert!(app.status.contains("(0, 1]"), "{}", app.status);
    assert_eq!(type_in(&mut app, "speed = 3"), None);
    assert!(app.status.contains("unknown parameter"), "{}", app.status);
    // The prompt shows what is typed; Esc drops it.
    app.apply(Action::OpenInput);
    app.apply(Action::Type('g'));
    assert!(screen(&app).join("\n").contains("set: g_"));
    app.apply(Action::CloseOverlay);
    assert!(app.input.is_none());
    // Tolerance in decades from the keyboard, from the value typed above.
    assert_eq!(app.apply(Action::LowerTolerance), Some(Command::SetTolerance(1e-10)));
}

/// Whole screens at the smallest supported and a large terminal.
#[test]
fn screens_at_two_sizes() {
    let mut sim = sim_with("elastic-beam-ghost", |s| {
        s.grid.h = 0.25;
        s.analysis.gamma_k = 0.0;
    });
    let mut app = App::new(&sim, None);
    for (w, h) in [(100u16, 30u16), (160, 48)] {
        let rows = screen_at(&app, w, h);
        let all = rows.join("\n");
        // Main screen: title, every panel, the key line; nothing cut at the edges.
        for part in [
            " points ",
            " parameters ",
            " last step ",
            " steps ",
            "space step",
            "? help",
        ] {
            assert!(all.contains(part), "{w}x{h}: {part}\n{all}");
        }
        assert!(rows[0].contains("elastic-beam-ghost") && rows[0].contains("step 0/50"));
        assert!(
            rows[1].starts_with('┌') && rows[h as usize - 2].starts_with('└'),
            "{all}"
        );
    }
    // Help at both sizes lists every key.
    app.apply(Action::ToggleHelp);
    for (w, h) in [(100u16, 30u16), (160, 48)] {
        let all = screen_at(&app, w, h).join("\n");
        for key in [
            "space",
            "enter",
            "redo",
            "cancel",
            "zoom",
            "pan",
            "gamma_M",
            "tolerance",
            "quit",
        ] {
            assert!(all.contains(key), "{w}x{h}: {key}\n{all}");
        }
    }
    app.apply(Action::CloseOverlay);
    // Failure panel at both sizes.
    let failure = loop {
        match sim.step() {
            Ok(r) => app.update(Update::Stepped(Box::new(r), Box::new(View::of(&sim, app.view.field)))),
            Err(f) => break f,
        }
    };
    let k = failure.step();
    app.update(Update::Failed(failure));
    for (w, h) in [(100u16, 30u16), (160, 48)] {
        let all = screen_at(&app, w, h).join("\n");
        assert!(
            all.contains(&format!("step {k} failed")) && all.contains("try:") && all.contains("redoes"),
            "{w}x{h}\n{all}"
        );
    }
}

#[test]
fn gamma_k_steps_from_a_scale_even_for_stress_free_scenes() {
    // stretching-ghost has E = 0: gamma_K still rises from 0 (scale 1 Pa),
    // and repeated presses compound before the engine answers.
    let sim = sim_with("stretching-ghost", |_| {});
    let mut app = App::new(&sim, None);
    match app.apply(Action::RaiseGammaK) {
        Some(Command::SetGammaK(g)) => assert!(g > 0.0 && g.is_finite()),
        other => panic!("{other:?}"),
    }
    let g0 = app.params.gamma_m;
    app.apply(Action::RaiseGammaM);
    assert_eq!(app.apply(Action::RaiseGammaM), Some(Command::SetGammaM(100.0 * g0)));
}

/// A probe's values in the last-step panel and its chart (load against
/// settlement for the footing), at both sizes; labels in the scene's units.
#[test]
fn probe_panel_and_chart_at_two_sizes() {
    let mut sim = sim_with("rigid-footing", |_| {});
    let mut app = App::new(&sim, None);
    for _ in 0..3 {
        let r = sim.step().unwrap();
        app.update(Update::Stepped(Box::new(r), Box::new(View::of(&sim, app.view.field))));
    }
    // v reaches the probe chart after the errors; it starts on the
    // footing's force against its displacement.
    for _ in 0..4 {
        app.apply(Action::NextChart);
    }
    assert_eq!(app.chart, mpmlab::tui::app::ChartKind::Probe);
    let cols = app.probe_columns();
    assert_eq!(cols[app.probe_y].0, "footing:fy", "{cols:?}");
    assert_eq!(cols[app.probe_x].0, "footing:uy", "{cols:?}");
    let r = sim.probe_values(None);
    let series = app.probe_series(app.probe_x);
    // The start and three steps; the last is the engine's value.
    assert_eq!(series.len(), 4);
    assert_eq!(series[3], r[0].u[1]);
    for (w, h) in [(100u16, 30u16), (160, 48)] {
        let rows = screen_at(&app, w, h);
        let all = rows.join("\n");
        assert!(all.contains("probe footing: u ("), "{w}x{h}\n{all}");
        assert!(
            all.contains("footing:fy (N/m) against footing:uy (m)"),
            "{w}x{h}\n{all}"
        );
        // The curve is drawn: braille dots in the chart's rows.
        let chart = rows.iter().position(|l| l.contains("against footing:uy")).unwrap();
        let dots: usize = rows[chart + 1..chart + 6].iter().map(|l| braille(l)).sum();
        assert!(dots > 5, "{w}x{h}\n{all}");
    }
}

/// A scene in mm, N, MPa is labelled so: stresses in MPa, forces per unit
/// thickness in N/mm.
#[test]
fn labels_in_the_scene_units() {
    let mut sim = sim_with("block-roller-0", |_| {});
    let mut app = App::new(&sim, None);
    let r = sim.step().unwrap();
    app.update(Update::Stepped(Box::new(r), Box::new(View::of(&sim, app.view.field))));
    let all = screen_at(&app, 160, 48).join("\n");
    for part in ["sigma_yy (MPa)", "N/mm", "N mm/mm", "probe top: u ("] {
        assert!(all.contains(part), "{part}\n{all}");
    }
    assert!(!all.contains("(Pa)") && !all.contains(" J "), "{all}");
}

/// The canvas names the implicit boundaries, draws grid supports
/// (magenta) and point loads (light red arrows), and ends in a colour bar
/// with the field's range; one-step charts show their single value.
#[test]
fn canvas_shows_names_supports_loads_and_a_colour_bar() {
    use ratatui::style::Color;
    let cells = |app: &App, w: u16, h: u16| {
        let mut t = Terminal::new(TestBackend::new(w, h)).unwrap();
        t.draw(|f| draw(f, app)).unwrap();
        t.backend().buffer().clone()
    };
    let count = |b: &ratatui::buffer::Buffer, c: Color| b.content.iter().filter(|x| x.fg == c).count();
    // The beam: clamped on the grid line x = 0, two point loads at the tip.
    let sim = sim_with("elastic-beam-ghost", |_| {});
    let app = App::new(&sim, None);
    for (w, h) in [(100u16, 30u16), (160, 48)] {
        let b = cells(&app, w, h);
        assert!(count(&b, Color::Magenta) >= 5, "{w}x{h}: the clamp");
        assert!(count(&b, Color::LightRed) >= 2, "{w}x{h}: the loads");
        // The colour bar: 12 cells through viridis in the bottom border,
        // low (dark purple) to high (yellow), between the range's ends.
        let bottom = h - 2;
        let bar: Vec<Color> = (0..w / 2)
            .map(|x| &b[(x, bottom)])
            .filter(|c| c.symbol() == "█")
            .map(|c| c.fg)
            .collect();
        assert_eq!(bar.len(), 12, "{w}x{h}");
        let [r, g, bl] = mpmlab::colormap::viridis(0.5 / 12.0);
        assert_eq!(bar[0], Color::Rgb(r, g, bl));
        let row: String = (0..w / 2).map(|x| b[(x, bottom)].symbol().to_string()).collect();
        assert!(row.contains("sigma_yy (Pa)"), "{row}");
    }
    // The block: its four implicit rollers are named on the canvas.
    let mut sim = sim_with("block-roller-30", |_| {});
    let mut app = App::new(&sim, None);
    let r = sim.step().unwrap();
    app.update(Update::Stepped(Box::new(r), Box::new(View::of(&sim, app.view.field))));
    app.apply(Action::NextChart);
    for (w, h) in [(100u16, 30u16), (160, 48)] {
        let rows = screen_at(&app, w, h);
        let canvas: String = rows
            .iter()
            .map(|l| l.chars().take(w as usize / 2).collect::<String>())
            .collect();
        for name in ["base", "left", "right", "top"] {
            assert!(canvas.contains(name), "{w}x{h}: {name}\n{}", rows.join("\n"));
        }
        // One step: the condition number is a dot on the chart.
        let all = rows.join("\n");
        assert!(all.contains("condition number per step") && all.contains('•'), "{all}");
    }
}

/// Whether a cell holds what a chart's curves draw.
fn plotted(symbol: &str) -> bool {
    symbol
        .chars()
        .any(|c| ('\u{2801}'..='\u{28ff}').contains(&c) || c == '•')
}

/// The legends of the charts hide no curve: the beam's condition numbers
/// (with ghost low, without it rising to 1e26 and back) cross the top left
/// of the plot, where the legend used to be; now it sits where no curve
/// passes (160x48: top right) or, when every place would hide some, in
/// the chart's bottom border (100x30). Read from the buffer: the cells the
/// legend changes (against the same screen with `L`, legends off) hold no
/// curve.
#[test]
fn chart_legends_hide_no_curve_at_two_sizes() {
    let mut sim = sim_with("elastic-beam-ghost", |_| {});
    let mut app = App::new(&sim, None);
    for _ in 0..6 {
        let r = sim.step().unwrap();
        app.update(Update::Stepped(Box::new(r), Box::new(View::of(&sim, app.view.field))));
    }
    app.apply(Action::NextChart);
    assert_eq!(app.chart, mpmlab::tui::app::ChartKind::Condition);
    let buffer = |app: &App, w: u16, h: u16| {
        let mut t = Terminal::new(TestBackend::new(w, h)).unwrap();
        t.draw(|f| draw(f, app)).unwrap();
        t.backend().buffer().clone()
    };
    for (w, h) in [(100u16, 30u16), (160, 48)] {
        let shown = buffer(&app, w, h);
        app.apply(Action::ToggleLegend);
        let hidden = buffer(&app, w, h);
        app.apply(Action::ToggleLegend);
        let rows = screen_at(&app, w, h);
        let all = rows.join("\n");
        let top = rows
            .iter()
            .position(|l| l.contains("condition number per step"))
            .unwrap() as u16;
        let left = w / 2;
        let bottom = (top + 1..h).find(|&y| shown[(left, y)].symbol() == "└").unwrap();
        let text = |b: &ratatui::buffer::Buffer| -> String {
            (top..=bottom)
                .map(|y| (left..w).map(|x| b[(x, y)].symbol().to_string()).collect::<String>())
                .collect::<Vec<_>>()
                .join("\n")
        };
        assert!(text(&shown).contains("without ghost"), "{w}x{h}\n{all}");
        assert!(!text(&hidden).contains("without ghost"), "{w}x{h}\n{}", text(&hidden));
        let mut changed = 0;
        for y in top + 1..bottom {
            for x in left + 1..w - 1 {
                if shown[(x, y)].symbol() != hidden[(x, y)].symbol() {
                    changed += 1;
                    assert!(
                        !plotted(hidden[(x, y)].symbol()),
                        "{w}x{h}: the legend hides a curve at ({x}, {y})\n{all}\n{}",
                        text(&hidden)
                    );
                }
            }
        }
        println!("{w}x{h}: the legend changes {changed} cells of the plot");
        // The old place, the plot's top left (a box 15 x 4 for `with
        // ghost`, `without ghost`): curves pass there.
        let axis = (left + 1..w).find(|&x| hidden[(x, top + 1)].symbol() == "│").unwrap();
        let under_old = (top + 1..top + 5)
            .flat_map(|y| (axis + 1..axis + 16).map(move |x| (x, y)))
            .filter(|&(x, y)| plotted(hidden[(x, y)].symbol()))
            .count();
        assert!(under_old > 0, "{w}x{h}\n{}", text(&hidden));
    }
}

/// Nothing cut mid-word at either size: the errors against the exact
/// solution (each name with its value on one line), the charts' titles,
/// and both columns of the redo panel (a failed step's message and its
/// residuals, wrapped between words).
#[test]
fn errors_titles_and_redo_panel_are_whole_words_at_two_sizes() {
    let tokens = |rows: &[String]| -> std::collections::HashSet<String> {
        rows.iter()
            .flat_map(|r| {
                r.chars()
                    .map(|c| if "│┌┐└┘─├┤".contains(c) { ' ' } else { c })
                    .collect::<String>()
                    .split_whitespace()
                    .map(str::to_string)
                    .collect::<Vec<_>>()
            })
            .collect()
    };
    // The plate with a hole: four error measures.
    let mut sim = sim_with("plate-hole-neumann", |_| {});
    let mut app = App::new(&sim, None);
    let r = sim.step().unwrap();
    app.update(Update::Stepped(
        Box::new(r.clone()),
        Box::new(View::of(&sim, app.view.field)),
    ));
    assert_eq!(r.errors.len(), 4);
    let words = [
        "residual",
        "per",
        "iteration",
        "(log10;",
        "v:",
        "next",
        "chart)",
        "condition",
        "number",
        "step",
        "(log10)",
        "(v:",
        "energy",
        "(J/m)",
        "errors",
        "—",
        "nothing",
        "yet",
    ];
    for (w, h) in [(100u16, 30u16), (160, 48)] {
        for _ in 0..4 {
            let rows = screen_at(&app, w, h);
            let all = rows.join("\n");
            for e in &r.errors {
                let pair = format!("{}\u{a0}{:.3e}", e.name, e.value);
                assert!(all.contains(&pair), "{w}x{h}: {pair}\n{all}");
            }
            // The chart's title: whole words only.
            let row = rows.iter().find(|l| l.contains(" per ")).unwrap();
            let title: String = row.chars().skip(w as usize / 2).collect();
            let title = title.trim_matches(|c| "┌┐─ ".contains(c));
            for t in title.split_whitespace() {
                assert!(words.contains(&t), "{w}x{h}: `{t}` in `{title}`");
            }
            // Its bottom border (a legend there): whole names, then how
            // many did not fit.
            let top = rows.iter().position(|l| l.contains(" per ")).unwrap();
            let border = rows[top + 1..]
                .iter()
                .find(|l| l.chars().nth(w as usize / 2) == Some('└'))
                .unwrap();
            let border: String = border.chars().skip(w as usize / 2).collect();
            for t in border.trim_matches(|c| "└┘─ ".contains(c)).split_whitespace() {
                let known = t == "■"
                    || r.errors.iter().any(|e| e.name == t)
                    || ["strain", "external", "work", "plastic", "K"].contains(&t)
                    || t.strip_prefix('+').is_some_and(|n| n.parse::<usize>().is_ok());
                assert!(known, "{w}x{h}: `{t}` in `{border}`");
            }
            app.apply(Action::NextChart);
        }
        app.apply(Action::NextChart);
    }
    // The redo panel: a failed step (its message lists eleven residuals)
    // against the step redone with ghost.
    let mut sim = sim_with("elastic-beam-ghost", |s| {
        s.grid.h = 0.25;
        s.analysis.gamma_k = 0.0;
    });
    let mut app = App::new(&sim, None);
    let (snapshot, failure) = loop {
        let snap = sim.snapshot();
        match sim.step() {
            Ok(r) => app.update(Update::Stepped(Box::new(r), Box::new(View::of(&sim, app.view.field)))),
            Err(f) => break (snap, f),
        }
    };
    app.update(Update::Failed(failure.clone()));
    app.apply(Action::RaiseGammaK);
    assert_eq!(app.apply(Action::Redo), Some(Command::Redo));
    sim.restore(&snapshot);
    let mut p = sim.params().clone();
    p.gamma_k = 12.0e6;
    sim.set_params(p);
    let after = sim.step().unwrap();
    let expected: Vec<String> = failure
        .to_string()
        .split_whitespace()
        .map(str::to_string)
        .chain(failure.residuals().iter().map(|x| format!("{x:.1e}")))
        .chain(after.residuals.iter().map(|x| format!("{x:.1e}")))
        .collect();
    app.update(Update::Redone(
        Box::new((Err(failure), Ok(after))),
        Box::new(View::of(&sim, app.view.field)),
    ));
    for (w, h) in [(100u16, 30u16), (160, 48)] {
        let rows = screen_at(&app, w, h);
        let have = tokens(&rows);
        for t in &expected {
            assert!(have.contains(t), "{w}x{h}: `{t}` is not whole\n{}", rows.join("\n"));
        }
    }
}

/// The sweep view's stability map hides no failed run: G Table 5's 15
/// rows of settings do not fit at 100x30; the rows with failures are kept
/// (the last two here), and a line counts the completed rows left out.
#[test]
fn sweep_stability_map_shows_every_failure_at_two_sizes() {
    use mpmlab::sweep::RunResult;
    use mpmlab::tui::sweep::{draw as draw_sweep, SweepView};
    let mut results = Vec::new();
    for h in ["0.5", "0.25", "0.125"] {
        for ppc in ["2", "3", "4", "5", "6"] {
            for g in ["12e6", "0"] {
                let fails =
                    g == "0" && (h, ppc) != ("0.125", "2") && (h == "0.125" && ppc >= "5" || h == "0.5" && ppc == "2");
                results.push(RunResult {
                    id: format!("h={h}_ppc={ppc}_gamma_k={g}"),
                    settings: vec![
                        ("h".into(), h.into()),
                        ("ppc".into(), ppc.into()),
                        ("gamma_k".into(), g.into()),
                    ],
                    completed: !fails,
                    failed_step: if fails { 13 } else { 0 },
                    wall_s: 1.0,
                    ..Default::default()
                });
            }
        }
    }
    let failed = results.iter().filter(|r| !r.completed).count();
    assert_eq!(failed, 3);
    let view = SweepView {
        title: "beam-stability".into(),
        results,
        scroll: 0,
        show_legend: true,
    };
    for (w, h) in [(100u16, 30u16), (160, 48)] {
        let mut t = Terminal::new(TestBackend::new(w, h)).unwrap();
        t.draw(|f| draw_sweep(f, &view)).unwrap();
        let buf = t.backend().buffer().clone();
        let rows: Vec<String> = (0..h)
            .map(|y| (0..w / 2).map(|x| buf[(x, y)].symbol().to_string()).collect())
            .collect();
        let top = rows.iter().position(|l| l.contains("stability map")).unwrap();
        let map = rows[top..].join("\n");
        assert!(
            map.contains(&format!("stability map ({failed} failed)")),
            "{w}x{h}\n{map}"
        );
        assert_eq!(map.matches("FAIL").count(), failed, "{w}x{h}\n{map}");
        assert!(map.contains("h=0.125 ppc=6"), "{w}x{h}\n{map}");
        if w == 100 {
            assert!(map.contains("more rows, all ok"), "{w}x{h}\n{map}");
        }
    }
}

/// The sweep view's charts place their legends as the main screen does:
/// error against h falls to the bottom left, so the old place, the top
/// right, covered the curve; the cells the legend changes (against `L`,
/// legends off) hold no curve, at both sizes.
#[test]
fn sweep_chart_legends_hide_no_curve_at_two_sizes() {
    use mpmlab::sweep::RunResult;
    use mpmlab::tui::sweep::{draw as draw_sweep, SweepView};
    let run = |h: f64, e: f64, t: f64| RunResult {
        id: format!("h={h}"),
        settings: vec![("h".into(), h.to_string())],
        completed: true,
        wall_s: t,
        errors: vec![("displacement_l2".into(), e)],
        condition: f64::NAN,
        ..Default::default()
    };
    let mut view = SweepView {
        title: "demo".into(),
        results: vec![
            run(1.0, 1e-1, 1e-3),
            run(0.5, 5e-2, 4e-3),
            run(0.25, 2.5e-2, 1.6e-2),
            run(0.125, 1.25e-2, 6.4e-2),
        ],
        scroll: 0,
        show_legend: true,
    };
    let buffer = |v: &SweepView, w: u16, h: u16| {
        let mut t = Terminal::new(TestBackend::new(w, h)).unwrap();
        t.draw(|f| draw_sweep(f, v)).unwrap();
        t.backend().buffer().clone()
    };
    for (w, h) in [(100u16, 30u16), (160, 48)] {
        let shown = buffer(&view, w, h);
        view.show_legend = false;
        let hidden = buffer(&view, w, h);
        view.show_legend = true;
        let row = |b: &ratatui::buffer::Buffer, y: u16| -> String {
            (w / 2..w).map(|x| b[(x, y)].symbol().to_string()).collect()
        };
        // Both titles in whole words (the long one shortened at 100x30).
        for y in (0..h).filter(|&y| row(&shown, y).contains("displacement_l2 ")) {
            let title = row(&shown, y);
            let title = title.trim_matches(|c| "┌┐─ ".contains(c));
            for t in title.split_whitespace() {
                let whole = [
                    "displacement_l2",
                    "against",
                    "wall",
                    "time",
                    "(log-log)",
                    "(lines)",
                    "and",
                    "cond(K)",
                    "(dots)",
                    "h",
                    "…",
                ];
                assert!(whole.contains(&t), "{w}x{h}: `{t}` in `{title}`");
            }
        }
        let top = (0..h)
            .find(|&y| row(&shown, y).contains("(lines) and cond(K)"))
            .unwrap_or_else(|| panic!("{}", (0..h).map(|y| row(&shown, y)).collect::<Vec<_>>().join("\n")));
        let bottom = (top + 1..h).find(|&y| shown[(w / 2, y)].symbol() == "└").unwrap();
        let text = |b: &ratatui::buffer::Buffer| (top..=bottom).map(|y| row(b, y)).collect::<Vec<_>>().join("\n");
        assert!(text(&shown).contains("rate 1.00"), "{w}x{h}\n{}", text(&shown));
        assert!(!text(&hidden).contains("rate 1.00"), "{w}x{h}\n{}", text(&hidden));
        for y in top + 1..bottom {
            for x in w / 2 + 1..w - 1 {
                if shown[(x, y)].symbol() != hidden[(x, y)].symbol() {
                    assert!(
                        !plotted(hidden[(x, y)].symbol()),
                        "{w}x{h}: the legend hides a curve at ({x}, {y})\n{}\n{}",
                        text(&shown),
                        text(&hidden)
                    );
                }
            }
        }
        // The old place, the plot's top right (a box of at least 11 x 3
        // for `rate 1.00`): the curve ends there.
        let under_old = (top + 1..top + 4)
            .flat_map(|y| (w - 12..w - 1).map(move |x| (x, y)))
            .filter(|&(x, y)| plotted(hidden[(x, y)].symbol()))
            .count();
        assert!(under_old > 0, "{w}x{h}\n{}", text(&hidden));
    }
}
