//! A recording read back with rerun's own decoder: entity paths, number of
//! points and metric values match what the run reported.

use crate::common;
use crate::common::{read_chunks, sim_with, temp_path};
use mpmlab::record::Recorder;
use std::collections::BTreeMap;

#[test]
fn recording_holds_grid_points_and_metrics() {
    let mut sim = sim_with("column-small-strain", |s| s.analysis.load_steps = 2);
    let text = std::fs::read_to_string(common::scene_path("column-small-strain")).unwrap();
    let path = temp_path("rec", "rrd");
    let mut rec = Recorder::create(&path, &text, &sim, true).unwrap();
    let mut reports = Vec::new();
    while !sim.finished() {
        let r = sim.step().unwrap();
        rec.log_step(&r, &sim).unwrap();
        reports.push(r);
    }
    rec.finish().unwrap();
    let n_points = sim.points().len();

    let chunks = read_chunks(&path);
    let scalars = rerun::Scalars::descriptor_scalars().component;
    let positions = rerun::Points2D::descriptor_positions().component;
    let step_tl: rerun::TimelineName = "step".into();
    // entity -> (step -> values)
    let mut series: BTreeMap<String, BTreeMap<i64, f64>> = BTreeMap::new();
    let mut point_counts: BTreeMap<i64, usize> = BTreeMap::new();
    let mut entities = std::collections::BTreeSet::new();
    for chunk in &chunks {
        let entity = chunk.entity_path().to_string();
        entities.insert(entity.clone());
        let steps: Vec<i64> = chunk
            .timelines()
            .get(&step_tl)
            .map(|t| t.times_raw().to_vec())
            .unwrap_or_default();
        for ((t, _), v) in chunk
            .iter_component_indices(step_tl, scalars)
            .zip(chunk.iter_slices::<f64>(scalars))
        {
            series.entry(entity.clone()).or_default().insert(t.as_i64(), v[0]);
        }
        if entity == "/points" {
            for (k, p) in chunk.iter_slices::<[f32; 2]>(positions).enumerate() {
                point_counts.insert(steps[k], p.len());
            }
        }
    }
    let _ = std::fs::remove_file(&path);

    for e in [
        "/scene",
        "/grid",
        "/grid/active",
        "/points",
        "/events",
        "/metrics/residual",
        "/metrics/condition/stiffness",
    ] {
        assert!(entities.contains(e), "missing {e} in {entities:?}");
    }
    assert_eq!(
        point_counts,
        BTreeMap::from([(0, n_points), (1, n_points), (2, n_points)])
    );
    // Per-point values of every field ride along with the points.
    let sigma_yy: rerun::ComponentIdentifier = "sigma_yy".into();
    let last: Vec<f64> = chunks
        .iter()
        .filter(|c| c.entity_path().to_string() == "/points")
        .flat_map(|c| c.iter_slices::<f64>(sigma_yy).map(|v| v.to_vec()).collect::<Vec<_>>())
        .last()
        .expect("sigma_yy on /points");
    let expected: Vec<f64> = sim.points().stress.iter().map(|s| s[1]).collect();
    assert_eq!(last, expected);
    for r in &reports {
        let s = r.step as i64;
        // Scalars are stored as f64: values come back bit-identical.
        assert_eq!(series["/metrics/energy/strain"][&s], r.energy.strain);
        assert_eq!(series["/metrics/energy/external_work"][&s], r.energy.external_work);
        assert_eq!(series["/metrics/energy/ghost"][&s], r.energy.ghost);
        assert_eq!(series["/metrics/condition/stiffness"][&s], r.condition.unwrap().value);
        assert_eq!(
            series["/metrics/error/syy_normalised"][&s],
            r.errors.iter().find(|e| e.name == "syy_normalised").unwrap().value
        );
        assert_eq!(series["/metrics/unknowns"][&s], r.unknowns as f64);
    }
}

#[test]
fn boundary_curves_are_recorded() {
    let mut sim = sim_with("thick-cylinder", |_| {});
    let text = std::fs::read_to_string(common::scene_path("thick-cylinder")).unwrap();
    let path = temp_path("rec-boundary", "rrd");
    let mut rec = Recorder::create(&path, &text, &sim, true).unwrap();
    let r = sim.step().unwrap();
    rec.log_step(&r, &sim).unwrap();
    rec.finish().unwrap();
    let scalars = rerun::Scalars::descriptor_scalars().component;
    let mut entities = std::collections::BTreeSet::new();
    let mut length = None;
    for chunk in read_chunks(&path) {
        let e = chunk.entity_path().to_string();
        if e == "/metrics/boundary/inner/length" {
            length = chunk.iter_slices::<f64>(scalars).next().map(|v| v[0]);
        }
        entities.insert(e);
    }
    let _ = std::fs::remove_file(&path);
    for e in [
        "/boundaries/inner/curve",
        "/boundaries/inner/control_points",
        "/boundaries/outer/curve",
    ] {
        assert!(entities.contains(e), "missing {e}");
    }
    assert_eq!(length, Some(r.boundaries[0].length));
}

#[test]
fn dynamic_run_records_energies_on_the_time_timeline() {
    // Explicit dynamics: energies, balance and mass conditioning are logged
    // on `step` and on `time` (simulated seconds), bit-identical to the reports.
    let mut sim = sim_with("ghost-collision-elastic", |s| {
        s.analysis.load_steps = 1000;
        s.analysis.condition_every = 2;
    });
    let text = std::fs::read_to_string(common::scene_path("ghost-collision-elastic")).unwrap();
    let path = temp_path("rec-dyn", "rrd");
    let mut rec = Recorder::create(&path, &text, &sim, true).unwrap();
    let mut reports = Vec::new();
    for _ in 0..4 {
        let r = sim.step().unwrap();
        rec.log_step(&r, &sim).unwrap();
        reports.push(r);
    }
    rec.finish().unwrap();
    let scalars = rerun::Scalars::descriptor_scalars().component;
    let time_tl: rerun::TimelineName = "time".into();
    // entity -> (time in ns -> value)
    let mut on_time: BTreeMap<String, BTreeMap<i64, f64>> = BTreeMap::new();
    for chunk in read_chunks(&path) {
        let e = chunk.entity_path().to_string();
        for ((t, _), v) in chunk
            .iter_component_indices(time_tl, scalars)
            .zip(chunk.iter_slices::<f64>(scalars))
        {
            on_time.entry(e.clone()).or_default().insert(t.as_i64(), v[0]);
        }
    }
    let _ = std::fs::remove_file(&path);
    for r in &reports {
        let d = r.dynamics.as_ref().unwrap();
        let t = std::time::Duration::from_secs_f64(d.time).as_nanos() as i64;
        assert_eq!(on_time["/metrics/energy/kinetic"][&t], r.energy.kinetic);
        assert_eq!(on_time["/metrics/energy/strain"][&t], r.energy.strain);
        assert_eq!(on_time["/metrics/energy/balance_error"][&t], d.energy_error);
        if let Some(c) = &d.conditioning {
            assert_eq!(
                on_time["/metrics/condition/mass_stabilised"][&t],
                c.mass_stabilised.value
            );
        }
    }
    // Condition steps 1, 2 and 4 (every 2nd step and the first).
    assert_eq!(on_time["/metrics/condition/mass_lumped"].len(), 3);
}

