//! The paper studies as ready-made sweeps (`mpmlab sweep --preset NAME`).

use super::Vary;

/// A named sweep: a shipped scene, settings every run shares, and the
/// varied settings.
pub struct Preset {
    pub name: &'static str,
    /// Scene name in `scenarios/`.
    pub scene: &'static str,
    pub fixed: Vec<(String, String)>,
    pub vary: Vec<Vary>,
    /// What it reproduces.
    pub about: &'static str,
}

fn vary(key: &str, values: &[&str]) -> Vary {
    Vary {
        key: key.into(),
        values: values.iter().map(|v| v.to_string()).collect(),
    }
}

pub const NAMES: &[&str] = &["plate-hole-h", "delta", "beam-stability", "column-gamma"];

/// The preset of this name.
pub fn preset(name: &str) -> Option<Preset> {
    let p = match name {
        "plate-hole-h" => Preset {
            name: "plate-hole-h",
            scene: "plate-hole-neumann",
            fixed: Vec::new(),
            vary: vec![vary("h", &["0.5", "0.25", "0.125", "0.0625"])],
            about: "B Fig. 17: plate with a hole, Kirsch traction on the B-spline boundary; errors against h (rates about 2 for displacement, 1 for stress)",
        },
        "delta" => Preset {
            name: "delta",
            scene: "block-roller-30",
            fixed: Vec::new(),
            vary: vec![vary(
                "delta_over_h",
                &["1e-2", "1e-4", "1e-6", "1e-8", "1e-10", "1e-12"],
            )],
            about: "C Fig. 13 / B Fig. 9: the 30 degree block on implicit rollers; error falls with delta/h then rises, cond(K) grows as 1/delta",
        },
        "beam-stability" => Preset {
            name: "beam-stability",
            scene: "elastic-beam-ghost",
            fixed: Vec::new(),
            vary: vec![
                vary("h", &["0.5", "0.25", "0.125"]),
                vary("ppc", &["2", "3", "4", "5", "6"]),
                vary("gamma_k", &["12e6", "0"]),
            ],
            about: "G Table 5: the large-deflection GIMP cantilever with and without Ghost stiffness; which runs complete, Newton iterations",
        },
        "column-gamma" => {
            // G Table 4: h = 50/512 m; gamma_K / E from 1e-6 to 1e6 (E = 10 kPa).
            let h = "0.09765625";
            Preset {
                name: "column-gamma",
                scene: "column-self-weight",
                fixed: vec![
                    ("grid.h".into(), h.into()),
                    ("grid.size".into(), format!("[{h}, 50.0]")),
                    ("body.0.region.max".into(), format!("[{h}, 50.0]")),
                    ("dirichlet.2.x".into(), h.into()),
                ],
                vary: vec![vary("gamma_k", &["1e-2", "1", "1e2", "1e4", "1e6", "1e8", "1e10"])],
                about: "G Table 4: the finite-deformation column at h = 50/512 m; the error barely changes for gamma_K/E from 1e-6 to 1e6",
            }
        }
        _ => return None,
    };
    Some(p)
}
