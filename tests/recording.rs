//! A recording read back with rerun's own decoder: entity paths, number of
//! points and metric values match what the run reported.

mod common;
use common::{read_chunks, sim_with, temp_path};
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
    let child = std::process::Command::new(env!("CARGO_BIN_EXE_mpmlab"))
        .args(["run", "scenarios/ghost-collision-plastic.toml", "--quiet", "--record"])
        .arg(&path)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Let it take some steps (the scene has 1000 of about 6 ms each).
    std::thread::sleep(std::time::Duration::from_millis(1500));
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
    let _ = std::fs::remove_file(&path);
    assert!(steps.len() > 10 && steps.len() < 1001, "{} steps recorded", steps.len());
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