#[test]
fn recording_carries_a_default_layout() {
    // A blueprint store (rerun's stored layout) with its views, activated:
    // the viewer opens on the scene with the metrics beside it.
    use rerun::external::re_log_encoding::DecoderApp;
    use rerun::log::{Chunk, LogMsg};
    let sim = sim_with("column-small-strain", |_| {});
    let text = std::fs::read_to_string(common::scene_path("column-small-strain")).unwrap();
    let path = temp_path("rec-layout", "rrd");
    Recorder::create(&path, &text, &sim, true).unwrap().finish().unwrap();
    let file = std::fs::File::open(&path).unwrap();
    let (mut blueprint_entities, mut activated) = (Vec::new(), false);
    for msg in DecoderApp::decode_eager(std::io::BufReader::new(file)).unwrap() {
        match msg.unwrap() {
            LogMsg::ArrowMsg(store, arrow) if !store.is_recording() => {
                blueprint_entities.push(Chunk::from_arrow_msg(&arrow).unwrap().entity_path().to_string());
            }
            LogMsg::BlueprintActivationCommand(c) => activated |= c.make_active,
            _ => {}
        }
    }
    let _ = std::fs::remove_file(&path);
    assert!(activated, "no activation command");
    let views = blueprint_entities.iter().filter(|e| e.starts_with("/view/")).count();
    // scene, residual, condition, errors, events.
    assert!(views >= 5, "{blueprint_entities:?}");
    assert!(blueprint_entities.iter().any(|e| e.starts_with("/container/")));
}

#[test]
fn an_interrupted_run_leaves_a_readable_recording() {
    // Ctrl-C (SIGINT) during `mpmlab run --record`: the run stops after its
    // current step with exit code 130 and the file holds every step so far
    // plus the interruption event.
    let path = temp_path("rec-interrupted", "rrd");
    let mut child = spawn_mpmlab(
        &[
            "run".as_ref(),
            "scenarios/ghost-collision-plastic.toml".as_ref(),
            "--record".as_ref(),
            path.as_os_str(),
        ],
        std::process::Stdio::piped(),
    );
    // Interrupt once it has printed step 11 (of 1000): whatever the
    // machine's speed, the run is then well inside the scene.
    let rx = step_lines(&mut child);
    let seen = wait_for_step(&rx, 11);
    let killed = std::process::Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(killed.success());
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(130), "{err}");
    assert!(err.contains("interrupted after step"), "{err}");
    let positions = rerun::Points2D::descriptor_positions().component;
    let step_tl: rerun::TimelineName = "step".into();
    let (mut steps, mut events) = (std::collections::BTreeSet::new(), 0);
    for chunk in read_chunks(&path) {
        let e = chunk.entity_path().to_string();
        if e == "/points" {
            for ((t, _), _) in chunk
                .iter_component_indices(step_tl, positions)
                .zip(chunk.iter_slices::<[f32; 2]>(positions))
            {
                steps.insert(t.as_i64());
            }
        }
        if e == "/events" {
            events += chunk.num_rows();
        }
    }
    // Every step the table printed is in the file (metrics every step,
    // points at the scene's cadence), nothing after the last, and the
    // message names it.
    let printed = rx.iter().fold(seen, i64::max);
    assert!(err.contains(&format!("interrupted after step {printed}")), "{err}");
    let chunks = read_chunks(&path);
    holds_steps_up_to(&chunks, printed);
    assert_eq!(scalar_steps(&chunks, "/metrics/unknowns").last(), Some(&printed));
    assert!(steps.iter().all(|&t| t <= printed), "{steps:?}");
    assert!((11..1000).contains(&printed), "interrupted after step {printed}");
    let _ = std::fs::remove_file(&path);
    // start, the interruption, and the end of the run.
    assert!(events >= 3, "{events} events");
}

/// The entity paths of a short recorded run of a shipped scene.
fn entities_of(scene: &str, steps: usize) -> std::collections::BTreeSet<String> {
    let mut sim = sim_with(scene, |s| s.analysis.condition_every = 1);
    let text = std::fs::read_to_string(common::scene_path(scene)).unwrap();
    let path = temp_path("rec-families", "rrd");
    let mut rec = Recorder::create(&path, &text, &sim, true).unwrap();
    for _ in 0..steps {
        let r = sim.step().unwrap();
        rec.log_step(&r, &sim).unwrap();
    }
    rec.event("parameter: test event", "INFO").unwrap();
    rec.finish().unwrap();
    let e = read_chunks(&path).iter().map(|c| c.entity_path().to_string()).collect();
    let _ = std::fs::remove_file(&path);
    e
}

#[test]
fn every_entity_family_is_recorded() {
    // Quasi-static with ghost stabilisation (G 5.5 beam).
    let e = entities_of("elastic-beam-ghost", 2);
    for f in [
        "/scene",
        "/grid",
        "/grid/active",
        "/grid/ghost_faces",
        "/points",
        "/events",
        "/metrics/residual",
        "/metrics/log10/residual",
        "/metrics/condition/stiffness",
        "/metrics/condition/stiffness_unstabilised",
        "/metrics/energy/strain",
        "/metrics/energy/external_work",
        "/metrics/energy/ghost",
        "/metrics/newton/iterations",
        "/metrics/time/total",
        "/metrics/unknowns",
    ] {
        assert!(e.contains(f), "beam: missing {f} in {e:?}");
    }
    // Explicit dynamics: energies, momentum and mass conditioning.
    let e = entities_of("ghost-collision-elastic", 2);
    for f in [
        "/points",
        "/grid/ghost_faces",
        "/metrics/energy/kinetic",
        "/metrics/energy/kinetic_grid",
        "/metrics/energy/total",
        "/metrics/energy/balance_error",
        "/metrics/momentum/x",
        "/metrics/condition/mass_stabilised",
        "/metrics/condition/mass_consistent",
        "/metrics/condition/mass_lumped",
        "/metrics/cfl/stabilised",
        "/events",
    ] {
        assert!(e.contains(f), "collision: missing {f} in {e:?}");
    }
}

/// What `/points` holds in a recording: the steps with positions and the
/// names of its components.
fn points_of(chunks: &[rerun::log::Chunk]) -> (std::collections::BTreeSet<i64>, std::collections::BTreeSet<String>) {
    let positions = rerun::Points2D::descriptor_positions().component;
    let step_tl: rerun::TimelineName = "step".into();
    let (mut steps, mut components) = (std::collections::BTreeSet::new(), std::collections::BTreeSet::new());
    for c in chunks.iter().filter(|c| c.entity_path().to_string() == "/points") {
        for (t, _) in c.iter_component_indices(step_tl, positions) {
            steps.insert(t.as_i64());
        }
        components.extend(c.components_identifiers().map(|i| i.to_string()));
    }
    (steps, components)
}

/// The steps at which `entity` holds a scalar.
fn scalar_steps(chunks: &[rerun::log::Chunk], entity: &str) -> Vec<i64> {
    let scalars = rerun::Scalars::descriptor_scalars().component;
    let step_tl: rerun::TimelineName = "step".into();
    let mut s: Vec<i64> = chunks
        .iter()
        .filter(|c| c.entity_path().to_string() == entity)
        .flat_map(|c| {
            c.iter_component_indices(step_tl, scalars)
                .map(|(t, _)| t.as_i64())
                .collect::<Vec<_>>()
        })
        .collect();
    s.sort();
    s
}

/// A short collision (10 steps of 3.5 ms) with `edit` applied, recorded to
/// the end (or its first failure); the chunks and the simulation.
fn record_collision(
    stem: &str,
    edit: impl FnOnce(&mut mpmlab::scene::Scene),
) -> (Vec<rerun::log::Chunk>, mpmlab::Simulation, Option<usize>) {
    let mut sim = sim_with("ghost-collision-elastic", |s| {
        s.analysis.load_steps = 10;
        s.analysis.duration = Some(0.035);
        s.analysis.condition_every = 0;
        edit(s);
    });
    let text = std::fs::read_to_string(common::scene_path("ghost-collision-elastic")).unwrap();
    let path = temp_path(stem, "rrd");
    let mut rec = Recorder::create(&path, &text, &sim, true).unwrap();
    let mut failed = None;
    while !sim.finished() {
        let s = mpmlab::runner::step(&mut sim, &mut [&mut rec]);
        assert!(s.detached.is_empty(), "{:?}", s.detached);
        if let Err(f) = s.result {
            failed = Some(f.step());
            break;
        }
    }
    let size = rec.finish().unwrap();
    assert_eq!(size.bytes, std::fs::metadata(&path).unwrap().len());
    let chunks = read_chunks(&path);
    let _ = std::fs::remove_file(&path);
    (chunks, sim, failed)
}

