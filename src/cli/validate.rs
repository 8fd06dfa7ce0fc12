//! The scenes of a sweep's runs, checked before anything is written or
//! run (`mpmlab sweep --vary`, `--target --try`).

use mpmlab::scene::Scene;
use mpmlab::Model;

/// Every run's scene must parse (every --vary key names a scene field,
/// every value has its type and range) before anything is written or run.
/// Runs whose scene then fails validation (an `h` that does not divide the
/// grid) are warned about and become failed rows, unless every run does.
pub fn validate_runs(base: &str, fixed: &[(String, String)], runs: &[mpmlab::sweep::Run]) -> Result<(), String> {
    let mut texts = Vec::new();
    for r in runs {
        let settings: Vec<String> = r.settings.iter().map(|(k, v)| format!("{k}={v}")).collect();
        let what = format!("run `{}` ({})", r.id, settings.join(" "));
        let text = mpmlab::sweep::run_scene(base, fixed, r).map_err(|e| format!("{what}: {e}"))?;
        if let Err(e) = Scene::parse(&text, &r.id) {
            return Err(format!(
                "{what} is not a valid scene: field `{}`: {}",
                e.field, e.message
            ));
        }
        texts.push((text, what));
    }
    let mut invalid = Vec::new();
    for (text, what) in &texts {
        if let Err(e) = Model::from_text(text, "run") {
            invalid.push(format!(
                "{what} is not a valid scene: field `{}`: {}",
                e.field, e.message
            ));
        }
    }
    if !invalid.is_empty() && invalid.len() == texts.len() {
        return Err(format!(
            "no run is a valid scene; the first: {}",
            invalid.swap_remove(0)
        ));
    }
    for w in invalid {
        eprintln!("warning: {w}; it will be a failed row");
    }
    Ok(())
}