#[test]
fn points_follow_the_cadence_and_metrics_every_step() {
    // every = 3 over 10 steps: points at the first state, steps 3, 6, 9 and
    // the last; the energies at every step.
    let (chunks, _, failed) = record_collision("rec-every", |s| s.record.every = Some(3));
    assert_eq!(failed, None);
    let (steps, _) = points_of(&chunks);
    assert_eq!(steps.into_iter().collect::<Vec<_>>(), [0, 3, 6, 9, 10]);
    assert_eq!(
        scalar_steps(&chunks, "/metrics/energy/kinetic"),
        (1..=10).collect::<Vec<_>>()
    );
    // The active cells go with the points.
    let active = chunks
        .iter()
        .filter(|c| c.entity_path().to_string() == "/grid/active")
        .map(|c| c.num_rows())
        .sum::<usize>();
    assert_eq!(active, 5);
}

#[test]
fn points_follow_a_cadence_in_simulated_time() {
    // Steps of 3.5 ms, points every 10 ms: the first step past 10, 20 and
    // 30 ms (3, 6, 9), the first state and the last.
    let (chunks, _, _) = record_collision("rec-dt", |s| s.record.dt = Some(0.01));
    let (steps, _) = points_of(&chunks);
    assert_eq!(steps.into_iter().collect::<Vec<_>>(), [0, 3, 6, 9, 10]);
}

#[test]
fn a_failed_step_holds_the_points_it_started_from() {
    // Both ghosts fly to the lower left at 10 m/s (3.5 cm a step) and leave
    // the grid a few steps in; the cadence would hold only the first and
    // last states, yet the state before the failure is there, with the
    // error event at the failed step.
    let (chunks, _, failed) = record_collision("rec-failed", |s| {
        s.record.every = Some(100);
        for b in &mut s.bodies {
            b.velocity = [-10.0, -10.0];
        }
    });
    let k = failed.expect("the ghosts leave the grid") as i64;
    assert!(k >= 2, "failed at step {k}");
    let (steps, _) = points_of(&chunks);
    assert_eq!(steps.into_iter().collect::<Vec<_>>(), [0, k - 1]);
    let step_tl: rerun::TimelineName = "step".into();
    let text = rerun::TextLog::descriptor_text().component;
    let errors: Vec<i64> = chunks
        .iter()
        .filter(|c| c.entity_path().to_string() == "/events")
        .flat_map(|c| {
            c.iter_component_indices(step_tl, text)
                .map(|(t, _)| t.as_i64())
                .collect::<Vec<_>>()
        })
        .collect();
    assert!(errors.contains(&k), "no event at step {k}: {errors:?}");
}

#[test]
fn only_the_asked_fields_are_recorded() {
    use mpmlab::field::Field;
    use mpmlab::scene::FieldNames;
    let positions = rerun::Points2D::descriptor_positions().component.to_string();
    let keys: Vec<&str> = Field::ALL.iter().map(|f| f.key()).collect();
    // One field: speed, with the positions, colours and radii.
    let (chunks, sim, _) = record_collision("rec-speed", |s| {
        s.record.fields = Some(FieldNames::Many(vec!["speed".into()]));
    });
    let (_, components) = points_of(&chunks);
    assert!(components.contains(&positions), "{components:?}");
    for k in &keys {
        assert_eq!(components.contains(*k), *k == "speed", "{k}: {components:?}");
    }
    let speed: rerun::ComponentIdentifier = "speed".into();
    let last: Vec<f64> = chunks
        .iter()
        .filter(|c| c.entity_path().to_string() == "/points")
        .flat_map(|c| c.iter_slices::<f64>(speed).map(|v| v.to_vec()).collect::<Vec<_>>())
        .last()
        .unwrap();
    assert_eq!(last, Field::Speed.values(&sim));
    // The recording says which fields it holds.
    let text = rerun::TextLog::descriptor_text().component;
    let said: Vec<String> = chunks
        .iter()
        .filter(|c| c.entity_path().to_string() == "/recording/fields")
        .flat_map(|c| {
            c.iter_slices::<String>(text)
                .flat_map(|v| v.to_vec())
                .collect::<Vec<_>>()
        })
        .map(|s| s.to_string())
        .collect();
    assert_eq!(said, ["speed"]);

    // Positions only.
    let (chunks, _, _) = record_collision("rec-positions", |s| {
        s.record.fields = Some(FieldNames::Many(vec!["positions".into()]));
    });
    let (steps, components) = points_of(&chunks);
    assert_eq!(steps.len(), 11);
    assert!(components.contains(&positions));
    assert!(keys.iter().all(|k| !components.contains(*k)), "{components:?}");

    // Every field, at every step: what recordings held before cadences.
    let (chunks, sim, _) = record_collision("rec-all", |s| {
        s.record.every = Some(1);
        s.record.fields = Some(FieldNames::One("all".into()));
    });
    let (steps, components) = points_of(&chunks);
    assert_eq!(steps.len(), 11);
    for f in Field::ALL {
        assert!(components.contains(f.key()), "{}: {components:?}", f.key());
        let id: rerun::ComponentIdentifier = f.key().into();
        let last: Vec<f64> = chunks
            .iter()
            .filter(|c| c.entity_path().to_string() == "/points")
            .flat_map(|c| c.iter_slices::<f64>(id).map(|v| v.to_vec()).collect::<Vec<_>>())
            .last()
            .unwrap();
        assert_eq!(last, f.values(&sim), "{}", f.key());
    }
}

#[test]
fn a_recording_with_a_cadence_keeps_the_layout() {
    use rerun::external::re_log_encoding::DecoderApp;
    use rerun::log::LogMsg;
    let sim = sim_with("ghost-collision-elastic", |s| s.record.every = Some(50));
    let text = std::fs::read_to_string(common::scene_path("ghost-collision-elastic")).unwrap();
    let path = temp_path("rec-layout-cadence", "rrd");
    Recorder::create(&path, &text, &sim, true).unwrap().finish().unwrap();
    let file = std::fs::File::open(&path).unwrap();
    let (mut blueprint, mut activated) = (0, false);
    for msg in DecoderApp::decode_eager(std::io::BufReader::new(file)).unwrap() {
        match msg.unwrap() {
            LogMsg::ArrowMsg(store, _) if !store.is_recording() => blueprint += 1,
            LogMsg::BlueprintActivationCommand(c) => activated |= c.make_active,
            _ => {}
        }
    }
    let _ = std::fs::remove_file(&path);
    assert!(activated && blueprint > 5, "{blueprint} blueprint chunks");
}

/// Record `steps` steps of `scene` (fewer if it finishes); the chunks of
/// the recording store, the blueprint's view titles, and the simulation.
fn record_steps(scene: &str, steps: usize) -> (Vec<rerun::log::Chunk>, Vec<String>, mpmlab::Simulation) {
    use rerun::external::re_log_encoding::DecoderApp;
    use rerun::external::re_sdk_types::blueprint::archetypes::ViewBlueprint;
    use rerun::log::{Chunk, LogMsg};
    let mut sim = sim_with(scene, |_| {});
    let text = std::fs::read_to_string(common::scene_path(scene)).unwrap();
    let path = temp_path(&format!("rec-view-{scene}"), "rrd");
    let mut rec = Recorder::create(&path, &text, &sim, true).unwrap();
    for _ in 0..steps {
        if sim.finished() {
            break;
        }
        let r = sim.step().unwrap();
        rec.log_step(&r, &sim).unwrap();
    }
    rec.finish().unwrap();
    let name = ViewBlueprint::descriptor_display_name().component;
    let (mut chunks, mut views) = (Vec::new(), Vec::new());
    let file = std::fs::File::open(&path).unwrap();
    for msg in DecoderApp::decode_eager(std::io::BufReader::new(file)).unwrap() {
        if let LogMsg::ArrowMsg(store, arrow) = msg.unwrap() {
            let c = Chunk::from_arrow_msg(&arrow).unwrap();
            if store.is_recording() {
                chunks.push(c);
            } else if c.entity_path().to_string().starts_with("/view/") {
                for names in c.iter_slices::<String>(name) {
                    views.extend(names.iter().map(|n| n.to_string()));
                }
            }
        }
    }
    let _ = std::fs::remove_file(&path);
    (chunks, views, sim)
}

#[test]
fn the_scene_is_drawn_with_physical_y_up() {
    // rerun's 2D views draw y downward: every entity of the scene carries a
    // static transform scaling y by -1 (so the plate's hole is drawn
    // bottom-left), while the points keep their true coordinates.
    let (chunks, _, sim) = record_steps("plate-hole-neumann", 1);
    let scale = rerun::Transform3D::descriptor_scale().component;
    let mut flipped = std::collections::BTreeMap::new();
    for c in &chunks {
        for s in c.iter_slices::<[f32; 3]>(scale) {
            flipped.insert(c.entity_path().to_string(), s[0]);
        }
    }
    for root in [
        "/points",
        "/grid",
        "/boundaries",
        "/ibm",
        "/legend",
        "/loads",
        "/probes",
    ] {
        assert_eq!(flipped.get(root), Some(&[1.0, -1.0, 1.0]), "{root}: {flipped:?}");
    }
    let positions = rerun::Points2D::descriptor_positions().component;
    let last: Vec<[f32; 2]> = chunks
        .iter()
        .filter(|c| c.entity_path().to_string() == "/points")
        .flat_map(|c| {
            c.iter_slices::<[f32; 2]>(positions)
                .map(|p| p.to_vec())
                .collect::<Vec<_>>()
        })
        .last()
        .unwrap();
    // The plate's linear solution at S = E moves its edges by more than
    // the hole's radius: drawn at x0 + s u with the scale the recording
    // names (a tenth of the extent for the full-load displacement).
    let s = drawn_scale(&chunks);
    assert!(s < 0.5, "{s}");
    assert_eq!(last, drawn(&sim, s));
}

/// The deformation scale a small-strain recording names in its events (1
/// when none is named: true scale).
fn drawn_scale(chunks: &[rerun::log::Chunk]) -> f64 {
    common::event_texts(chunks)
        .iter()
        .find_map(|e| {
            let rest = e.split("drawn at x0 + ").nth(1)?;
            rest.split(' ').next()?.parse::<f64>().ok()
        })
        .unwrap_or(1.0)
}

/// The points as drawn at deformation scale `s`: `x0 + s (x - x0)`.
fn drawn(sim: &mpmlab::Simulation, s: f64) -> Vec<[f32; 2]> {
    let p = sim.points();
    p.x.iter()
        .zip(&p.x0)
        .map(|(x, x0)| [(x0[0] + s * (x[0] - x0[0])) as f32, (x0[1] + s * (x[1] - x0[1])) as f32])
        .collect()
}

#[test]
fn occupied_cells_hold_the_points_shown() {
    // `grid/occupied` are the cells of the points shown (as drawn, at the
    // small-strain deformation scale): every point lies in one of them
    // and each holds a point (checked on the boxes read back).
    let (chunks, _, sim) = record_steps("plate-hole-neumann", 1);
    let strips = rerun::LineStrips2D::descriptor_strips().component;
    let step_tl: rerun::TimelineName = "step".into();
    let mut boxes: Vec<[f32; 4]> = Vec::new();
    for c in chunks
        .iter()
        .filter(|c| c.entity_path().to_string() == "/grid/occupied")
    {
        for ((t, _), batch) in c
            .iter_component_indices(step_tl, strips)
            .zip(c.iter_component::<rerun::components::LineStrip2D>(strips))
        {
            if t.as_i64() == 1 {
                boxes = batch
                    .iter()
                    .map(|s| {
                        let xs = s.0.iter().map(|p| p.x());
                        let ys = s.0.iter().map(|p| p.y());
                        [
                            xs.clone().fold(f32::INFINITY, f32::min),
                            ys.clone().fold(f32::INFINITY, f32::min),
                            xs.fold(f32::NEG_INFINITY, f32::max),
                            ys.fold(f32::NEG_INFINITY, f32::max),
                        ]
                    })
                    .collect();
            }
        }
    }
    assert!(!boxes.is_empty());
    // Boxes are drawn a sixth of a cell inside the grid lines (2/3 of a
    // cell wide): the cell is the box grown by a quarter of its width.
    let inside = |b: &[f32; 4], p: [f32; 2]| {
        let d = 0.25 * (b[2] - b[0]) + 1e-6;
        p[0] >= b[0] - d && p[0] <= b[2] + d && p[1] >= b[1] - d && p[1] <= b[3] + d
    };
    let pts = drawn(&sim, drawn_scale(&chunks));
    for p in &pts {
        assert!(boxes.iter().any(|b| inside(b, *p)), "point {p:?} in no occupied cell");
    }
    for b in &boxes {
        assert!(pts.iter().any(|p| inside(b, *p)), "occupied cell {b:?} holds no point");
    }
}

#[test]
fn the_colour_bar_names_the_field_its_unit_and_range() {
    let (chunks, _, sim) = record_steps("column-small-strain", 1);
    let labels = rerun::Points2D::descriptor_labels().component;
    // Every frame's label, the step's among them (a finished recording
    // adds the frames it coloured again with the run's scale).
    let shown: Vec<Vec<String>> = chunks
        .iter()
        .filter(|c| c.entity_path().to_string() == "/legend/range")
        .flat_map(|c| {
            c.iter_slices::<String>(labels)
                .map(|l| l.iter().map(|s| s.to_string()).collect::<Vec<_>>())
                .collect::<Vec<_>>()
        })
        .collect();
    let syy: Vec<f64> = sim.points().stress.iter().map(|s| s[1]).collect();
    let (lo, hi) = syy
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
    // A stress is signed: its colours span [-m, m], m = max |s_yy| over
    // the run (here the last step's), grey at zero; the label also gives
    // the frame's own range.
    let m = lo.abs().max(hi.abs());
    let want = vec![format!(
        "sigma_yy (Pa): colours {:.3e} .. {m:.3e} (0 grey)\nthis frame {lo:.3e} .. {hi:.3e}",
        -m
    )];
    assert!(shown.contains(&want), "{shown:?}");
    // The initial state (zero stress) is one colour, grey, on the run's scale.
    let initial = vec![format!(
        "sigma_yy (Pa): colours {:.3e} .. {m:.3e} (0 grey)\nthis frame uniform 0.0000e0 ± 0.0e0",
        -m
    )];
    assert!(shown.contains(&initial), "{shown:?}");
    // Five ticks under the bar, from -m through 0 to m.
    let ticks: Vec<String> = chunks
        .iter()
        .filter(|c| c.entity_path().to_string() == "/legend/ticks")
        .flat_map(|c| {
            c.iter_slices::<String>(labels)
                .map(|l| l.iter().map(|s| s.to_string()).collect::<Vec<_>>())
                .collect::<Vec<_>>()
        })
        .last()
        .unwrap();
    let want: Vec<String> = [-m, -0.5 * m, 0.0, 0.5 * m, m]
        .iter()
        .map(|v| format!("{v:.2e}"))
        .collect();
    assert_eq!(ticks, want);
}

#[test]
fn residual_history_of_each_step_is_a_bar_chart() {
    // The viewer shows the step under the time cursor: one bar per
    // iteration, log10 of the relative residual the step reported.
    use rerun::external::re_sdk_types::datatypes::TensorBuffer;
    let mut sim = sim_with("slender-cantilever-finite-0", |s| s.analysis.load_steps = 40);
    let text = std::fs::read_to_string(common::scene_path("slender-cantilever-finite-0")).unwrap();
    let path = temp_path("rec-residuals", "rrd");
    let mut rec = Recorder::create(&path, &text, &sim, true).unwrap();
    let mut reports = Vec::new();
    for _ in 0..2 {
        let r = sim.step().unwrap();
        rec.log_step(&r, &sim).unwrap();
        reports.push(r);
    }
    rec.finish().unwrap();
    let values = rerun::BarChart::descriptor_values().component;
    let step_tl: rerun::TimelineName = "step".into();
    let mut bars: BTreeMap<i64, Vec<f64>> = BTreeMap::new();
    for c in read_chunks(&path) {
        if c.entity_path().to_string() != "/metrics/newton/residual_history" {
            continue;
        }
        for ((t, _), batch) in c
            .iter_component_indices(step_tl, values)
            .zip(c.iter_component::<rerun::components::TensorData>(values))
        {
            let TensorBuffer::F64(b) = &batch[0].0.buffer else {
                panic!("residuals as f64")
            };
            bars.insert(t.as_i64(), b.to_vec());
        }
    }
    let _ = std::fs::remove_file(&path);
    for r in &reports {
        assert!(r.residuals.len() > 2, "a Newton step iterates: {:?}", r.residuals);
        let expected: Vec<f64> = r.residuals.iter().map(|v| v.log10()).collect();
        assert_eq!(bars[&(r.step as i64)], expected, "step {}", r.step);
    }
}

#[test]
fn each_layout_shows_the_panels_its_run_has() {
    let has = |views: &[String], s: &str| views.iter().any(|v| v.contains(s));
    // Linear, with an exact solution: residual, conditioning, energies and errors.
    let (_, v, _) = record_steps("column-small-strain", 1);
    for s in [
        "scene, y up",
        "log10 |K du - r|/|r| against refinement",
        "condition number of the stiffness against load step",
        "energy (J/m)",
        "error vs exact",
        "events",
    ] {
        assert!(has(&v, s), "column: no `{s}` in {v:?}");
    }
    assert!(!has(&v, "without ghost") && !has(&v, "Newton"), "{v:?}");
    // Newton with ghost and no exact solution: both condition numbers on
    // one plot (log10: 20 orders apart fit), probes one panel per unit.
    let (_, v, _) = record_steps("elastic-beam-ghost", 1);
    for s in [
        "Newton residual history of the step at the cursor: log10 |r|/|r0| against iteration",
        "Newton iterations per step against load step",
        "log10 condition number, with and without ghost against load step",
        "energy (J/m)",
        // G 5.5's tip, in the scene's units.
        "probes: displacements (m)",
        "probes: stresses (Pa)",
    ] {
        assert!(has(&v, s), "beam: no `{s}` in {v:?}");
    }
    assert!(
        !has(&v, "error"),
        "beam: an errors panel without an exact solution: {v:?}"
    );
    // Explicit dynamics: energies, their balance and the masses' conditioning.
    let (_, v, _) = record_steps("ghost-collision-elastic", 1);
    for s in [
        "energy (J/m) against time (s)",
        "balance error",
        "condition number of the mass: stabilised, lumped, consistent",
    ] {
        assert!(has(&v, s), "collision: no `{s}` in {v:?}");
    }
    assert!(
        !has(&v, "|r") && !has(&v, "error vs") && !has(&v, "probes"),
        "collision: {v:?}"
    );
    // A scene in mm, N, MPa is titled so.
    let (_, v, _) = record_steps("block-roller-0", 1);
    for s in [
        "sigma_yy (MPa)",
        "energy (N mm/mm)",
        "probes: displacements (mm)",
        "probes: forces (N/mm)",
    ] {
        assert!(has(&v, s), "block: no `{s}` in {v:?}");
    }
}

#[test]
fn recordings_are_named_after_scene_and_run() {
    use mpmlab::record::recording_name;
    use std::path::Path;
    assert_eq!(
        recording_name("plate", Path::new("recordings/plate-20261201-2330.rrd")),
        "plate-20261201-2330"
    );
    assert_eq!(
        recording_name("plate", Path::new("sweeps/s/recordings/h=0.1.rrd")),
        "plate: h=0.1"
    );
    // The name travels in the file, as the recording's property.
    let (chunks, _, _) = record_steps("column-small-strain", 1);
    let name = rerun::RecordingInfo::descriptor_name().component;
    let names: Vec<String> = chunks
        .iter()
        .flat_map(|c| {
            c.iter_slices::<String>(name)
                .flat_map(|n| n.iter().map(|s| s.to_string()).collect::<Vec<_>>())
                .collect::<Vec<_>>()
        })
        .collect();
    assert_eq!(names.len(), 1, "{names:?}");
    // The test file's stem holds the scene's name: the stem alone.
    assert!(
        names[0].starts_with("mpmlab-rec-view-column-small-strain-"),
        "{names:?}"
    );
}

/// Events keep their step and their order: several at one step (a
/// parameter change before the first step logged from another thread, as
/// the TUI's engine does; a failure, then the end of the run) stay
/// distinct on the `event` timeline, each with its step.
#[test]
fn events_of_one_step_stay_distinct_with_their_step() {
    let path = temp_path("rec-events", "rrd");
    let sim = sim_with("column-small-strain", |_| {});
    let text = std::fs::read_to_string(common::scene_path("column-small-strain")).unwrap();
    let rec = Recorder::create(&path, &text, &sim, true).unwrap();
    // The TUI moves the recorder to its engine thread before any step.
    let mut rec = std::thread::spawn(move || {
        rec.event("parameter: gamma_K = 1e6 Pa from step 1", "INFO").unwrap();
        rec.event("parameter: tolerance = 1e-9 from step 1", "INFO").unwrap();
        rec
    })
    .join()
    .unwrap();
    let mut sim = sim;
    let r = sim.step().unwrap();
    rec.log_step(&r, &sim).unwrap();
    rec.event("run complete", "INFO").unwrap();
    rec.event("end of interactive session", "INFO").unwrap();
    rec.finish().unwrap();
    let text_c = rerun::TextLog::descriptor_text().component;
    let (step_tl, event_tl): (rerun::TimelineName, rerun::TimelineName) = ("step".into(), "event".into());
    let mut by_event: BTreeMap<i64, (i64, String)> = BTreeMap::new();
    for c in read_chunks(&path) {
        if c.entity_path().to_string() != "/events" {
            continue;
        }
        let steps: Vec<i64> = c
            .iter_component_indices(step_tl, text_c)
            .map(|(t, _)| t.as_i64())
            .collect();
        let events: Vec<i64> = c
            .iter_component_indices(event_tl, text_c)
            .map(|(t, _)| t.as_i64())
            .collect();
        let texts: Vec<String> = c
            .iter_slices::<String>(text_c)
            .flat_map(|v| v.into_iter().map(|s| s.to_string()))
            .collect();
        assert_eq!(
            (steps.len(), events.len()),
            (texts.len(), texts.len()),
            "every event has both times"
        );
        for ((s, e), t) in steps.into_iter().zip(events).zip(texts) {
            assert!(by_event.insert(e, (s, t)).is_none(), "event {e} twice");
        }
    }
    let _ = std::fs::remove_file(&path);
    let got: Vec<(i64, i64, &str)> = by_event.iter().map(|(e, (s, t))| (*e, *s, t.as_str())).collect();
    assert_eq!(got.len(), 5, "{got:?}");
    assert!(got[0].2.starts_with("start:") && got[0].1 == 0, "{got:?}");
    assert_eq!(
        (got[1].1, got[2].1),
        (0, 0),
        "changes before step 1 belong to step 0: {got:?}"
    );
    assert!(
        got[1].2.contains("gamma_K") && got[2].2.contains("tolerance"),
        "{got:?}"
    );
    assert_eq!((got[3].1, got[3].2), (1, "run complete"), "{got:?}");
    assert_eq!((got[4].1, got[4].2), (1, "end of interactive session"), "{got:?}");
}

/// The `mpmlab` binary running in the crate folder with its stdout piped
/// (its stderr as `stderr` says).
fn spawn_mpmlab(args: &[&std::ffi::OsStr], stderr: std::process::Stdio) -> std::process::Child {
    std::process::Command::new(env!("CARGO_BIN_EXE_mpmlab"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(std::process::Stdio::piped())
        .stderr(stderr)
        .spawn()
        .unwrap()
}

/// The step numbers of a run's table rows as they are printed (other lines
/// are left out), read on a thread until the output closes.
fn step_lines(child: &mut std::process::Child) -> std::sync::mpsc::Receiver<i64> {
    use std::io::BufRead;
    let out = child.stdout.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in std::io::BufReader::new(out).lines().map_while(Result::ok) {
            if let Some(Ok(k)) = line.split_whitespace().next().map(str::parse::<i64>) {
                if tx.send(k).is_err() {
                    break;
                }
            }
        }
    });
    rx
}

/// Wait until the run has printed step `k` (at most a minute).
fn wait_for_step(rx: &std::sync::mpsc::Receiver<i64>, k: i64) -> i64 {
    let until = std::time::Instant::now() + std::time::Duration::from_secs(60);
    loop {
        let left = until.saturating_duration_since(std::time::Instant::now());
        match rx.recv_timeout(left) {
            Ok(s) if s >= k => return s,
            Ok(_) => {}
            Err(e) => panic!("step {k} was never printed: {e}"),
        }
    }
}

/// Whether `path` is a recording rerun accepts as complete: every message
/// decodes, and its footer holds a manifest per store that lists exactly
/// the chunks the store has (what `rerun rrd verify` checks; the CLI is
/// run too when it is installed, and must be in CI). Its recording chunks.
fn verified_chunks(path: &std::path::Path) -> Vec<rerun::log::Chunk> {
    use rerun::external::re_log_encoding::DecoderApp;
    use rerun::log::{Chunk, LogMsg};
    let file = std::fs::File::open(path).unwrap();
    let mut it = DecoderApp::decode_eager(std::io::BufReader::new(file)).unwrap();
    let mut per_store: BTreeMap<String, u64> = BTreeMap::new();
    let mut chunks = Vec::new();
    for msg in it.by_ref() {
        if let LogMsg::ArrowMsg(store, arrow) = msg.unwrap() {
            *per_store.entry(format!("{store:?}")).or_default() += 1;
            if store.is_recording() {
                chunks.push(Chunk::from_arrow_msg(&arrow).unwrap());
            }
        }
    }
    let manifests = it.rrd_manifests().unwrap();
    assert!(!manifests.is_empty(), "{}: no footer", path.display());
    let listed: BTreeMap<String, u64> = manifests
        .iter()
        .map(|m| {
            m.sanity_check_heavy().unwrap();
            (format!("{:?}", m.store_id), m.data.num_rows() as u64)
        })
        .collect();
    assert_eq!(
        listed,
        per_store,
        "{}: the footer's manifests against the chunks",
        path.display()
    );
    match std::process::Command::new("rerun")
        .args(["rrd", "verify"])
        .arg(path)
        .output()
    {
        Ok(o) => assert!(
            o.status.success(),
            "rerun rrd verify {}: {}",
            path.display(),
            String::from_utf8_lossy(&o.stderr)
        ),
        Err(e) => {
            assert!(
                std::env::var_os("CI").is_none(),
                "recordings are verified with the rerun CLI: {e} (.ci/run installs it with `python3 -m pip install rerun-sdk==0.36.3`)"
            );
            eprintln!("rerun rrd verify skipped: {e}");
        }
    }
    chunks
}

/// Every step up to `last` has its metrics in `chunks`, and its points
/// where the default cadence of the 1000-step collision puts them.
fn holds_steps_up_to(chunks: &[rerun::log::Chunk], last: i64) {
    let metrics: std::collections::BTreeSet<i64> = scalar_steps(chunks, "/metrics/unknowns").into_iter().collect();
    let missing: Vec<i64> = (1..=last).filter(|k| !metrics.contains(k)).collect();
    assert!(missing.is_empty(), "steps printed but not recorded: {missing:?}");
    let sim = common::sim_with("ghost-collision-plastic", |_| {});
    let a = &sim.model().analysis;
    let plan = mpmlab::model::record::Plan::new(
        sim.model().record.cadence,
        sim.load_steps(),
        sim.points().len(),
        a.duration.map(|d| d / a.load_steps as f64),
    );
    let (points, _) = points_of(chunks);
    let missing: Vec<i64> = (0..=last)
        .filter(|&k| (k == 0 || plan.holds_points(k as usize)) && !points.contains(&k))
        .collect();
    assert!(missing.is_empty(), "steps printed without their points: {missing:?}");
}

#[test]
fn a_killed_run_is_repaired_with_every_step_it_printed() {
    // SIGKILL leaves no chance to close the file: it lacks rerun's footer.
    // With --record-sync 0 every step is in the file before its row is
    // printed; `mpmlab repair` writes the footer again.
    let path = temp_path("rec-killed", "rrd");
    let fixed = temp_path("rec-killed-repaired", "rrd");
    let mut child = spawn_mpmlab(
        &[
            "run".as_ref(),
            "scenarios/ghost-collision-plastic.toml".as_ref(),
            "--record-sync".as_ref(),
            "0".as_ref(),
            "--record".as_ref(),
            path.as_os_str(),
        ],
        std::process::Stdio::null(),
    );
    let rx = step_lines(&mut child);
    let seen = wait_for_step(&rx, 20);
    child.kill().unwrap();
    let status = child.wait().unwrap();
    assert_eq!(status.code(), None, "killed by a signal");
    // Rows already in the pipe were printed before the kill too.
    let printed = rx.iter().fold(seen, i64::max);
    assert!((20..1000).contains(&printed), "{printed}");
    // The run never renamed its file into place: it is `NAME.partial`.
    assert!(!path.exists(), "a killed run's file keeps its temporary name");
    let partial = mpmlab::output::partial_of(&path);
    let file = std::fs::File::open(&partial).unwrap();
    let mut it = rerun::external::re_log_encoding::DecoderApp::decode_eager(std::io::BufReader::new(file)).unwrap();
    it.by_ref().for_each(drop);
    assert!(
        it.rrd_manifests().unwrap().is_empty(),
        "a killed run's file has no footer"
    );

    let (code, out, err) = common::mpmlab(&["repair", partial.to_str().unwrap(), fixed.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("repaired"), "{out}");
    assert!(
        out.contains("without rerun's footer") || out.contains("incomplete message"),
        "{out}"
    );
    let chunks = verified_chunks(&fixed);
    holds_steps_up_to(&chunks, printed);
    assert!(
        out.contains(&format!(
            "data up to step {}",
            scalar_steps(&chunks, "/metrics/unknowns").last().unwrap()
        )),
        "{out}"
    );

    // The input is left alone; a second repair of a complete file copies it.
    let again = temp_path("rec-killed-again", "rrd");
    let (code, out, _) = common::mpmlab(&["repair", fixed.to_str().unwrap(), again.to_str().unwrap()]);
    assert_eq!(code, 0);
    assert!(out.contains("the recording was complete"), "{out}");
    assert_eq!(read_chunks(&again).len(), chunks.len());
    for p in [&path, &fixed, &again] {
        let _ = std::fs::remove_file(p);
    }
    let _ = std::fs::remove_file(&partial);
}

#[test]
fn repair_refuses_what_it_cannot_repair() {
    let rec = temp_path("rec-refused", "rrd");
    let out = temp_path("rec-refused-out", "rrd");
    let r = |a: &std::path::Path, b: &std::path::Path| {
        common::mpmlab(&["repair", a.to_str().unwrap(), b.to_str().unwrap()])
    };
    // Not a recording, or only its stream header: nothing to keep, nothing written.
    std::fs::write(&rec, "step,load\n").unwrap();
    let (code, _, err) = r(&rec, &out);
    assert_eq!(code, 2);
    assert!(err.contains("is not a rerun recording"), "{err}");
    std::fs::write(&rec, b"RRF2\x00\x24\x03\x00\x01\x02\x00\x00").unwrap();
    let (code, _, err) = r(&rec, &out);
    assert_eq!(code, 2);
    assert!(err.contains("holds no complete message"), "{err}");
    assert!(!out.exists());
    // The input itself, or a file that is not a recording, is not an output.
    let (code, _, err) = r(&rec, &rec);
    assert_eq!(code, 2);
    assert!(err.contains("is the input itself"), "{err}");
    let scene = common::scene_path("patch-compression");
    let (code, _, err) = r(&rec, &scene);
    assert_eq!(code, 2);
    assert!(err.contains("is not a rerun recording; refusing to overwrite"), "{err}");
    let _ = std::fs::remove_file(&rec);
}

#[test]
fn a_second_signal_ends_the_run_at_once_and_its_recording_can_be_repaired() {
    let path = temp_path("rec-two-signals", "rrd");
    let fixed = temp_path("rec-two-signals-repaired", "rrd");
    let mut child = spawn_mpmlab(
        &[
            "run".as_ref(),
            "scenarios/ghost-collision-plastic.toml".as_ref(),
            "--record-sync".as_ref(),
            "0".as_ref(),
            "--record".as_ref(),
            path.as_os_str(),
        ],
        std::process::Stdio::null(),
    );
    let rx = step_lines(&mut child);
    let seen = wait_for_step(&rx, 20);
    let pid = child.id().to_string();
    for _ in 0..2 {
        let sent = std::process::Command::new("kill")
            .args(["-INT", &pid])
            .status()
            .unwrap();
        assert!(sent.success());
    }
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(130));
    let printed = rx.iter().fold(seen, i64::max);
    // The first signal may have closed the file (renamed into place)
    // before the second came, or not (left as `NAME.partial`); either way
    // the repaired file holds every printed step.
    let partial = mpmlab::output::partial_of(&path);
    let written = if path.exists() {
        path.to_path_buf()
    } else {
        partial.clone()
    };
    let (code, out, err) = common::mpmlab(&["repair", written.to_str().unwrap(), fixed.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("repaired"), "{out}");
    holds_steps_up_to(&verified_chunks(&fixed), printed);
    for p in [&path, &fixed] {
        let _ = std::fs::remove_file(p);
    }
    let _ = std::fs::remove_file(&partial);
}

#[test]
fn sigterm_during_a_long_step_stops_it_with_a_complete_recording() {
    // The G 5.5 beam at h = 1/24 m: Newton steps of most of a second.
    let text = std::fs::read_to_string(common::scene_path("elastic-beam-ghost"))
        .unwrap()
        .replace("h = 0.5\n", "h = 0.041666666666666664\n")
        .replace("load_steps = 50", "load_steps = 10")
        .replace("max_iterations = 10", "max_iterations = 30");
    assert!(text.contains("0.0416") && text.contains("load_steps = 10") && text.contains("max_iterations = 30"));
    let scene = temp_path("beam-fine", "toml");
    std::fs::write(&scene, &text).unwrap();
    let path = temp_path("rec-sigterm", "rrd");
    let mut child = spawn_mpmlab(
        &["run".as_ref(), scene.as_os_str(), "--record".as_ref(), path.as_os_str()],
        std::process::Stdio::piped(),
    );
    let rx = step_lines(&mut child);
    // Step 1 is printed as step 2 begins: the signal lands in step 2 (or,
    // on a machine fast enough to have gone on, just before it), and
    // either way the run stops after step 1 with nothing of step 2.
    let seen = wait_for_step(&rx, 1);
    let kill = std::process::Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(130), "{err}");
    let printed = rx.iter().fold(seen, i64::max);
    assert_eq!(printed, 1, "the signal came during step 2");
    assert!(err.contains("interrupted after step 1"), "{err}");
    let chunks = verified_chunks(&path);
    assert_eq!(scalar_steps(&chunks, "/metrics/unknowns"), vec![1]);
    let events = common::events(&path);
    assert!(
        events.iter().any(|e| e.contains("interrupted after step 1")),
        "{events:?}"
    );
    for p in [&path, &scene] {
        let _ = std::fs::remove_file(p);
    }
}

#[test]
fn a_step_beyond_the_memory_budget_is_an_error_event() {
    // The step's factor is refused by its estimate (the budget, 1 MiB, is
    // below what the process holds): the recording keeps the initial state
    // and the failure, named as out of memory, at step 1.
    let text = std::fs::read_to_string(common::scene_path("column-small-strain")).unwrap();
    let scene = mpmlab::scene::Scene::parse(&text, "column-small-strain").unwrap();
    let mut model = mpmlab::Model::build(&scene, &text, "column-small-strain").unwrap();
    model.max_memory = 1 << 20;
    let mut sim = mpmlab::Simulation::new(model);
    let path = temp_path("rec-out-of-memory", "rrd");
    let mut rec = Recorder::create(&path, &text, &sim, true).unwrap();
    let failure = sim.step_guarded().unwrap_err();
    assert!(
        matches!(failure, mpmlab::StepFailure::OutOfMemory { step: 1, .. }),
        "{failure:?}"
    );
    rec.log_failure(&failure, &sim).unwrap();
    rec.finish().unwrap();
    let events = common::events(&path);
    let _ = std::fs::remove_file(&path);
    assert!(
        events.iter().any(
            |e| e.starts_with("step 1 failed: out of memory: the Cholesky factor of")
                && e.contains("needs an estimated")
                && e.contains("grid.h")
        ),
        "{events:?}"
    );
}

/// Seeded damage to a complete recording (a short run): 300 single-bit
/// flips and 60 truncations, each repaired by `mpmlab repair`. A repair
/// never panics or aborts (rerun's arrow decoder panics on some damaged
/// payloads, 2% of flips in the issue's trial, and asks for petabytes on
/// some damaged lengths, which aborts a process: repair decodes in a
/// child first), never leaves its temporary file, and either writes a
/// recording (saying where decoding stopped, by byte range) or refuses
/// with its reason. The recording differs from run to run (rerun's ids),
/// so the cases do too; every one must hold.
#[test]
fn repair_survives_seeded_damage_and_names_where_it_stopped() {
    let rec = temp_path("rec-fuzz", "rrd");
    let (code, _, err) = common::mpmlab(&[
        "run",
        common::scene_path("patch-compression").to_str().unwrap(),
        "--quiet",
        "--record",
        rec.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let good = std::fs::read(&rec).unwrap();
    let damaged = temp_path("rec-fuzz-damaged", "rrd");
    let out = temp_path("rec-fuzz-out", "rrd");
    let mut seed = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = |n: usize| {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed % n as u64) as usize
    };
    let (mut written, mut refused, mut stopped) = (0, 0, 0);
    for k in 0..360 {
        let bytes = if k < 300 {
            // The first flip hits the stream header's magic.
            let bit = if k == 0 { 0 } else { next(8 * good.len()) };
            let mut b = good.clone();
            b[bit / 8] ^= 1 << (bit % 8);
            b
        } else {
            good[..next(good.len())].to_vec()
        };
        std::fs::write(&damaged, &bytes).unwrap();
        let _ = std::fs::remove_file(&out);
        let (code, o, e) = common::mpmlab(&["repair", damaged.to_str().unwrap(), out.to_str().unwrap(), "--force"]);
        assert!(code == 0 || code == 2, "case {k}: exit {code}: {e}");
        assert!(!e.contains("panicked"), "case {k}: {e}");
        assert!(
            !mpmlab::output::partial_of(&out).exists(),
            "case {k}: temporary file left"
        );
        if code == 0 {
            written += 1;
            assert!(std::fs::read(&out).unwrap().starts_with(b"RRF"), "case {k}");
            if o.contains("does not decode") {
                // The first few, and every stop that is a caught panic or
                // an abort of the decoder rather than its error.
                if stopped < 5 || !o.contains("Codec error") {
                    println!("case {k}: {o}");
                }
                stopped += 1;
                assert!(o.contains("(bytes "), "case {k}: {o}");
            }
        } else {
            refused += 1;
            assert!(!out.exists(), "case {k}: {e}: an output written");
        }
    }
    println!("written {written}, of which stopped at a damaged message {stopped}; refused {refused}");
    assert_eq!(written + refused, 360);
    assert!(written > 0 && refused > 0 && stopped > 0);
    for p in [&rec, &damaged, &out] {
        let _ = std::fs::remove_file(p);
    }
}

/// A recording whose 46th message has a damaged length on which rerun's
/// arrow decoder asks for petabytes and aborts the process (found by the
/// seeded flips above, kept as a file: the recordings differ from run to
/// run): `repair` decodes in a child process first, so it keeps the 45
/// messages before it and names the one it stopped at.
#[test]
fn a_message_that_aborts_the_decoder_ends_the_repair_there() {
    let input = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/decoder-aborts.rrd");
    let out = temp_path("rec-aborts-out", "rrd");
    let (code, o, e) = common::mpmlab(&["repair", input.to_str().unwrap(), out.to_str().unwrap()]);
    assert_eq!(code, 0, "{e}");
    assert!(
        o.contains("kept 45 messages") && o.contains("message 46 (bytes 58579..60605)") && o.contains("aborted"),
        "{o}"
    );
    assert!(std::fs::read(&out).unwrap().starts_with(b"RRF"));
    assert!(!mpmlab::output::partial_of(&out).exists());
    let _ = std::fs::remove_file(&out);
}

/// A recording whose 73rd message decodes but carries a damaged column
/// name, at odds with the other chunks of its entity: rerun's encoder
/// refuses the footer's index of such a set (the fresh-clone CI run met
/// one, exit 3 "cannot write"). `repair` finds the longest run of
/// messages that closes and names the one after it.
#[test]
fn a_message_that_spoils_the_index_ends_the_repair_there() {
    let input = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/index-inconsistent.rrd");
    let out = temp_path("rec-index-out", "rrd");
    let (code, o, e) = common::mpmlab(&["repair", input.to_str().unwrap(), out.to_str().unwrap()]);
    assert_eq!(code, 0, "{e}");
    assert!(
        o.contains("kept 72 messages")
            && o.contains("message 73 (bytes 97046..98543)")
            && o.contains("index inconsistent"),
        "{o}"
    );
    assert!(std::fs::read(&out).unwrap().starts_with(b"RRF"));
    let _ = std::fs::remove_file(&out);
}

/// The labels of an entity's Points2D, LineStrips2D or Arrows2D, over the
/// whole recording.
fn labels_of(chunks: &[rerun::log::Chunk], path: &str) -> Vec<String> {
    let labels = rerun::Points2D::descriptor_labels().component;
    let strips = rerun::LineStrips2D::descriptor_labels().component;
    let arrows = rerun::Arrows2D::descriptor_labels().component;
    chunks
        .iter()
        .filter(|c| c.entity_path().to_string() == path)
        .flat_map(|c| {
            [labels, strips, arrows]
                .into_iter()
                .flat_map(|d| {
                    c.iter_slices::<String>(d)
                        .flat_map(|l| l.iter().map(|s| s.to_string()).collect::<Vec<_>>())
                        .collect::<Vec<_>>()
                })
                .collect::<Vec<_>>()
        })
        .collect()
}

#[test]
fn conditions_loads_probes_and_warnings_are_drawn_and_named() {
    // The plate: two grid-line rollers, two probes, and Kirsch traction
    // lost on inactive nodes (1.4e3 N/m, a warning on the timeline).
    let (chunks, _, _) = record_steps("plate-hole-neumann", 1);
    let c0 = labels_of(&chunks, "/grid/conditions/0");
    assert!(c0.iter().any(|l| l.starts_with("roller x = 0: u_x = 0")), "{c0:?}");
    let c1 = labels_of(&chunks, "/grid/conditions/1");
    assert!(c1.iter().any(|l| l.starts_with("roller y = 0: u_y = 0")), "{c1:?}");
    let probes = labels_of(&chunks, "/probes");
    for p in ["probe hole_top", "probe hole_side"] {
        assert!(probes.iter().any(|l| l == p), "{probes:?}");
    }
    let events = common::event_texts(&chunks);
    assert!(
        events
            .iter()
            .any(|e| e.contains("boundary `outer` LOST") && e.contains("inactive nodes")),
        "{events:?}"
    );
    // Implicit rollers are named rollers.
    let (chunks, _, _) = record_steps("square-traction-ibm-45", 1);
    let left = labels_of(&chunks, "/ibm/left/line");
    assert!(left.iter().any(|l| l == "left (implicit roller)"), "{left:?}");
    // Gravity as a labelled arrow.
    let (chunks, _, _) = record_steps("column-small-strain", 1);
    let g = labels_of(&chunks, "/loads/gravity");
    assert!(g.iter().any(|l| l.starts_with("gravity (0, -10)")), "{g:?}");
}

#[test]
fn a_singular_condition_number_is_an_event_not_a_number() {
    // Without ghost the beam's stiffness is singular to working precision
    // at some steps (the condition estimate above 1/eps): those are
    // events; every number logged is at most 1/eps.
    let (chunks, _, _) = record_steps("elastic-beam-ghost", 20);
    let events = common::event_texts(&chunks);
    assert!(
        events
            .iter()
            .any(|e| e.contains("the stiffness without ghost is singular to working precision")),
        "{events:?}"
    );
    let scalars = rerun::Scalars::descriptor_scalars().component;
    for c in chunks
        .iter()
        .filter(|c| c.entity_path().to_string().starts_with("/metrics/condition/"))
    {
        for v in c.iter_slices::<f64>(scalars) {
            assert!(
                v.iter().all(|x| x.is_finite() && *x <= 1.0 / f64::EPSILON),
                "{}: {v:?}",
                c.entity_path()
            );
        }
    }
}
