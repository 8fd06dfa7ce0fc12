//! Hostile input: broken scenes of every kind are refused with exit code 2
//! and a message that names the file, line, column and field (never a
//! panic, an abort or a hang); files that are not scenes (binary,
//! non-UTF-8, a FIFO, a directory) are refused before they are read; a
//! random mutation of any shipped scene either builds or fails with a
//! located error. Also: `--record` does not overwrite what is not a
//! recording, and sweeps reject bad settings before anything runs.

use crate::common::{mpmlab, scene_path, temp_path};
use mpmlab::model::Limits;
use mpmlab::scene::Scene;
use mpmlab::Model;
use std::path::{Path, PathBuf};

/// One broken scene: how to make it and what `check` must say.
struct Case {
    name: String,
    contents: Contents,
    code: i32,
    /// A fragment of the message.
    fragment: String,
    /// The field the message must name (`field `...``), if located.
    field: Option<String>,
}

enum Contents {
    Text(String),
    Bytes(Vec<u8>),
}

/// A new empty folder for one test's files.
fn scratch(stem: &str) -> crate::common::TempPath {
    let dir = temp_path(stem, "d");
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn shipped(name: &str) -> String {
    std::fs::read_to_string(scene_path(name)).unwrap()
}

/// Shipped scene `base` with each `from` replaced (once) by its `to`.
fn edit(base: &str, edits: &[(&str, &str)]) -> String {
    let mut t = shipped(base);
    for (from, to) in edits {
        assert!(t.contains(from), "{base}: no `{from}`");
        t = t.replacen(from, to, 1);
    }
    t
}

struct Cases(Vec<Case>);

impl Cases {
    fn add(&mut self, name: &str, text: String, code: i32, fragment: &str, field: Option<&str>) {
        self.0.push(Case {
            name: name.to_string(),
            contents: Contents::Text(text),
            code,
            fragment: fragment.to_string(),
            field: field.map(str::to_string),
        });
    }

    /// The patch scene with one replacement, refused at `field`.
    fn patch(&mut self, name: &str, from: &str, to: &str, fragment: &str, field: &str) {
        self.add(name, edit("patch-compression", &[(from, to)]), 2, fragment, Some(field));
    }

    /// Any shipped scene with replacements, refused at `field`.
    fn scene(&mut self, name: &str, base: &str, edits: &[(&str, &str)], fragment: &str, field: &str) {
        self.add(name, edit(base, edits), 2, fragment, Some(field));
    }
}

const BODY: &str = "region = { shape = \"rectangle\", min = [0.25, 0.0], max = [2.25, 2.0] }";

/// The patch scene with its body's region replaced.
fn region(r: &str) -> String {
    edit("patch-compression", &[(BODY, &format!("region = {r}"))])
}

fn cases() -> Vec<Case> {
    let mut c = Cases(Vec::new());

    // --- Syntax: the line's key is the field even when the text is no TOML.
    c.patch("syntax-two-values", "h = 0.5", "h = 0.5 0.5", "", "grid.h");
    c.patch("syntax-no-value", "h = 0.5", "h =", "", "grid.h");
    c.patch("syntax-no-equals", "h = 0.5", "h 0.5", "", "grid");
    c.patch(
        "syntax-open-string",
        "name = \"block\"",
        "name = \"block",
        "",
        "body[0].name",
    );
    c.patch(
        "syntax-open-array",
        "size = [3.0, 2.5]",
        "size = [3.0, 2.5",
        "missing comma",
        "grid.size[2]",
    );
    c.patch(
        "syntax-open-inline-table",
        BODY,
        "region = { shape = \"rectangle\"",
        "",
        "body[0].region",
    );
    c.patch(
        "syntax-bad-escape",
        "name = \"block\"",
        "name = \"bl\\qock\"",
        "",
        "body[0].name",
    );
    c.patch(
        "syntax-bare-word",
        "plane = \"strain\"",
        "plane = strain",
        "",
        "material[0].plane",
    );
    c.patch("syntax-open-header", "[grid]", "[grid", "", "grid");
    c.patch(
        "syntax-duplicate-key",
        "h = 0.5",
        "h = 0.5\nh = 0.25",
        "duplicate key",
        "grid.h",
    );
    c.patch("syntax-duplicate-table", "[analysis]", "[grid]\n[analysis]", "", "grid");
    c.patch(
        "syntax-table-vs-array",
        "[[dirichlet]]\nkind = \"roller\"\nx = 0.0",
        "[dirichlet]\nkind = \"roller\"\nx = 0.0",
        "duplicate key",
        "dirichlet[0]",
    );
    c.patch("syntax-number-garbage", "E = 1.0e6", "E = 1.0e6e6", "", "material[0].E");
    c.patch("syntax-leading-dot", "nu = 0.3", "nu = .3", "", "material[0].nu");
    c.patch(
        "syntax-nul-in-string",
        "name = \"block\"",
        "name = \"bl\u{0}ock\"",
        "",
        "body[0].name",
    );
    c.patch(
        "syntax-newline-in-string",
        "name = \"block\"",
        "name = \"bl\nock\"",
        "",
        "body[0]",
    );

    // --- Types: the field inside its table, never the document.
    c.patch("type-h-string", "h = 0.5", "h = \"0.5\"", "invalid type", "grid.h");
    c.patch("type-h-bool", "h = 0.5", "h = true", "invalid type", "grid.h");
    c.patch("type-h-array", "h = 0.5", "h = [0.5]", "invalid type", "grid.h");
    c.patch(
        "type-h-table",
        "h = 0.5",
        "h = { value = 0.5 }",
        "invalid type",
        "grid.h",
    );
    c.patch("type-h-date", "h = 0.5", "h = 1979-05-27", "invalid type", "grid.h");
    c.patch(
        "type-basis-bool",
        "points_per_cell = 2",
        "points_per_cell = 2\nbasis = true",
        "wanted string",
        "body[0].basis",
    );
    c.patch(
        "type-basis-unknown",
        "points_per_cell = 2",
        "points_per_cell = 2\nbasis = \"cubic\"",
        "unknown variant",
        "body[0].basis",
    );
    c.patch(
        "type-ppc-float",
        "points_per_cell = 2",
        "points_per_cell = 2.5",
        "invalid type",
        "body[0].points_per_cell",
    );
    c.patch(
        "type-ppc-negative",
        "points_per_cell = 2",
        "points_per_cell = -1",
        "invalid value",
        "body[0].points_per_cell",
    );
    c.patch(
        "type-ppc-string",
        "points_per_cell = 2",
        "points_per_cell = \"2\"",
        "invalid type",
        "body[0].points_per_cell",
    );
    c.patch(
        "type-E-string",
        "E = 1.0e6",
        "E = \"stiff\"",
        "invalid type",
        "material[0].E",
    );
    c.patch(
        "type-nu-array",
        "nu = 0.3",
        "nu = [0.3]",
        "invalid type",
        "material[0].nu",
    );
    c.patch(
        "type-origin-short",
        "origin = [0.0, 0.0]",
        "origin = [0.0]",
        "",
        "grid.origin",
    );
    c.patch(
        "type-origin-long",
        "origin = [0.0, 0.0]",
        "origin = [0.0, 0.0, 0.0]",
        "got 3 numbers",
        "grid.origin",
    );
    c.patch(
        "type-origin-strings",
        "origin = [0.0, 0.0]",
        "origin = [\"a\", \"b\"]",
        "invalid type",
        "grid.origin[0]",
    );
    c.patch(
        "type-size-string",
        "size = [3.0, 2.5]",
        "size = \"3 x 2.5\"",
        "invalid type",
        "grid.size",
    );
    c.patch(
        "type-load-steps-float",
        "load_steps = 1",
        "load_steps = 1.5",
        "invalid type",
        "analysis.load_steps",
    );
    c.patch(
        "type-load-steps-negative",
        "load_steps = 1",
        "load_steps = -3",
        "invalid value",
        "analysis.load_steps",
    );
    c.patch(
        "type-kind-unknown",
        "load_steps = 1",
        "load_steps = 1\nkind = \"dynamic\"",
        "unknown variant",
        "analysis.kind",
    );
    c.patch(
        "type-model-unknown",
        "nu = 0.3",
        "nu = 0.3\nmodel = \"plastic\"",
        "unknown variant",
        "material[0].model",
    );
    c.patch(
        "type-plane-int",
        "plane = \"strain\"",
        "plane = 3",
        "wanted string",
        "material[0].plane",
    );
    c.patch(
        "type-placement-unknown",
        "points_per_cell = 2",
        "points_per_cell = 2\nplacement = \"random\"",
        "unknown variant",
        "body[0].placement",
    );
    c.patch("type-region-int", BODY, "region = 5", "invalid type", "body[0].region");
    c.patch(
        "type-region-shape-unknown",
        BODY,
        "region = { shape = \"hexagon\" }",
        "unknown variant",
        "body[0].region.shape",
    );
    c.patch(
        "type-region-min-string",
        BODY,
        "region = { shape = \"rectangle\", min = \"origin\", max = [2.25, 2.0] }",
        "invalid type",
        "body[0].region.min",
    );
    c.patch(
        "type-name-int",
        "name = \"block\"",
        "name = 5",
        "invalid type",
        "body[0].name",
    );
    c.patch(
        "type-gravity-string",
        "[analysis]",
        "[loads]\ngravity = \"down\"\n\n[analysis]",
        "invalid type",
        "loads.gravity",
    );
    c.patch(
        "type-tolerance-string",
        "tolerance = 1e-10",
        "tolerance = \"tight\"",
        "invalid type",
        "analysis.tolerance",
    );
    c.patch(
        "type-condition-unknown",
        "tolerance = 1e-10",
        "tolerance = 1e-10\ncondition = \"maybe\"",
        "unknown variant",
        "analysis.condition",
    );
    c.patch(
        "type-dirichlet-kind",
        "kind = \"roller\"\nx = 0.0",
        "kind = \"sticky\"\nx = 0.0",
        "unknown variant",
        "dirichlet[0].kind",
    );
    c.patch(
        "type-exact-name",
        "name = \"uniaxial-y\"",
        "name = \"parabolic\"",
        "unknown variant",
        "exact.name",
    );
    c.patch("type-scene-table", "[scene]", "scene = 1\n[scene2]", "", "scene");
    c.patch("type-body-not-array", "[[body]]", "[body]", "", "body");

    // --- Unknown keys: named where they stand.
    c.patch(
        "key-top",
        "[scene]",
        "colour = \"red\"\n[scene]",
        "unknown field",
        "colour",
    );
    c.patch(
        "key-scene",
        "name = \"patch-compression\"",
        "name = \"patch-compression\"\nauthor = \"me\"",
        "unknown field",
        "scene.author",
    );
    c.patch(
        "key-grid",
        "h = 0.5",
        "h = 0.5\ncells = 6",
        "unknown field",
        "grid.cells",
    );
    c.patch(
        "key-material",
        "nu = 0.3",
        "nu = 0.3\nyoung = 5.0",
        "unknown field",
        "material[0].young",
    );
    c.patch(
        "key-body",
        "points_per_cell = 2",
        "points_per_cell = 2\nppc = 3",
        "unknown field",
        "body[0].ppc",
    );
    c.patch(
        "key-region",
        BODY,
        "region = { shape = \"rectangle\", min = [0.25, 0.0], max = [2.25, 2.0], radius = 1.0 }",
        "unknown field",
        "body[0].region.radius",
    );
    c.patch(
        "key-dirichlet",
        "normal_displacement = -0.002",
        "normal_displacement = -0.002\nvalue = 1.0",
        "unknown field",
        "dirichlet[2].value",
    );
    c.patch(
        "key-analysis",
        "tolerance = 1e-10",
        "tolerance = 1e-10\nsolver = \"lu\"",
        "unknown field",
        "analysis.solver",
    );
    c.patch(
        "key-exact",
        "anchor = [0.0, 0.0]",
        "anchor = [0.0, 0.0]\nscale = 2.0",
        "unknown field",
        "exact.scale",
    );
    c.patch(
        "key-loads",
        "[analysis]",
        "[loads]\nwind = [1.0, 0.0]\n\n[analysis]",
        "unknown field",
        "loads.wind",
    );
    c.patch(
        "key-table",
        "[analysis]",
        "[output]\nevery = 1\n\n[analysis]",
        "unknown field",
        "output",
    );
    c.scene(
        "key-ibm",
        "rigid-footing",
        &[("moves = true", "moves = true\nspeed = 1.0")],
        "unknown field",
        "ibm[0].speed",
    );
    // The von Mises strength: the old key (read as uniaxial, it was G's
    // radius), two of the three, none, a negative one, one on an elastic
    // material.
    c.scene(
        "strength-old-key",
        "collapse-von-mises",
        &[("rho_y = 20.0e3", "yield_stress = 20.0e3")],
        "write rho_y = 2e4",
        "material[0].yield_stress",
    );
    c.scene(
        "strength-two-keys",
        "collapse-von-mises",
        &[("rho_y = 20.0e3", "rho_y = 20.0e3\nsigma_y = 1.0e4")],
        "give one of rho_y, sigma_y and c_u",
        "material[0].sigma_y",
    );
    c.scene(
        "strength-none",
        "collapse-von-mises",
        &[("rho_y = 20.0e3", "")],
        "von Mises needs its strength",
        "material[0].rho_y",
    );
    c.scene(
        "strength-negative",
        "collapse-von-mises",
        &[("rho_y = 20.0e3", "c_u = -1.0")],
        "must be positive",
        "material[0].c_u",
    );
    c.scene(
        "strength-elastic",
        "patch-compression",
        &[("nu = 0.3", "nu = 0.3\nsigma_y = 1.0e4")],
        "only for model",
        "material[0].sigma_y",
    );
    // A probe off the grid or outside every body snapped to the nearest
    // point silently.
    c.scene(
        "probe-off-grid",
        "axial-vibration-implicit",
        &[("at = [1.0, 0.025]", "at = [5.0, 0.025]")],
        "outside the grid",
        "probe[0].at",
    );
    c.scene(
        "probe-outside-bodies",
        "axial-vibration-implicit",
        &[("at = [1.0, 0.025]", "at = [1.15, 0.025]")],
        "outside every body",
        "probe[0].at",
    );
    c.scene(
        "key-boundary",
        "thick-cylinder",
        &[("layer = \"inner\"", "layer = \"inner\"\nsmooth = true")],
        "unknown field",
        "boundary[0].smooth",
    );

    // --- Missing fields: the table and the field.
    c.patch(
        "missing-grid",
        "[grid]\norigin = [0.0, 0.0]\nsize = [3.0, 2.5]\nh = 0.5\n",
        "",
        "missing field",
        "grid",
    );
    c.patch("missing-h", "h = 0.5\n", "", "missing field", "grid.h");
    c.patch("missing-E", "E = 1.0e6\n", "", "missing field", "material[0].E");
    c.patch(
        "missing-region",
        &format!("{BODY}\n"),
        "",
        "missing field",
        "body[0].region",
    );
    c.patch(
        "missing-load-steps",
        "load_steps = 1\n",
        "",
        "missing field",
        "analysis.load_steps",
    );
    c.patch(
        "missing-body-name",
        "name = \"block\"\n",
        "",
        "missing field",
        "body[0].name",
    );
    c.patch(
        "missing-region-min",
        BODY,
        "region = { shape = \"rectangle\", max = [2.25, 2.0] }",
        "missing field",
        "body[0].region.min",
    );
    c.add("empty-file", String::new(), 2, "missing field", Some("scene"));
    c.add(
        "comment-only",
        "# nothing here\n".into(),
        2,
        "missing field",
        Some("scene"),
    );

    // --- Non-finite, negative, zero and huge values.
    for (field, from, vals) in [
        ("grid.h", "h = 0.5", &["nan", "inf", "-inf"][..]),
        ("material[0].E", "E = 1.0e6", &["nan", "inf", "-inf"][..]),
        ("material[0].nu", "nu = 0.3", &["nan", "+inf"][..]),
        ("grid.origin[0]", "origin = [0.0, 0.0]", &["[nan, 0.0]"][..]),
        ("analysis.tolerance", "tolerance = 1e-10", &["nan", "inf"][..]),
    ] {
        for v in vals {
            let key = from.split(" = ").next().unwrap();
            c.patch(
                &format!("nonfinite-{field}-{v}"),
                from,
                &format!("{key} = {v}"),
                "finite",
                field,
            );
        }
    }
    for (name, from, to, fragment, field) in [
        ("h-negative", "h = 0.5", "h = -0.5", "must be positive", "grid.h"),
        ("h-zero", "h = 0.5", "h = 0.0", "must be positive", "grid.h"),
        ("h-huge", "h = 0.5", "h = 1e300", "out of range", "grid.h"),
        ("h-tiny", "h = 0.5", "h = 1e-300", "out of range", "grid.h"),
        (
            "h-fine",
            "h = 0.5",
            "h = 1e-6",
            "cells, more than the 20000000 supported",
            "grid.h",
        ),
        (
            "h-not-dividing",
            "h = 0.5",
            "h = 0.7",
            "whole number of cells",
            "grid.size",
        ),
        (
            "size-negative",
            "size = [3.0, 2.5]",
            "size = [-3.0, 2.5]",
            "whole number of cells",
            "grid.size",
        ),
        (
            "size-zero",
            "size = [3.0, 2.5]",
            "size = [0.0, 2.5]",
            "whole number of cells",
            "grid.size",
        ),
        (
            "E-negative",
            "E = 1.0e6",
            "E = -1.0e6",
            "must be positive",
            "material[0].E",
        ),
        ("E-zero", "E = 1.0e6", "E = 0.0", "must be positive", "material[0].E"),
        ("E-huge", "E = 1.0e6", "E = 1e31", "out of range", "material[0].E"),
        (
            "E-tiny",
            "E = 1.0e6",
            "E = 1e-300",
            "1.0000e-300 is out of range",
            "material[0].E",
        ),
        (
            "E-subnormal",
            "E = 1.0e6",
            "E = 5e-324",
            "out of range",
            "material[0].E",
        ),
        ("nu-half", "nu = 0.3", "nu = 0.5", "(-1, 0.5)", "material[0].nu"),
        ("nu-minus-one", "nu = 0.3", "nu = -1.0", "(-1, 0.5)", "material[0].nu"),
        ("nu-two", "nu = 0.3", "nu = 2.0", "(-1, 0.5)", "material[0].nu"),
        (
            "density-negative",
            "nu = 0.3",
            "nu = 0.3\ndensity = -1.0",
            "non-negative",
            "material[0].density",
        ),
        (
            "load-steps-zero",
            "load_steps = 1",
            "load_steps = 0",
            "between 1 and",
            "analysis.load_steps",
        ),
        (
            "load-steps-huge",
            "load_steps = 1",
            "load_steps = 2000000",
            "between 1 and",
            "analysis.load_steps",
        ),
        (
            "load-steps-i64-max",
            "load_steps = 1",
            "load_steps = 9223372036854775807",
            "between 1 and",
            "analysis.load_steps",
        ),
        (
            "load-steps-beyond-i64",
            "load_steps = 1",
            "load_steps = 99999999999999999999",
            "",
            "analysis.load_steps",
        ),
        (
            "tolerance-zero",
            "tolerance = 1e-10",
            "tolerance = 0.0",
            "(0, 1)",
            "analysis.tolerance",
        ),
        (
            "tolerance-one",
            "tolerance = 1e-10",
            "tolerance = 1.0",
            "(0, 1)",
            "analysis.tolerance",
        ),
        (
            "tolerance-negative",
            "tolerance = 1e-10",
            "tolerance = -1e-3",
            "(0, 1)",
            "analysis.tolerance",
        ),
        (
            "max-iterations-zero",
            "load_steps = 1",
            "load_steps = 1\nmax_iterations = 0",
            "between 1 and 1000",
            "analysis.max_iterations",
        ),
        (
            "max-iterations-huge",
            "load_steps = 1",
            "load_steps = 1\nmax_iterations = 4294967296",
            "between 1 and 1000",
            "analysis.max_iterations",
        ),
        (
            "max-cutbacks-huge",
            "load_steps = 1",
            "load_steps = 1\nmax_cutbacks = 64",
            "at most 20",
            "analysis.max_cutbacks",
        ),
        (
            "gamma-k-negative",
            "load_steps = 1",
            "load_steps = 1\ngamma_k = -1.0",
            "zero (off) or positive",
            "analysis.gamma_k",
        ),
        (
            "delta-over-h-zero",
            "load_steps = 1",
            "load_steps = 1\ndelta_over_h = 0.0",
            "(0, 1]",
            "analysis.delta_over_h",
        ),
        (
            "delta-over-h-two",
            "load_steps = 1",
            "load_steps = 1\ndelta_over_h = 2.0",
            "(0, 1]",
            "analysis.delta_over_h",
        ),
        (
            "delta-big",
            "load_steps = 1",
            "load_steps = 1\ndelta = 3.0",
            "(0, h]",
            "analysis.delta",
        ),
        (
            "dense-limit-huge",
            "load_steps = 1",
            "load_steps = 1\ndense_limit = 1000000000",
            "at most 20000",
            "analysis.dense_limit",
        ),
        (
            "ppc-zero",
            "points_per_cell = 2",
            "points_per_cell = 0",
            "between 1 and 64",
            "body[0].points_per_cell",
        ),
        (
            "ppc-65",
            "points_per_cell = 2",
            "points_per_cell = 65",
            "between 1 and 64",
            "body[0].points_per_cell",
        ),
        (
            "ppc-billion",
            "points_per_cell = 2",
            "points_per_cell = 1000000000",
            "between 1 and 64",
            "body[0].points_per_cell",
        ),
        (
            "dirichlet-off-grid",
            "y = 2.0",
            "y = 2.1",
            "not a grid line",
            "dirichlet[2].y",
        ),
        ("dirichlet-nan", "y = 2.0", "y = nan", "finite", "dirichlet[2].y"),
        (
            "dirichlet-far",
            "y = 2.0",
            "y = 1e29",
            "not a grid line",
            "dirichlet[2].y",
        ),
        (
            "dirichlet-both",
            "x = 0.0",
            "x = 0.0\ny = 0.0",
            "exactly one of",
            "dirichlet[0]",
        ),
        (
            "dirichlet-none",
            "kind = \"roller\"\nx = 0.0",
            "kind = \"roller\"",
            "exactly one of",
            "dirichlet[0]",
        ),
        (
            "dirichlet-roller-displacement",
            "normal_displacement = -0.002",
            "displacement = [0.0, 1.0]",
            "only for fixed",
            "dirichlet[2].displacement",
        ),
        (
            "gravity-huge",
            "[analysis]",
            "[loads]\ngravity = [0.0, -1e40]\n\n[analysis]",
            "out of range",
            "loads.gravity[1]",
        ),
        (
            "point-load-outside",
            "[analysis]",
            "[[loads.point]]\nat = [50.0, 0.0]\nforce = [1.0, 0.0]\n\n[analysis]",
            "outside the grid",
            "loads.point[0].at",
        ),
        (
            "point-load-nan",
            "[analysis]",
            "[[loads.point]]\nat = [1.0, 1.0]\nforce = [nan, 0.0]\n\n[analysis]",
            "finite",
            "loads.point[0].force[0]",
        ),
        (
            "exact-nan",
            "strain_yy = -0.001",
            "strain_yy = nan",
            "finite",
            "exact.strain_yy",
        ),
        (
            "exact-huge",
            "strain_yy = -0.001",
            "strain_yy = -1e35",
            "out of range",
            "exact.strain_yy",
        ),
        (
            "velocity-static",
            "points_per_cell = 2",
            "points_per_cell = 2\nvelocity = [1.0, 0.0]",
            "explicit-dynamics",
            "body[0].velocity",
        ),
        (
            "duration-static",
            "load_steps = 1",
            "load_steps = 1\nduration = 1.0",
            "only for kind",
            "analysis.duration",
        ),
    ] {
        c.patch(name, from, to, fragment, field);
    }
    c.scene(
        "explicit-no-duration",
        "translating-ghost",
        &[("duration = 0.5\n", "")],
        "with a duration",
        "exact.name",
    );
    c.scene(
        "explicit-no-duration-no-exact",
        "translating-ghost",
        &[("duration = 0.5\n", ""), ("[exact]\nname = \"free-motion\"", "")],
        "dynamics needs the simulated time",
        "analysis.duration",
    );
    // Implicit dynamics: its own settings, and what it shares.
    c.scene(
        "implicit-no-duration",
        "incline-slide-implicit",
        &[("duration = 0.1\n", "")],
        "dynamics needs the simulated time",
        "analysis.duration",
    );
    c.scene(
        "implicit-bossak-alpha",
        "incline-slide-implicit",
        &[(
            "kind = \"dynamic-implicit\"",
            "kind = \"dynamic-implicit\"\nintegrator = \"bossak\"\nbossak_alpha = -0.5",
        )],
        "must lie in [-1/3, 0]",
        "analysis.bossak_alpha",
    );
    c.scene(
        "implicit-integrator-typo",
        "incline-slide-implicit",
        &[(
            "kind = \"dynamic-implicit\"",
            "kind = \"dynamic-implicit\"\nintegrator = \"newmark\"",
        )],
        "unknown variant",
        "analysis.integrator",
    );
    c.scene(
        "implicit-moving-grid-support",
        "axial-vibration-implicit",
        &[(
            "kind = \"roller\"\nx = 0.0",
            "kind = \"roller\"\nx = 0.0\nnormal_displacement = 0.01",
        )],
        "implicit boundary's `displacement`",
        "dirichlet",
    );
    c.scene(
        "implicit-mode-no-length",
        "axial-vibration-implicit",
        &[("length = 1.0 }", "length = 0.0 }")],
        "positive length",
        "body[0].velocity_mode",
    );
    c.scene(
        "explicit-ibm-points-to-implicit",
        "incline-slide-implicit",
        &[("kind = \"dynamic-implicit\"", "kind = \"explicit-dynamics\"")],
        "dynamic-implicit",
        "ibm[0].kind",
    );
    c.scene(
        "explicit-zero-density",
        "translating-ghost",
        &[("density = 1.0", "density = 0.0")],
        "positive density",
        "material[0].density",
    );
    c.scene(
        "explicit-blowup-one",
        "translating-ghost",
        &[("condition_every = 50", "condition_every = 50\nblowup_factor = 1.0")],
        "must exceed 1",
        "analysis.blowup_factor",
    );

    // --- Empty and degenerate regions.
    for (name, r, fragment, field) in [
        ("rect-inverted", "{ shape = \"rectangle\", min = [2.25, 2.0], max = [0.25, 0.0] }", "must exceed `min`", "body[0].region.max"),
        ("rect-flat", "{ shape = \"rectangle\", min = [0.25, 1.0], max = [2.25, 1.0] }", "must exceed `min`", "body[0].region.max"),
        ("rect-outside", "{ shape = \"rectangle\", min = [0.25, 0.0], max = [4.25, 2.0] }", "outside the grid", "body[0].region"),
        ("rect-far-outside", "{ shape = \"rectangle\", min = [1e20, 0.0], max = [2e20, 2.0] }", "1.0000e20", "body[0].region"),
        ("rect-tiny", "{ shape = \"rectangle\", min = [0.25, 0.25], max = [0.25000000000001, 0.25000000000001] }", "empty", "body[0].region"),
        ("polygon-two", "{ shape = \"polygon\", vertices = [[0.0, 0.0], [1.0, 1.0]] }", "at least 3", "body[0].region.vertices"),
        ("polygon-empty", "{ shape = \"polygon\", vertices = [] }", "at least 3", "body[0].region.vertices"),
        ("polygon-collinear", "{ shape = \"polygon\", vertices = [[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]] }", "zero area", "body[0].region.vertices"),
        ("polygon-same-point", "{ shape = \"polygon\", vertices = [[1.0, 1.0], [1.0, 1.0], [1.0, 1.0], [1.0, 1.0]] }", "", "body[0].region.vertices"),
        ("polygon-nan", "{ shape = \"polygon\", vertices = [[0.0, 0.0], [1.0, nan], [2.0, 0.0]] }", "finite", "body[0].region.vertices[1][1]"),
        ("polygon-bowtie", "{ shape = \"polygon\", vertices = [[0.0, 0.0], [2.0, 2.0], [2.0, 0.0], [0.0, 2.0]] }", "crosses itself", "body[0].region.vertices"),
        ("polygon-star", "{ shape = \"polygon\", vertices = [[1.0, 0.0], [1.6, 2.0], [0.0, 0.8], [2.0, 0.8], [0.4, 2.0]] }", "crosses itself", "body[0].region.vertices"),
        ("polygon-figure-eight", "{ shape = \"polygon\", vertices = [[0.0, 0.0], [1.0, 1.0], [2.0, 0.0], [2.0, 2.0], [1.0, 1.0], [0.0, 2.0]] }", "touches itself at (1, 1)", "body[0].region.vertices"),
        ("polygon-crossing-edge", "{ shape = \"polygon\", vertices = [[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0], [0.0, 1.0], [2.5, 1.0]] }", "crosses itself", "body[0].region.vertices"),
        ("polygon-vertex-on-edge", "{ shape = \"polygon\", vertices = [[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [1.0, 0.0], [1.0, 2.0]] }", "touches itself", "body[0].region.vertices"),
        ("circle-zero", "{ shape = \"circle\", center = [1.0, 1.0], radius = 0.0 }", "must be positive", "body[0].region.radius"),
        ("circle-negative", "{ shape = \"circle\", center = [1.0, 1.0], radius = -1.0 }", "must be positive", "body[0].region.radius"),
        ("circle-tolerance-1e-20", "{ shape = \"circle\", center = [1.0, 1.0], radius = 0.5, tolerance = 1e-20 }", "more than 10000 chords", "body[0].region.tolerance"),
        ("circle-tolerance-zero", "{ shape = \"circle\", center = [1.0, 1.0], radius = 0.5, tolerance = 0.0 }", "must be positive", "body[0].region.tolerance"),
        ("circle-tolerance-negative", "{ shape = \"circle\", center = [1.0, 1.0], radius = 0.5, tolerance = -1.0 }", "must be positive", "body[0].region.tolerance"),
        ("circle-outside", "{ shape = \"circle\", center = [1.0, 1.0], radius = 5.0 }", "outside the grid", "body[0].region"),
        ("annulus-inverted", "{ shape = \"annulus-sector\", center = [0.0, 0.0], r_inner = 2.0, r_outer = 1.0, start_deg = 0.0, end_deg = 90.0 }", "must exceed `r_inner`", "body[0].region.r_outer"),
        ("annulus-no-sweep", "{ shape = \"annulus-sector\", center = [0.0, 0.0], r_inner = 1.0, r_outer = 2.0, start_deg = 30.0, end_deg = 30.0 }", "at most 360", "body[0].region.end_deg"),
        ("annulus-over-360", "{ shape = \"annulus-sector\", center = [0.0, 0.0], r_inner = 1.0, r_outer = 2.0, start_deg = 0.0, end_deg = 400.0 }", "at most 360", "body[0].region.end_deg"),
        ("annulus-tolerance-1e-20", "{ shape = \"annulus-sector\", center = [0.0, 0.0], r_inner = 1.0, r_outer = 2.0, start_deg = 0.0, end_deg = 90.0, tolerance = 1e-20 }", "more than 10000 chords", "body[0].region.tolerance"),
        ("annulus-tolerance-negative", "{ shape = \"annulus-sector\", center = [0.0, 0.0], r_inner = 1.0, r_outer = 2.0, start_deg = 0.0, end_deg = 90.0, tolerance = -0.1 }", "must be positive", "body[0].region.tolerance"),
        ("spline-two-points", "{ shape = \"spline\", points = [[0.5, 0.5], [1.5, 1.5]] }", "", "body[0].region.points"),
        ("spline-repeated-point", "{ shape = \"spline\", points = [[0.5, 0.5], [0.5, 0.5], [1.5, 1.5], [0.5, 1.5]] }", "", "body[0].region.points"),
        ("spline-all-same", "{ shape = \"spline\", points = [[1.0, 1.0], [1.0, 1.0], [1.0, 1.0]] }", "", "body[0].region.points"),
        ("spline-corner-out-of-range", "{ shape = \"spline\", points = [[0.5, 0.5], [1.5, 0.5], [1.0, 1.5]], corners = [7] }", "no point 7", "body[0].region.corners"),
        ("spline-per-segment-zero", "{ shape = \"spline\", points = [[0.5, 0.5], [1.5, 0.5], [1.0, 1.5]], per_segment = 0 }", "between 1 and 1024", "body[0].region.per_segment"),
        ("spline-per-segment-1e9", "{ shape = \"spline\", points = [[0.5, 0.5], [1.5, 0.5], [1.0, 1.5]], per_segment = 1000000000 }", "between 1 and 1024", "body[0].region.per_segment"),
        ("spline-too-many-vertices", "{ shape = \"spline\", points = [[0.5, 0.5], [1.5, 0.5], [1.5, 1.0], [1.0, 1.5], [0.5, 1.0], [0.6, 0.7], [0.7, 0.6], [0.8, 0.55], [0.9, 0.52], [1.0, 0.51]], per_segment = 1024 }", "more than the 10000", "body[0].region.per_segment"),
        ("spline-self-crossing", "{ shape = \"spline\", points = [[0.5, 0.5], [1.5, 1.5], [1.5, 0.5], [0.5, 1.5]], corners = [0, 1, 2, 3] }", "itself", "body[0].region.vertices"),
        ("union-empty", "{ shape = \"union\", parts = [] }", "at least one part", "body[0].region.parts"),
        ("union-bad-part", "{ shape = \"union\", parts = [{ shape = \"rectangle\", min = [0.0, 0.0], max = [1.0, 1.0] }, { shape = \"circle\", center = [1.0, 1.0], radius = -1.0 }] }", "must be positive", "body[0].region.parts[1].radius"),
        ("difference-everything", "{ shape = \"difference\", base = { shape = \"rectangle\", min = [0.5, 0.5], max = [1.5, 1.5] }, subtract = [{ shape = \"rectangle\", min = [0.0, 0.0], max = [2.0, 2.0] }] }", "empty", "body[0].region"),
        ("rotated-nan", "{ shape = \"rotated\", angle_deg = nan, about = [0.0, 0.0], region = { shape = \"rectangle\", min = [0.5, 0.5], max = [1.5, 1.5] } }", "finite", "body[0].region.angle_deg"),
        ("rotated-out", "{ shape = \"rotated\", angle_deg = 180.0, about = [0.0, 0.0], region = { shape = \"rectangle\", min = [0.5, 0.5], max = [1.5, 1.5] } }", "outside the grid", "body[0].region"),
        ("ghost-zero", "{ shape = \"ghost\", min = [0.5, 0.5], size = 0.0 }", "must be positive", "body[0].region.size"),
    ] {
        c.add(&format!("region-{name}"), region(r), 2, fragment, Some(field));
    }
    // A union of many overlapping parts would expand to 2^n pieces.
    let parts: Vec<String> = (0..40)
        .map(|k| format!("{{ shape = \"rectangle\", min = [0.{k:02}, 0.0], max = [2.0, 2.0] }}"))
        .collect();
    c.add(
        "region-union-explosion",
        region(&format!("{{ shape = \"union\", parts = [{}] }}", parts.join(", "))),
        2,
        "more than the 20000 supported",
        Some("body[0].region.parts[14]"),
    );
    let many: Vec<String> = (0..20_001)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / 20_001.0;
            format!("[{:.9}, {:.9}]", 1.0 + 0.5 * a.cos(), 1.0 + 0.5 * a.sin())
        })
        .collect();
    c.add(
        "region-polygon-20001-vertices",
        region(&format!("{{ shape = \"polygon\", vertices = [{}] }}", many.join(", "))),
        2,
        "more than the 10000 a polygon may have",
        Some("body[0].region.vertices"),
    );

    // --- Counts that overflow or exhaust memory.
    let polar = |nr: &str, nc: &str| {
        edit(
            "thick-cylinder",
            &[
                ("radial_points = 16", &format!("radial_points = {nr}")),
                ("circumferential_points = 32", &format!("circumferential_points = {nc}")),
            ],
        )
    };
    c.add(
        "polar-2^32-each",
        polar("4294967296", "4294967296"),
        2,
        "more than the 10000000",
        Some("body[0].radial_points"),
    );
    c.add(
        "polar-2^32-by-2",
        polar("4294967296", "2"),
        2,
        "more than the 10000000",
        Some("body[0].radial_points"),
    );
    c.add(
        "polar-one",
        polar("1", "32"),
        2,
        "at least 2",
        Some("body[0].radial_points"),
    );
    c.add(
        "polar-usize-max",
        polar("9223372036854775807", "9223372036854775807"),
        2,
        "more than the 10000000",
        Some("body[0].radial_points"),
    );
    c.scene(
        "polar-on-rectangle",
        "patch-compression",
        &[(
            "points_per_cell = 2",
            "points_per_cell = 2\nplacement = \"polar\"\nradial_points = 4\ncircumferential_points = 4",
        )],
        "annulus-sector",
        "body[0].region",
    );
    let lattice = |v: &str| {
        edit(
            "translating-ghost",
            &[("lattice = [31, 31]", &format!("lattice = {v}"))],
        )
    };
    c.add(
        "lattice-2^32-squared-ghost",
        lattice("[4294967296, 4294967296]"),
        2,
        "more than the 10000000",
        Some("body[0].lattice"),
    );
    c.add(
        "lattice-2^32-by-1-ghost",
        lattice("[4294967296, 1]"),
        2,
        "more than the 10000000",
        Some("body[0].lattice"),
    );
    c.add(
        "lattice-zero",
        lattice("[0, 31]"),
        2,
        "positive",
        Some("body[0].lattice"),
    );
    c.add("lattice-one-d", lattice("[31]"), 2, "", Some("body[0].lattice"));
    c.add(
        "lattice-negative",
        lattice("[-31, 31]"),
        2,
        "invalid value",
        Some("body[0].lattice[0]"),
    );
    c.scene(
        "lattice-missing",
        "translating-ghost",
        &[("lattice = [31, 31]\n", "")],
        "needs `lattice",
        "body[0].lattice",
    );
    let rect_lattice = |v: &str| {
        edit(
            "patch-compression",
            &[(
                "points_per_cell = 2",
                &format!("points_per_cell = 2\nplacement = \"lattice\"\nlattice = {v}"),
            )],
        )
    };
    c.add(
        "lattice-2^32-squared-rect",
        rect_lattice("[4294967296, 4294967296]"),
        2,
        "more than the 10000000",
        Some("body[0].lattice"),
    );
    c.add(
        "lattice-1e7-plus",
        rect_lattice("[10000001, 1]"),
        2,
        "more than the 10000000",
        Some("body[0].lattice"),
    );
    c.add(
        "ppc-64-fine-grid",
        edit(
            "patch-compression",
            &[("h = 0.5", "h = 0.01"), ("points_per_cell = 2", "points_per_cell = 64")],
        ),
        2,
        "more than the 10000000",
        Some("body[0].points_per_cell"),
    );
    c.scene(
        "ibm-point-1e300",
        "rigid-footing",
        &[(
            "points = [[1.8, 3.0], [1.2, 3.0]]",
            "points = [[1e300, 3.0], [1.2, 3.0]]",
        )],
        "out of range",
        "ibm[0].points[0][0]",
    );
    c.scene(
        "ibm-outside-grid",
        "rigid-footing",
        &[(
            "points = [[1.8, 3.0], [1.2, 3.0]]",
            "points = [[10.0, 3.0], [1.2, 3.0]]",
        )],
        "outside the grid",
        "ibm[0].points",
    );
    c.scene(
        "ibm-below-grid",
        "rigid-footing",
        &[(
            "points = [[1.8, 3.0], [1.2, 3.0]]",
            "points = [[1.8, -3.0], [1.2, -3.0]]",
        )],
        "outside the grid",
        "ibm[0].points",
    );
    c.scene(
        "ibm-one-point",
        "rigid-footing",
        &[("points = [[1.8, 3.0], [1.2, 3.0]]", "points = [[1.8, 3.0]]")],
        "at least 2",
        "ibm[0].points",
    );
    c.scene(
        "ibm-coincide",
        "rigid-footing",
        &[("points = [[1.8, 3.0], [1.2, 3.0]]", "points = [[1.8, 3.0], [1.8, 3.0]]")],
        "coincide",
        "ibm[0].points",
    );
    c.scene(
        "ibm-no-geometry",
        "rigid-footing",
        &[("points = [[1.8, 3.0], [1.2, 3.0]]\n", "")],
        "exactly one of",
        "ibm[0]",
    );
    c.scene(
        "ibm-gauss-zero",
        "rigid-footing",
        &[("moves = true", "moves = true\ngauss_points = 0")],
        "between 1 and 20",
        "ibm[0].gauss_points",
    );
    c.scene(
        "ibm-regularisation",
        "rigid-footing",
        &[("moves = true", "moves = true\nfit_regularisation = 2.0")],
        "[0, 1)",
        "ibm[0].fit_regularisation",
    );
    c.scene(
        "ibm-boundary-unknown",
        "rigid-footing",
        &[("points = [[1.8, 3.0], [1.2, 3.0]]", "boundary = \"nowhere\"")],
        "no [[boundary]]",
        "ibm[0].boundary",
    );

    // --- Names.
    let second_body = "\n[[body]]\nname = \"block\"\nmaterial = \"elastic\"\npoints_per_cell = 2\nregion = { shape = \"rectangle\", min = [2.5, 0.0], max = [3.0, 0.5] }\n";
    c.patch(
        "name-duplicate-body",
        "[[dirichlet]]",
        &format!("{second_body}\n[[dirichlet]]"),
        "already used by body[0]",
        "body[1].name",
    );
    c.patch(
        "name-body-like-material",
        "name = \"block\"",
        "name = \"elastic\"",
        "already used by material[0]",
        "body[0].name",
    );
    c.patch(
        "name-duplicate-material",
        "[[body]]",
        "[[material]]\nname = \"elastic\"\nE = 2.0e6\nnu = 0.3\n\n[[body]]",
        "already used by material[0]",
        "material[1].name",
    );
    c.scene(
        "name-duplicate-ibm",
        "rigid-footing",
        &[(
            "[[dirichlet]]",
            "[[ibm]]\nname = \"footing\"\nkind = \"roller\"\npoints = [[0.0, 3.4], [3.0, 3.4]]\n\n[[dirichlet]]",
        )],
        "already used by ibm[0]",
        "ibm[1].name",
    );
    c.scene(
        "name-ibm-like-body",
        "rigid-footing",
        &[("name = \"footing\"", "name = \"block\"")],
        "already used by body[0]",
        "ibm[0].name",
    );
    c.scene(
        "name-duplicate-boundary",
        "thick-cylinder",
        &[("name = \"outer\"", "name = \"inner\"")],
        "already used by boundary[0]",
        "boundary[1].name",
    );
    c.patch(
        "name-empty",
        "name = \"block\"",
        "name = \"\"",
        "must not be empty",
        "body[0].name",
    );
    c.patch(
        "name-blank",
        "name = \"block\"",
        "name = \"   \"",
        "must not be empty",
        "body[0].name",
    );
    c.patch(
        "name-slash",
        "name = \"block\"",
        "name = \"a/b\"",
        "must not contain",
        "body[0].name",
    );
    c.patch(
        "name-control",
        "name = \"block\"",
        "name = \"a\\u0007b\"",
        "must not contain",
        "body[0].name",
    );
    c.patch(
        "name-long",
        "name = \"block\"",
        &format!("name = \"{}\"", "x".repeat(300)),
        "at most 100",
        "body[0].name",
    );
    c.patch(
        "scene-name-traversal",
        "name = \"patch-compression\"",
        "name = \"../../etc/passwd\"",
        "must not contain",
        "scene.name",
    );
    c.patch(
        "scene-name-dot",
        "name = \"patch-compression\"",
        "name = \".hidden\"",
        "must not start with",
        "scene.name",
    );
    c.patch(
        "material-unknown",
        "material = \"elastic\"",
        "material = \"steel\"",
        "no material named",
        "body[0].material",
    );
    c.scene(
        "boundary-body-unknown",
        "thick-cylinder",
        &[("body = \"cylinder\"", "body = \"nobody\"")],
        "no body named",
        "boundary[0].body",
    );
    c.scene(
        "boundary-layer-and-points",
        "thick-cylinder",
        &[(
            "layer = \"inner\"",
            "layer = \"inner\"\npoints = [[1.0, 0.0], [0.0, 1.0], [0.7, 0.7]]",
        )],
        "exactly one of",
        "boundary[0]",
    );
    c.scene(
        "boundary-gauss-zero",
        "thick-cylinder",
        &[("gauss_points = 3", "gauss_points = 0")],
        "between 1 and 20",
        "boundary[0].gauss_points",
    );
    c.scene(
        "boundary-no-center",
        "thick-cylinder",
        &[("layer = \"inner\"\ncenter = [0.0, 0.0]", "layer = \"inner\"")],
        "need a `center`",
        "boundary[0].center",
    );
    c.scene(
        "boundary-traction-nan",
        "thick-cylinder",
        &[("value = 756000.0", "value = nan")],
        "finite",
        "boundary[0].traction.value",
    );

    // --- Binary and non-UTF-8 bytes: located at the first bad byte.
    let latin1 = |from: &str, to: &[u8]| {
        let t = shipped("patch-compression");
        let at = t.find(from).unwrap() + from.len();
        let mut b = t.into_bytes();
        b.splice(at..at, to.iter().copied());
        b
    };
    for (name, bytes, fragment, field) in [
        (
            "bytes-utf16",
            b"\xff\xfe[\x00s\x00c\x00".to_vec(),
            "not UTF-8",
            "(top level)",
        ),
        (
            "bytes-gzip",
            b"\x1f\x8b\x08\x00\x00\x00\x00\x00\x00\x03".to_vec(),
            "",
            "(top level)",
        ),
        (
            "bytes-latin1-in-value",
            latin1("name = \"bl", b"\xe9"),
            "byte 0xE9",
            "body[0].name",
        ),
        (
            "bytes-latin1-in-comment",
            latin1("h = 0.5", b" # caf\xe9"),
            "not UTF-8",
            "grid.h",
        ),
        (
            "bytes-truncated-utf8",
            latin1("nu = 0.3", b" # \xe2\x82"),
            "not UTF-8",
            "material[0].nu",
        ),
        (
            "bytes-elf",
            b"\x7fELF\x02\x01\x01\x00\x00\x00\x00\x00\x00\x00\x00\x00\x02\x00>\x00".to_vec(),
            "",
            "(top level)",
        ),
    ] {
        c.0.push(Case {
            name: name.into(),
            contents: Contents::Bytes(bytes),
            code: 2,
            fragment: fragment.into(),
            field: Some(field.into()),
        });
    }

    // Too many entries: bounded before anything quadratic in them runs.
    let mats: String = (0..1001)
        .map(|k| format!("[[material]]\nname = \"m{k}\"\nE = 1.0e6\nnu = 0.3\n\n"))
        .collect();
    c.patch(
        "entries-1001-materials",
        "[[body]]",
        &format!("{mats}[[body]]"),
        "more than the 1000 supported",
        "material[1000]",
    );
    // --- [record]: the cadence and the fields, located.
    let rec = |body: &str| format!("[record]\n{body}\n\n[analysis]");
    for (name, base, body, fragment, field) in [
        (
            "record-every-zero",
            "patch-compression",
            "every = 0",
            "between 1 and",
            "record.every",
        ),
        (
            "record-every-negative",
            "patch-compression",
            "every = -3",
            "",
            "record.every",
        ),
        (
            "record-dt-quasi-static",
            "patch-compression",
            "dt = 0.1",
            "explicit-dynamics",
            "record.dt",
        ),
        (
            "record-dt-negative",
            "ghost-collision-elastic",
            "dt = -0.5",
            "positive",
            "record.dt",
        ),
        (
            "record-dt-nan",
            "ghost-collision-elastic",
            "dt = nan",
            "finite",
            "record.dt",
        ),
        (
            "record-every-and-dt",
            "ghost-collision-elastic",
            "every = 2\ndt = 0.1",
            "not both",
            "record.dt",
        ),
        (
            "record-unknown-field",
            "patch-compression",
            "fields = [\"sigma_yy\", \"colour\"]",
            "unknown field `colour`",
            "record.fields",
        ),
        (
            "record-fields-number",
            "patch-compression",
            "fields = 3",
            "",
            "record.fields",
        ),
        (
            "record-unknown-key",
            "patch-compression",
            "evry = 2",
            "unknown field",
            "record.evry",
        ),
    ] {
        c.scene(name, base, &[("[analysis]", &rec(body))], fragment, field);
    }

    let loads: String = (0..10_001)
        .map(|_| "[[loads.point]]\nat = [1.0, 1.0]\nforce = [0.0, -1.0]\n".to_string())
        .collect();
    c.patch(
        "entries-10001-point-loads",
        "[analysis]",
        &format!("{loads}\n[analysis]"),
        "more than the 10000 supported",
        "loads.point",
    );

    c.0
}

/// Write each case's file; run `check` on every one, a few at a time.
fn check_all(cases: &[Case], dir: &Path) -> Vec<(PathBuf, i32, String)> {
    let paths: Vec<PathBuf> = cases
        .iter()
        .map(|c| {
            let p = dir.join(format!("{}.toml", c.name.replace(['/', '[', ']', '^'], "_")));
            match &c.contents {
                Contents::Text(t) => std::fs::write(&p, t).unwrap(),
                Contents::Bytes(b) => std::fs::write(&p, b).unwrap(),
            }
            p
        })
        .collect();
    let next = std::sync::atomic::AtomicUsize::new(0);
    let out = std::sync::Mutex::new(vec![None; paths.len()]);
    std::thread::scope(|s| {
        for _ in 0..4 {
            s.spawn(|| loop {
                let k = next.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
                let Some(p) = paths.get(k) else { break };
                let (code, _, err) = mpmlab(&["check", "--max-memory", "2G", p.to_str().unwrap()]);
                out.lock().unwrap()[k] = Some((p.clone(), code, err));
            });
        }
    });
    out.into_inner().unwrap().into_iter().map(Option::unwrap).collect()
}

/// What every refusal must look like: the code, the fragment, the field,
/// `file:line:column:` before it, no panic and no `(document)`.
fn verdict(c: &Case, path: &Path, code: i32, err: &str) -> Option<String> {
    let mut wrong = Vec::new();
    if code != c.code {
        wrong.push(format!("exit {code}, expected {}", c.code));
    }
    if !err.contains(&c.fragment) {
        wrong.push(format!("no `{}`", c.fragment));
    }
    if let Some(f) = &c.field {
        if !err.contains(&format!("field `{f}`")) {
            wrong.push(format!("no field `{f}`"));
        }
        let located = format!("{}:", path.display());
        let rest = err.split(&located).nth(1).unwrap_or("");
        let mut nums = rest.splitn(3, ':');
        let (l, col) = (nums.next().unwrap_or(""), nums.next().unwrap_or(""));
        if !(l.parse::<usize>().is_ok_and(|l| l >= 1) && col.parse::<usize>().is_ok_and(|c| c >= 1)) {
            wrong.push("no file:line:column".into());
        }
    }
    if err.contains("(document)") || err.contains("panicked") || err.contains("RUST_BACKTRACE") {
        wrong.push("a panic or an unlocated field".into());
    }
    if err.contains("18446744073709551615") || err.contains("000000000000000000000") {
        wrong.push("an unreadable number".into());
    }
    (!wrong.is_empty()).then(|| format!("{}: {}\n    {}", c.name, wrong.join("; "), err.trim()))
}

#[test]
fn broken_scenes_are_refused_with_located_messages() {
    let cases = cases();
    assert!(cases.len() >= 150, "{} cases", cases.len());
    eprintln!("{} broken scenes", cases.len());
    let dir = scratch("hostile");
    let results = check_all(&cases, &dir);
    let failures: Vec<String> = cases
        .iter()
        .zip(&results)
        .filter_map(|(c, (p, code, err))| verdict(c, p, *code, err))
        .collect();
    assert!(
        failures.is_empty(),
        "{} of {} cases wrong:\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n")
    );
    // `run` refuses the same scenes the same way (a sample of each kind).
    for (c, (p, _, check_err)) in cases.iter().zip(&results).step_by(9) {
        let (code, _, err) = mpmlab(&["run", "--quiet", "--max-memory", "2G", p.to_str().unwrap()]);
        assert_eq!(code, c.code, "{}: {err}", c.name);
        assert_eq!(err, *check_err, "{}", c.name);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_lattice_of_nine_million_points_is_refused_by_its_memory_estimate() {
    let dir = scratch("hostile-memory");
    let p = dir.join("lattice.toml");
    let text = edit(
        "patch-compression",
        &[(
            "points_per_cell = 2",
            "points_per_cell = 2\nplacement = \"lattice\"\nlattice = [3000, 3000]",
        )],
    );
    std::fs::write(&p, &text).unwrap();
    for cmd in ["check", "run"] {
        let (code, _, err) = mpmlab(&[cmd, "--max-memory", "4G", p.to_str().unwrap()]);
        assert_eq!(code, 2, "{err}");
        assert!(
            err.contains("field `body[0].lattice`")
                && err.contains("estimated 9.2 GB")
                && err.contains("9000000 points")
                && err.contains("more than the 4.3 GB allowed")
                && err.contains("coarser lattice"),
            "{err}"
        );
    }
    // A fine grid: the grid h is the field to change.
    let fine = edit(
        "patch-compression",
        &[("h = 0.5", "h = 0.005"), ("points_per_cell = 2", "points_per_cell = 1")],
    );
    std::fs::write(&p, fine).unwrap();
    let (code, _, err) = mpmlab(&["check", "--max-memory", "100M", p.to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("field `grid.h`") && err.contains("larger grid h"), "{err}");
    // Dense eigenvalues of many unknowns: the condition setting.
    let dense = edit(
        "patch-compression",
        &[
            ("h = 0.5", "h = 0.01"),
            ("tolerance = 1e-10", "tolerance = 1e-10\ncondition = \"dense\""),
        ],
    );
    std::fs::write(&p, dense).unwrap();
    let (code, _, err) = mpmlab(&["check", "--max-memory", "4G", p.to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("field `analysis.condition`") && err.contains("lanczos"),
        "{err}"
    );
    // The option itself: bad sizes are argument errors.
    for bad in ["lots", "-1G", "0", "12X"] {
        let arg = format!("--max-memory={bad}");
        let (code, _, err) = mpmlab(&["check", &arg, "scenarios/patch-compression.toml"]);
        assert_eq!(code, 2, "{bad}: {err}");
        assert!(err.contains("--max-memory"), "{err}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn files_that_are_not_scenes_are_refused_before_reading() {
    let dir = scratch("hostile-files");
    let run = |p: &Path| mpmlab(&["check", p.to_str().unwrap()]);

    // Binary garbage with invalid UTF-8: located at its first bad byte.
    let bin = dir.join("binary.toml");
    let mut bytes: Vec<u8> = (0..4096u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    bytes[0] = 0xff;
    std::fs::write(&bin, &bytes).unwrap();
    let (code, _, err) = run(&bin);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("not UTF-8") && err.contains(":1:1:") && err.contains("0xFF"),
        "{err}"
    );

    // Latin-1 in a comment on line 12 of an otherwise good scene.
    let latin = dir.join("latin1.toml");
    let text = shipped("patch-compression").replacen("h = 0.5", "h = 0.5 # \u{0}", 1);
    let mut b = text.into_bytes();
    let at = b.iter().position(|&x| x == 0).unwrap();
    b[at] = 0xe9; // é in Latin-1
    std::fs::write(&latin, &b).unwrap();
    let (code, _, err) = run(&latin);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains(":14:") && err.contains("field `grid.h`") && err.contains("not UTF-8"),
        "{err}"
    );

    // Valid UTF-8 but binary (NUL bytes): a located syntax error.
    let nul = dir.join("nul.toml");
    std::fs::write(&nul, b"[scene]\nname = \"x\"\n\0\0\0\0").unwrap();
    let (code, _, err) = run(&nul);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains(":3:") && err.contains("field `scene`"), "{err}");

    // A FIFO would block a reader forever (no writer ever comes): that
    // the run returns at all, with the FIFO named, shows it was refused
    // without being opened.
    let fifo = dir.join("fifo.toml");
    let made = std::process::Command::new("mkfifo").arg(&fifo).status().unwrap();
    assert!(made.success());
    let (code, _, err) = run(&fifo);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("not a regular file (a FIFO)"), "{err}");
    // `run` too, and `list` does not hang on it.
    let (code, _, _) = mpmlab(&["run", fifo.to_str().unwrap()]);
    assert_eq!(code, 2);
    let (code, out, _) = mpmlab(&["list", dir.to_str().unwrap()]);
    assert_eq!(code, 0);
    assert!(out.contains("not a regular file"), "{out}");
    // `repair` of a FIFO blocked for ever opening it.
    let (code, _, err) = mpmlab(&["repair", fifo.to_str().unwrap(), dir.join("out.rrd").to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("not a regular file"), "{err}");

    // A directory, a device, a missing file, an oversized file.
    let (code, _, err) = run(&dir);
    assert_eq!(code, 2);
    assert!(err.contains("is a directory"), "{err}");
    let (code, _, err) = run(Path::new("/dev/zero"));
    assert_eq!(code, 2);
    assert!(err.contains("character device"), "{err}");
    let (code, _, err) = run(&dir.join("missing.toml"));
    assert_eq!(code, 2);
    assert!(err.contains("no such file"), "{err}");
    let big = dir.join("big.toml");
    std::fs::write(&big, "#".repeat(5 << 20)).unwrap();
    let (code, _, err) = run(&big);
    assert_eq!(code, 2);
    assert!(err.contains("limited to 4194304 bytes"), "{err}");

    // A checkpoint to resume from is read the same way: a FIFO, a device
    // (`/dev/zero` never ends) and a directory are refused before they
    // are opened; a file larger than the run's memory budget is refused
    // by its size.
    let scene = "scenarios/patch-compression.toml";
    for (ck, why) in [
        (fifo.to_str().unwrap(), "not a regular file (a FIFO)"),
        ("/dev/zero", "not a regular file (a character device)"),
        (dir.to_str().unwrap(), "is a directory"),
    ] {
        let (code, _, err) = mpmlab(&["run", scene, "--resume", ck]);
        assert_eq!(code, 2, "{ck}: {err}");
        assert!(
            err.contains(&format!("cannot read checkpoint {ck}")) && err.contains(why),
            "{ck}: {err}"
        );
    }
    // (The patch needs about 17 MB by its estimate; 20 MB lets it build.)
    let huge = dir.join("huge.ckpt");
    std::fs::write(&huge, vec![b'#'; 21 << 20]).unwrap();
    let (code, _, err) = mpmlab(&["run", scene, "--resume", huge.to_str().unwrap(), "--max-memory", "20M"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("larger than the run's memory budget"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn record_does_not_overwrite_what_is_not_a_recording() {
    let dir = scratch("hostile-record");
    let scene = dir.join("s.toml");
    let text = shipped("patch-compression");
    std::fs::write(&scene, &text).unwrap();
    let s = scene.to_str().unwrap();

    // The scene itself: refused, untouched, even under another spelling.
    let (code, _, err) = mpmlab(&["run", s, "--record", s]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("is the scene file itself"), "{err}");
    let other = format!("{}/./s.toml", dir.display());
    let (code, _, _) = mpmlab(&["run", s, "--record", &other]);
    assert_eq!(code, 2);
    assert_eq!(std::fs::read_to_string(&scene).unwrap(), text);

    // Another existing file that is not a recording: refused, untouched.
    let notes = dir.join("notes.rrd");
    std::fs::write(&notes, "my notes").unwrap();
    let (code, _, err) = mpmlab(&["run", s, "--quiet", "--record", notes.to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("not a rerun recording") && err.contains("--force"),
        "{err}"
    );
    assert_eq!(std::fs::read_to_string(&notes).unwrap(), "my notes");

    // A recording is replaced; it starts with rerun's magic bytes.
    let rrd = dir.join("run.rrd");
    for _ in 0..2 {
        let (code, _, err) = mpmlab(&["run", s, "--quiet", "--record", rrd.to_str().unwrap()]);
        assert_eq!(code, 0, "{err}");
    }
    let head = std::fs::read(&rrd).unwrap();
    assert_eq!(&head[..3], b"RRF");

    // --force replaces anything but still needs a path.
    let (code, _, err) = mpmlab(&["run", s, "--quiet", "--force", "--record", notes.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(&std::fs::read(&notes).unwrap()[..3], b"RRF");

    // A directory, and a path without permission, name the cause and path.
    let (code, _, err) = mpmlab(&["run", s, "--quiet", "--record", dir.to_str().unwrap()]);
    assert_eq!(code, 2);
    assert!(err.contains("is a directory"), "{err}");
    let (code, _, err) = mpmlab(&["run", s, "--quiet", "--record", "/proc/version"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("/proc/version"), "{err}");
    // A device is never replaced, --force or not (it used to be replaced
    // by a regular file through the temporary file's rename).
    for force in [false, true] {
        let mut args = vec!["run", s, "--quiet", "--record", "/dev/full"];
        if force {
            args.push("--force");
        }
        let (code, _, err) = mpmlab(&args);
        assert_eq!(code, 2, "{err}");
        assert!(err.contains("/dev/full") && err.contains("a device"), "{err}");
    }
    assert!(!std::path::Path::new("/dev/full").is_file());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn outputs_never_replace_the_scene_and_clash_by_identity() {
    let dir = scratch("hostile-identity");
    let scene = dir.join("s.toml");
    let text = shipped("patch-compression");
    std::fs::write(&scene, &text).unwrap();
    std::os::unix::fs::symlink(&scene, dir.join("link.rrd")).unwrap();
    std::fs::hard_link(&scene, dir.join("hard.csv")).unwrap();
    let s = scene.to_str().unwrap();
    // The scene, through its own name, a symlink and a hard link: refused
    // with --force too, and untouched.
    for (flag, target) in [("--record", "s.toml"), ("--record", "link.rrd"), ("--csv", "hard.csv")] {
        let t = dir.join(target);
        let (code, _, err) = mpmlab(&["run", s, "--quiet", "--force", flag, t.to_str().unwrap()]);
        assert_eq!(code, 2, "{flag} {target}: {err}");
        assert!(err.contains("is the scene file itself"), "{err}");
        assert_eq!(std::fs::read_to_string(&scene).unwrap(), text);
    }
    // The recording and the table named one file by two spellings.
    let rrd = dir.join("out.rrd");
    let (code, _, err) = mpmlab(&[
        "run",
        s,
        "--quiet",
        "--record",
        rrd.to_str().unwrap(),
        "--csv",
        &format!("{}/./out.rrd", dir.display()),
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("name the same file"), "{err}");
    assert!(!rrd.exists());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_run_that_cannot_start_leaves_the_old_outputs_as_they_were() {
    let dir = scratch("hostile-keep");
    let scene = dir.join("s.toml");
    std::fs::write(&scene, shipped("patch-compression")).unwrap();
    let s = scene.to_str().unwrap();
    let (rrd, csv) = (dir.join("run.rrd"), dir.join("run.csv"));
    let (r, c) = (rrd.to_str().unwrap(), csv.to_str().unwrap());
    let (code, _, err) = mpmlab(&["run", s, "--quiet", "--record", r, "--csv", c]);
    assert_eq!(code, 0, "{err}");
    let (old_rrd, old_csv) = (std::fs::read(&rrd).unwrap(), std::fs::read(&csv).unwrap());
    // The ParaView series cannot be created: the run ends before its
    // first step (it used to have truncated both files by then).
    let (code, _, err) = mpmlab(&[
        "run",
        s,
        "--quiet",
        "--record",
        r,
        "--csv",
        c,
        "--vtk",
        "/proc/mpmlab-no",
    ]);
    assert_eq!(code, 3, "{err}");
    assert_eq!(std::fs::read(&rrd).unwrap(), old_rrd);
    assert_eq!(std::fs::read(&csv).unwrap(), old_csv);
    let leftovers: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".partial"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
    // A `.partial` left by a run that did not finish is kept unless
    // --force: it may be the only copy of a long run's recording.
    let partial = dir.join("run.rrd.partial");
    std::fs::write(&partial, b"RRF2 cut short").unwrap();
    let (code, _, err) = mpmlab(&["run", s, "--quiet", "--record", r]);
    assert_eq!(code, 3, "{err}");
    assert!(
        err.contains("left from a run") && err.contains("mpmlab repair"),
        "{err}"
    );
    assert_eq!(std::fs::read(&partial).unwrap(), b"RRF2 cut short");
    assert_eq!(std::fs::read(&rrd).unwrap(), old_rrd);
    let (code, _, err) = mpmlab(&["run", s, "--quiet", "--record", r, "--force"]);
    assert_eq!(code, 0, "{err}");
    assert!(!partial.exists());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_second_run_writing_the_same_recording_is_refused() {
    let dir = scratch("hostile-two-writers");
    let rrd = dir.join("run.rrd");
    let bin = env!("CARGO_BIN_EXE_mpmlab");
    // The first run is long enough to be running when the second starts:
    // it prints its first step once its recording is open and locked.
    let mut first = std::process::Command::new(bin)
        .args(["run", "scenarios/ghost-collision-plastic.toml", "--record"])
        .arg(&rrd)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let mut lines = std::io::BufRead::lines(std::io::BufReader::new(first.stdout.take().unwrap()));
    assert!(
        lines.any(|l| l.unwrap().trim_start().starts_with('1')),
        "the first run prints step 1"
    );
    let (code, _, err) = mpmlab(&[
        "run",
        "scenarios/patch-compression.toml",
        "--quiet",
        "--record",
        rrd.to_str().unwrap(),
    ]);
    let _ = std::process::Command::new("kill")
        .args(["-INT", &first.id().to_string()])
        .status();
    drop(lines);
    let status = first.wait().unwrap();
    assert_eq!(code, 3, "{err}");
    assert!(err.contains("another run is writing"), "{err}");
    assert!(matches!(status.code(), Some(0 | 130)), "{status:?}");
    // The first run's recording is whole: its own rows only.
    let head = std::fs::read(&rrd).unwrap();
    assert_eq!(&head[..3], b"RRF");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_checkpoint_folder_with_other_files_is_refused_unless_forced() {
    let dir = scratch("hostile-ckpt-folder");
    std::fs::write(dir.join("notes.txt"), b"mine").unwrap();
    let ck = dir.to_str().unwrap();
    let (code, _, err) = mpmlab(&["run", "scenarios/patch-compression.toml", "--quiet", "--checkpoint", ck]);
    assert_eq!(code, 3, "{err}");
    assert!(err.contains("notes.txt") && err.contains("--force"), "{err}");
    let (code, _, err) = mpmlab(&[
        "run",
        "scenarios/patch-compression.toml",
        "--quiet",
        "--checkpoint",
        ck,
        "--force",
    ]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(std::fs::read(dir.join("notes.txt")).unwrap(), b"mine");
    assert!(std::fs::read_dir(&dir)
        .unwrap()
        .any(|e| e.unwrap().file_name().to_string_lossy().ends_with(".ckpt")));
    let _ = std::fs::remove_dir_all(&dir);
}

/// `mpmlab ARGS` in `dir` with files limited to `blocks` 512-byte blocks
/// and SIGXFSZ ignored, so a write past the limit fails with EFBIG as a
/// full disk fails with ENOSPC (no mount needed); killed if it takes more
/// than a minute (it hung for ever on a full disk).
fn with_file_limit(dir: &Path, blocks: u64, args: &[&str]) -> (i32, String) {
    let mut cmd = format!(
        "ulimit -f {blocks}; trap '' XFSZ; exec '{}'",
        env!("CARGO_BIN_EXE_mpmlab")
    );
    for a in args {
        cmd.push_str(&format!(" '{a}'"));
    }
    let mut child = std::process::Command::new("sh")
        .arg("-c")
        .arg(&cmd)
        .current_dir(dir)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let start = std::time::Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            let mut err = String::new();
            std::io::Read::read_to_string(child.stderr.as_mut().unwrap(), &mut err).unwrap();
            return (status.code().unwrap_or(-1), err);
        }
        if start.elapsed() > std::time::Duration::from_secs(60) {
            let _ = child.kill();
            panic!("mpmlab {args:?} hung on a full file system");
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
}

#[test]
fn a_full_disk_ends_the_run_with_what_was_written_readable() {
    let dir = scratch("hostile-full-disk");
    let d = dir.to_str().unwrap();
    let scene = std::path::absolute(scene_path("ghost-collision-plastic")).unwrap();
    let scene = scene.to_str().unwrap();
    // The recording fills the limit first (512 kB) mid-run: exit 3, the
    // step named, the partial file kept and repairable to that step.
    let (code, err) = with_file_limit(
        &dir,
        1000,
        &["run", scene, "--record", "run.rrd", "--csv", "run.csv", "--quiet"],
    );
    assert_eq!(code, 3, "{err}");
    assert!(err.contains("cannot write") && err.contains("run.rrd.partial"), "{err}");
    let after: i64 = err
        .split("the run stops after step ")
        .nth(1)
        .and_then(|t| t.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no step named: {err}"));
    assert!(after > 0 && after < 1000, "{err}");
    assert!(!dir.join("run.rrd").exists(), "a recording that failed took its name");
    let (code, out, e) = mpmlab(&["repair", &format!("{d}/run.rrd.partial"), &format!("{d}/fixed.rrd")]);
    assert_eq!(code, 0, "{e}");
    // The write error surfaces at the next flush of the file: the repaired
    // recording holds every step up to the one named, less those written
    // since the last flush that reached the disk (none on an idle
    // machine; a few when other processes delay the flushes).
    let kept: i64 = out
        .split("data up to step ")
        .nth(1)
        .and_then(|t| t.split(|c: char| !c.is_ascii_digit()).next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no step kept: {out}"));
    assert!(kept > 0 && kept <= after, "kept {kept}, stopped after {after}: {out}");
    // A checkpoint that does not fit: the run stops there and no half
    // checkpoint is left (the limit is per file, so here the first one
    // already fails; any whole one there resumes).
    let ck = dir.join("ck");
    let (code, err) = with_file_limit(
        &dir,
        1000,
        &["run", scene, "--checkpoint", "ck", "--checkpoint-every", "5", "--quiet"],
    );
    assert_eq!(code, 3, "{err}");
    assert!(err.contains("cannot write checkpoint"), "{err}");
    let names: Vec<String> = std::fs::read_dir(&ck)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(!names.iter().any(|n| n.ends_with(".partial")), "{names:?}");
    // A sweep recording its runs: the child whose recording fills the
    // limit is a row with the reason (the sweep hung in its first child).
    let (code, err) = with_file_limit(
        &dir,
        1000,
        &[
            "sweep",
            scene,
            "--out",
            "sw",
            "--vary",
            "analysis.load_steps=200",
            "--record",
        ],
    );
    assert_eq!(code, 0, "{err}");
    let table = std::fs::read_to_string(dir.join("sw/sweep.csv")).unwrap();
    assert!(table.contains("cannot write"), "{table}");
    // A ParaView series: exit 3 and no half file in its folders.
    let (code, err) = with_file_limit(&dir, 300, &["run", scene, "--vtk", "series", "--quiet"]);
    assert_eq!(code, 3, "{err}");
    for sub in ["series", "series/points", "series/grid"] {
        if let Ok(entries) = std::fs::read_dir(dir.join(sub)) {
            for e in entries {
                let n = e.unwrap().file_name().to_string_lossy().into_owned();
                assert!(!n.ends_with(".partial"), "{sub}/{n}: {err}");
            }
        }
    }
    for n in names.iter().filter(|n| n.ends_with(".ckpt")) {
        let (code, _, e) = mpmlab(&["run", scene, "--resume", &format!("{}/{n}", ck.display()), "--quiet"]);
        assert_eq!(code, 0, "{n}: {e}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn sweep_and_series_folders_with_other_files_are_refused_unless_forced() {
    let dir = scratch("hostile-foreign-folders");
    std::fs::write(dir.join("sweep.csv"), b"my own table").unwrap();
    let d = dir.to_str().unwrap();
    // A user's sweep.csv in the --out folder was silently replaced.
    let (code, _, err) = mpmlab(&[
        "sweep",
        "scenarios/patch-compression.toml",
        "--out",
        d,
        "--vary",
        "h=0.5",
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("not a sweep's") && err.contains("--force"), "{err}");
    assert_eq!(std::fs::read(dir.join("sweep.csv")).unwrap(), b"my own table");
    // A ParaView folder holding the user's file.
    let (code, _, err) = mpmlab(&["run", "scenarios/patch-compression.toml", "--quiet", "--vtk", d]);
    assert_eq!(code, 3, "{err}");
    assert!(
        err.contains("not a ParaView series") && err.contains("sweep.csv"),
        "{err}"
    );
    let (code, _, err) = mpmlab(&[
        "run",
        "scenarios/patch-compression.toml",
        "--quiet",
        "--vtk",
        d,
        "--force",
    ]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(std::fs::read(dir.join("sweep.csv")).unwrap(), b"my own table");
    assert!(dir.join("points.pvd").exists());
    // A sweep's own folder is gone on with: run twice, the second finds
    // its runs done.
    let own = dir.join("own");
    let o = own.to_str().unwrap();
    for _ in 0..2 {
        let (code, _, err) = mpmlab(&[
            "sweep",
            "scenarios/patch-compression.toml",
            "--out",
            o,
            "--vary",
            "h=0.5",
        ]);
        assert_eq!(code, 0, "{err}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_run_with_no_step_left_writes_its_table_and_damaged_results_are_named() {
    let dir = scratch("hostile-no-step");
    let d = dir.to_str().unwrap();
    let (code, _, err) = mpmlab(&[
        "run",
        "scenarios/patch-compression.toml",
        "--quiet",
        "--checkpoint",
        &format!("{d}/ck"),
    ]);
    assert_eq!(code, 0, "{err}");
    // Resumed from the last checkpoint: no step to take; the table still
    // has its header and the row of where the run stands (it was empty).
    let (code, _, err) = mpmlab(&[
        "run",
        "scenarios/patch-compression.toml",
        "--quiet",
        "--resume",
        &format!("{d}/ck/step-000001.ckpt"),
        "--csv",
        &format!("{d}/end.csv"),
    ]);
    assert_eq!(code, 0, "{err}");
    let t = std::fs::read_to_string(dir.join("end.csv")).unwrap();
    let lines: Vec<&str> = t.lines().collect();
    assert!(
        lines.len() == 2 && lines[0].starts_with("step,load_factor,") && lines[1].starts_with("1,"),
        "{t}"
    );
    // A damaged result file in a sweep folder is named as such.
    let sw = format!("{d}/sw");
    let (code, _, err) = mpmlab(&[
        "sweep",
        "scenarios/patch-compression.toml",
        "--out",
        &sw,
        "--vary",
        "h=0.5,0.25",
    ]);
    assert_eq!(code, 0, "{err}");
    std::fs::write(dir.join("sw/results/h=0.25.csv"), "garbage").unwrap();
    std::fs::remove_file(dir.join("sw/sweep.csv")).unwrap();
    let (_, _, err) = mpmlab(&["sweep", "--collect", &sw]);
    assert!(
        err.contains("cannot be read (damaged") && err.contains("h=0.25.csv"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn sweeps_reject_bad_settings_before_running() {
    let dir = temp_path("hostile-sweep", "d");
    let out = dir.to_str().unwrap();
    let sweep = |extra: &[&str]| {
        let mut args = vec!["sweep", "scenarios/patch-compression.toml", "--out", out];
        args.extend_from_slice(extra);
        mpmlab(&args)
    };
    // An unknown key, a non-numeric value, a value out of range: exit 2,
    // nothing written.
    for (vary, fragment) in [
        ("hh=0.5", "unknown field `hh`"),
        ("h=abc", "field `grid.h`"),
        ("h=1e300", "out of range"),
        ("analysis.nope=1", "unknown field `nope`"),
        ("body.3.basis=gimp", "no element 3"),
        ("ppc=0", "no run is a valid scene"),
    ] {
        let (code, o, err) = sweep(&["--vary", vary]);
        assert_eq!(code, 2, "{vary}: {o}{err}");
        assert!(err.contains(fragment), "{vary}: {err}");
        assert!(!dir.exists(), "{vary}: the sweep folder was written");
    }
    // --jobs 0 is an argument error.
    let (code, _, err) = sweep(&["--vary", "h=0.5", "--jobs", "0"]);
    assert_eq!(code, 2);
    assert!(err.contains("--jobs"), "{err}");
    // One field set twice (the later would win in every run, both labelled)
    // and --try without --target (it was ignored): exit 2, nothing written.
    for (args, fragment) in [
        (&["--vary", "h=0.5", "--vary", "h=0.25"][..], "both set `grid.h`"),
        (
            &["--vary", "ppc=2", "--vary", "body.0.points_per_cell=4"][..],
            "both set `body.0.points_per_cell`",
        ),
        (&["--vary", "h=0.5", "--try", "h=0.25"][..], "--try needs --target"),
        // Target quantities the scene does not report (they ran to the
        // budget and exited 1), and --try of what the search sets itself.
        (&["--target", "error:nope=1e-2"][..], "its errors: error:stress_l2"),
        (&["--target", "probe:nope:uy=1e-3"][..], "the scene has no probes"),
        (&["--target", "energy:nope=1e-2"][..], "its energies: energy:strain"),
        (&["--target", "error:stress_l2=1e-2=3"][..], "expected one QUANTITY=TOL"),
        (
            &["--target", "energy:strain=1e-2", "--try", "h=0.1"][..],
            "refines h and points per cell itself",
        ),
        (
            &["--target", "energy:strain=1e-2", "--try", "ppc=3"][..],
            "refines h and points per cell itself",
        ),
        (
            &[
                "--target",
                "energy:strain=1e-2",
                "--try",
                "body.0.basis=gimp",
                "--try",
                "body.0.basis=standard",
            ][..],
            "both set `body.0.basis`",
        ),
    ] {
        let (code, o, err) = sweep(args);
        assert_eq!(code, 2, "{args:?}: {o}{err}");
        assert!(err.contains(fragment), "{args:?}: {err}");
        assert!(!dir.exists(), "{args:?}: the sweep folder was written");
    }

    // An error target on a scene without an exact solution.
    let (code, _, err) = mpmlab(&[
        "sweep",
        "scenarios/collapse-von-mises.toml",
        "--out",
        out,
        "--target",
        "error:stress_l2=1e-2",
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("no exact solution"), "{err}");
    assert!(!dir.exists());
    // --estimate when fewer than three sizes complete (every run fails: one
    // Newton iteration, no cutbacks): said, exit 1 (it exited 0 silently).
    let (code, o, err) = sweep(&[
        "--vary",
        "h=0.5,0.25,0.125",
        "--vary",
        "analysis.kind=quasi-static-finite",
        "--vary",
        "analysis.max_iterations=1",
        "--vary",
        "analysis.max_cutbacks=0",
        "--estimate",
    ]);
    assert_eq!(code, 1, "{o}{err}");
    assert!(err.contains("only 0 cell sizes completed"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);

    // Emitted jobs carry absolute paths; collecting with none run fails
    // loudly; with one run, the missing one is named.
    let (code, o, err) = sweep(&["--vary", "h=0.5,0.25", "--emit-jobs"]);
    assert_eq!(code, 0, "{o}{err}");
    let jobs = std::fs::read_to_string(dir.join("jobs.txt")).unwrap();
    for line in jobs.lines() {
        let paths: Vec<&str> = line.split('\'').skip(1).step_by(2).collect();
        assert_eq!(paths.len(), 3, "{line}");
        assert!(paths.iter().all(|p| p.starts_with('/')), "{line}");
    }
    let (code, _, err) = mpmlab(&["sweep", "--collect", out]);
    assert_eq!(code, 1, "{err}");
    assert!(
        err.contains("2 of 2 runs have no result") && err.contains("nothing to collect"),
        "{err}"
    );
    let first = jobs.lines().next().unwrap();
    assert!(std::process::Command::new("sh")
        .arg("-c")
        .arg(first)
        .current_dir("/")
        .status()
        .unwrap()
        .success());
    let (code, o, err) = mpmlab(&["sweep", "--collect", out]);
    assert_eq!(code, 0, "exit {code}: {o}{err}");
    assert!(
        err.contains("1 of 2 runs have no result") && err.contains("died): h=0.25"),
        "{err}"
    );
    // Not a sweep folder at all.
    let (code, _, err) = mpmlab(&["sweep", "--collect", "/nonexistent-sweep"]);
    assert_eq!(code, 2);
    assert!(err.contains("not a sweep folder"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn every_preset_plans_valid_runs() {
    use mpmlab::sweep::{expand, presets, run_scene};
    for name in presets::NAMES {
        let p = presets::preset(name).unwrap();
        let base = shipped(p.scene);
        for r in expand(&p.vary) {
            let text = run_scene(&base, &p.fixed, &r).unwrap();
            if let Err(e) = Model::from_text(&text, &r.id) {
                panic!("{name} {}: {e}", r.id);
            }
        }
    }
}

/// A shipped scene built with the default limits, then given a step-time
/// budget of `budget` bytes.
fn sim_with_budget(name: &str, budget: u64) -> mpmlab::Simulation {
    let text = std::fs::read_to_string(scene_path(name)).unwrap();
    let scene = Scene::parse(&text, name).unwrap();
    let mut model = Model::build(&scene, &text, name).unwrap();
    model.max_memory = budget;
    mpmlab::Simulation::new(model)
}

#[test]
fn a_factor_beyond_the_memory_budget_is_a_reported_step_failure() {
    // Each factorisation is estimated from its symbolic analysis before it
    // is computed; 1 MiB is less than the process already holds, so every
    // factor is refused, whatever its size, and the state stays at step 0.
    for (scene, what) in [
        ("column-small-strain", "the Cholesky factor of"),
        ("elastic-beam-ghost", "the Cholesky factor of"),
        ("cantilever-follower-pressure-finite", "the LU factor of"),
        ("ghost-collision-elastic", "the Cholesky factor of"),
    ] {
        let mut sim = sim_with_budget(scene, 1 << 20);
        let f = sim.step_guarded().unwrap_err();
        let mpmlab::StepFailure::OutOfMemory {
            step: 1,
            what: w,
            bytes,
            in_use,
            budget: Some(budget),
        } = &f
        else {
            panic!("{scene}: {f:?}");
        };
        assert!(w.starts_with(what) && w.contains("unknowns"), "{scene}: {w}");
        assert!(
            *bytes > 0 && *in_use + *bytes > *budget && *budget == 1 << 20,
            "{scene}: {f:?}"
        );
        let text = f.to_string();
        assert!(
            text.starts_with("step 1 failed: out of memory: ")
                && text.contains(what)
                && text.contains("needs an estimated")
                && text.contains("--max-memory")
                && text.contains("grid.h"),
            "{text}"
        );
        assert_eq!(sim.step_index(), 0, "{scene}");
        // With the budget the build gives (half the available memory) it steps.
        let mut sim = sim_with_budget(scene, Limits::default().max_memory);
        sim.step_guarded().unwrap_or_else(|f| panic!("{scene}: {f}"));
    }
}

#[test]
fn memory_that_cannot_be_allocated_for_a_step_is_a_reported_failure() {
    // The linear column at h = 0.05 m (160,000 points, 80,199 unknowns)
    // under `ulimit -v` below its peak: the step's big buffers (the
    // pattern, the matrix, the symbolic analysis, the factor and its
    // workspace) are reserved fallibly, so the step fails with exit 1 and
    // `out of memory` instead of aborting. (The points are reserved
    // fallibly while the model is built: next test.)
    let dir = scratch("hostile-ulimit");
    let p = dir.join("column.toml");
    let text = edit(
        "column-small-strain",
        &[
            ("size = [1.0, 12.0]", "size = [10.0, 12.0]"),
            ("h = 0.5", "h = 0.05"),
            ("max = [1.0, 10.0]", "max = [10.0, 10.0]"),
            ("x = 1.0", "x = 10.0"),
            ("tolerance = 1e-8", "tolerance = 1e-8\ncondition = \"off\""),
        ],
    );
    std::fs::write(&p, text).unwrap();
    let scene = p.to_str().unwrap();
    let (code, out, err) = mpmlab(&["run", "--quiet", "--max-memory", "1T", scene]);
    assert_eq!(code, 0, "{err}");
    let peak_mb: f64 = out
        .split("peak memory ")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no peak memory in {out}"));
    let run_limited = |kib: u64| {
        let o = std::process::Command::new("sh")
            .arg("-c")
            .arg(format!("ulimit -v {kib} && exec \"$0\" run --max-memory 1T \"$1\""))
            .arg(env!("CARGO_BIN_EXE_mpmlab"))
            .arg(scene)
            .output()
            .unwrap();
        (
            o.status.code(),
            String::from_utf8_lossy(&o.stdout).into_owned(),
            String::from_utf8_lossy(&o.stderr).into_owned(),
        )
    };
    let mut reported = Vec::new();
    for fraction in [0.75, 0.8, 0.85, 0.9, 0.95] {
        let kib = (fraction * peak_mb * 1e3) as u64;
        let (code, out, err) = run_limited(kib);
        match code {
            Some(0) => {}
            Some(1) => {
                assert!(
                    err.contains("step 1 failed: out of memory: ")
                        && err.contains("could not be allocated")
                        && err.contains("grid.h"),
                    "ulimit -v {kib}: {err}"
                );
                assert!(out.starts_with("scene `column-small-strain`"), "{out}");
                reported.push(err);
            }
            other => panic!("ulimit -v {kib}: exit {other:?}\n{out}\n{err}"),
        }
    }
    assert!(
        !reported.is_empty(),
        "no limit between 0.75 and 0.95 of the {peak_mb} MB peak made the step fail"
    );
    eprintln!("{}", reported.join(""));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn points_that_cannot_be_allocated_name_their_field() {
    // A valid lattice of 9e6 points (2.2 GB of point arrays) with the
    // memory budget lifted, under `ulimit -v` 1.5 GB: the points are
    // reserved fallibly before they are placed, so the scene is refused
    // with exit 2 naming `body[0].lattice` and the bytes, not an abort.
    let dir = scratch("hostile-ulimit-points");
    let p = dir.join("lattice.toml");
    std::fs::write(
        &p,
        r#"[scene]
name = "lattice"
description = "A lattice too large for the address space."
[grid]
origin = [0.0, 0.0]
size = [2.0, 2.0]
h = 0.01
[[material]]
name = "soft"
E = 1000.0
nu = 0.3
density = 1000.0
[[body]]
name = "block"
material = "soft"
placement = "lattice"
points_per_cell = 1
lattice = [3000, 3000]
region = { shape = "rectangle", min = [0.5, 0.5], max = [1.5, 1.5] }
[analysis]
kind = "explicit-dynamics"
duration = 0.01
load_steps = 1
mass = "lumped"
"#,
    )
    .unwrap();
    let o = std::process::Command::new("sh")
        .arg("-c")
        .arg("ulimit -v 1500000 && exec \"$0\" run --max-memory 1T \"$1\"")
        .arg(env!("CARGO_BIN_EXE_mpmlab"))
        .arg(&p)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("lattice.toml:18:")
            && err.contains("field `body[0].lattice`")
            && err.contains("cannot allocate 2.2 GB"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A block under its weight on a fixed base, its finite-deformation
/// tangent made non-symmetric by F-bar (so factorised by LU), cells `h` m.
fn fbar_block(h: &str) -> String {
    format!(
        r#"[scene]
name = "fbar-block"
description = "An F-bar block under its weight."
[grid]
origin = [0.0, 0.0]
size = [2.0, 2.0]
h = {h}
[[material]]
name = "soft"
E = 1.0e6
nu = 0.3
density = 1000.0
[[body]]
name = "block"
material = "soft"
points_per_cell = 1
region = {{ shape = "rectangle", min = [0.0, 0.0], max = [2.0, 1.5] }}
[loads]
gravity = [0.0, -9.81]
[[dirichlet]]
kind = "fixed"
y = 0.0
[analysis]
kind = "quasi-static-finite"
load_steps = 1
fbar = true
"#
    )
}

#[test]
fn an_lu_factor_that_cannot_be_allocated_is_a_step_failure() {
    // F-bar makes the tangent non-symmetric, so Newton factorises it by LU,
    // whose fill faer grows during the numeric factorisation as partial
    // pivoting decides. With the budget lifted and `ulimit -v` 250 MB, the
    // 60,300-unknown block fits (about 160 MB resident) but its LU factor
    // (194 MB estimated before pivoting) does not: the step fails as out of
    // memory naming the factor, exit 1, not an abort (134) nor a
    // "singular system".
    let dir = scratch("hostile-ulimit-lu");
    let p = dir.join("fbar.toml");
    std::fs::write(&p, fbar_block("0.01")).unwrap();
    let o = std::process::Command::new("sh")
        .arg("-c")
        .arg("ulimit -v 250000 && exec \"$0\" run --quiet --max-memory 1T \"$1\"")
        .arg(env!("CARGO_BIN_EXE_mpmlab"))
        .arg(&p)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("step 1 failed: out of memory")
            && err.contains("for the LU factor of 60300 unknowns")
            && err.contains("could not be allocated"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn no_memory_limit_makes_a_run_abort_or_hang() {
    // Three scenes whose memory crosses 30-94 MB (measured), each run under
    // `ulimit -v` at eight limits across that range, with backtraces on
    // (a panic that prints one while memory is short once deadlocked in the
    // standard library): Newton with ghost (the G 5.5 beam at h = 0.0625),
    // a linear step with dense eigenvalues (the slender cantilever), and a
    // non-symmetric F-bar step factorised by LU. Every run must end with
    // exit 0, 1 (a step failure, reported) or 2 (refused), within 60 s:
    // before the fallible residual buffers, dense eigenvalues and the
    // kernels' warm-up, three of these ended in SIGABRT (134) and one hung.
    let dir = scratch("hostile-ulimit-sweep");
    let scenes = dir.join("scenes");
    std::fs::create_dir_all(&scenes).unwrap();
    let with_h = |name: &str, h: Option<&str>| {
        let text = std::fs::read_to_string(scene_path(name)).unwrap();
        let text = match h {
            Some(h) => text
                .lines()
                .map(|l| {
                    if l.starts_with("h = ") {
                        format!("h = {h}")
                    } else {
                        l.to_string()
                    }
                })
                .collect::<Vec<_>>()
                .join("\n"),
            None => text,
        };
        let p = scenes.join(format!("{name}.toml"));
        std::fs::write(&p, text).unwrap();
        p
    };
    let fbar = scenes.join("fbar.toml");
    std::fs::write(&fbar, fbar_block("0.02")).unwrap();
    let runs = [
        with_h("elastic-beam-ghost", Some("0.0625")),
        with_h("slender-cantilever-0", None),
        fbar,
    ];
    let mut bad = Vec::new();
    for scene in &runs {
        for kb in (30_000..=86_000).step_by(8_000) {
            let o = std::process::Command::new("timeout")
                .args(["60", "sh", "-c"])
                .arg(format!(
                    "ulimit -v {kb} && exec \"$0\" run --quiet --max-memory 1T \"$1\""
                ))
                .arg(env!("CARGO_BIN_EXE_mpmlab"))
                .arg(scene)
                .env("RUST_BACKTRACE", "1")
                .output()
                .unwrap();
            let code = o.status.code();
            if !matches!(code, Some(0..=2)) {
                let err = String::from_utf8_lossy(&o.stderr);
                let lines: Vec<&str> = err.lines().filter(|l| !l.starts_with("  ")).collect();
                let tail = lines[lines.len().saturating_sub(12)..].join("\n    ");
                bad.push(format!("{} at {kb} kB: {:?}:\n    {tail}", scene.display(), o.status));
            }
        }
    }
    assert!(bad.is_empty(), "{}", bad.join("\n"));
    let _ = std::fs::remove_dir_all(&dir);
}

/// Mutations of shipped scenes for the property test.
mod mutate {
    use proptest::prelude::*;
    use toml::Value;

    /// Every path to a leaf or table in `v`, as keys and indices.
    pub fn paths(v: &Value, at: Vec<Step>, out: &mut Vec<Vec<Step>>) {
        match v {
            Value::Table(t) => {
                for (k, x) in t {
                    let mut p = at.clone();
                    p.push(Step::Key(k.clone()));
                    out.push(p.clone());
                    paths(x, p, out);
                }
            }
            Value::Array(a) => {
                for (i, x) in a.iter().enumerate() {
                    let mut p = at.clone();
                    p.push(Step::Index(i));
                    out.push(p.clone());
                    paths(x, p, out);
                }
            }
            _ => {}
        }
    }

    #[derive(Clone, Debug)]
    pub enum Step {
        Key(String),
        Index(usize),
    }

    fn get<'a>(v: &'a mut Value, path: &[Step]) -> Option<&'a mut Value> {
        let mut v = v;
        for s in path {
            v = match (s, v) {
                (Step::Key(k), Value::Table(t)) => t.get_mut(k)?,
                (Step::Index(i), Value::Array(a)) => a.get_mut(*i)?,
                _ => return None,
            };
        }
        Some(v)
    }

    /// What to do at a path.
    #[derive(Clone, Debug)]
    pub enum Op {
        Set(Value),
        Scale(f64),
        Delete,
        AddKey(String, Value),
    }

    pub fn value() -> impl Strategy<Value = Value> {
        prop_oneof![
            prop::sample::select(vec![
                0.0,
                -0.0,
                -1.0,
                1.0,
                0.5,
                1e-300,
                1e300,
                f64::NAN,
                f64::INFINITY,
                -f64::INFINITY,
                1e-12,
                1e12,
                f64::MIN_POSITIVE,
                2.5,
                -3.75,
            ])
            .prop_map(Value::Float),
            prop::sample::select(vec![
                0i64,
                -1,
                1,
                2,
                3,
                64,
                65,
                1000,
                1 << 32,
                i64::MAX,
                i64::MIN,
                1_000_000_000
            ])
            .prop_map(Value::Integer),
            any::<bool>().prop_map(Value::Boolean),
            prop::sample::select(vec![
                "",
                "gimp",
                "lattice",
                "polar",
                "circle",
                "fixed",
                "roller",
                "x",
                "dense",
                "explicit-dynamics",
                "block",
                "elastic",
                "../x",
            ])
            .prop_map(|s| Value::String(s.to_string())),
            (-1e3f64..1e3, -1e3f64..1e3).prop_map(|(a, b)| Value::Array(vec![Value::Float(a), Value::Float(b)])),
            Just(Value::Array(vec![])),
            Just(Value::Table(toml::Table::new())),
        ]
    }

    pub fn op() -> impl Strategy<Value = Op> {
        prop_oneof![
            4 => value().prop_map(Op::Set),
            2 => prop::sample::select(vec![0.0, -1.0, 0.5, 2.0, 10.0, 1e-9, 1e9]).prop_map(Op::Scale),
            2 => Just(Op::Delete),
            1 => (prop::sample::select(vec!["extra", "name", "h", "lattice", "points", "tolerance"]), value())
                .prop_map(|(k, v)| Op::AddKey(k.to_string(), v)),
        ]
    }

    /// Apply `op` at `path` (a no-op where it does not fit).
    pub fn apply(doc: &mut Value, path: &[Step], op: &Op) {
        match op {
            Op::Delete => {
                let Some((last, parent)) = path.split_last() else {
                    return;
                };
                match (get(doc, parent), last) {
                    (Some(Value::Table(t)), Step::Key(k)) => {
                        t.remove(k);
                    }
                    (Some(Value::Array(a)), Step::Index(i)) if *i < a.len() => {
                        a.remove(*i);
                    }
                    _ => {}
                }
            }
            Op::Set(v) => {
                if let Some(x) = get(doc, path) {
                    *x = v.clone();
                }
            }
            Op::Scale(s) => match get(doc, path) {
                Some(Value::Float(x)) => *x *= s,
                Some(Value::Integer(i)) => *i = (*i as f64 * s) as i64,
                _ => {}
            },
            Op::AddKey(k, v) => {
                if let Some(Value::Table(t)) = get(doc, path) {
                    t.insert(k.clone(), v.clone());
                }
            }
        }
    }
}

fn shipped_scenes() -> Vec<(String, String)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios");
    let mut v: Vec<(String, String)> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .map(|p| (p.display().to_string(), std::fs::read_to_string(&p).unwrap()))
        .collect();
    v.sort();
    v
}

use proptest::prelude::*;

proptest! {
    #![proptest_config(ProptestConfig { cases: 3000, failure_persistence: None, ..ProptestConfig::default() })]

    /// Any shipped scene with up to three random mutations either builds
    /// or is refused with a located error; nothing panics.
    #[test]
    fn mutated_scenes_build_or_fail_located(
        which in any::<prop::sample::Index>(),
        picks in prop::collection::vec((any::<prop::sample::Index>(), mutate::op()), 1..4),
    ) {
        let scenes = shipped_scenes_cached();
        let (file, text) = &scenes[which.index(scenes.len())];
        let mut doc: toml::Value = toml::Value::Table(text.parse().unwrap());
        for (at, op) in &picks {
            let mut paths = Vec::new();
            mutate::paths(&doc, Vec::new(), &mut paths);
            if paths.is_empty() {
                break;
            }
            let p = paths[at.index(paths.len())].clone();
            mutate::apply(&mut doc, &p, op);
        }
        let Ok(mutated) = toml::to_string(&doc) else { return Ok(()) };
        let limits = Limits { max_memory: 64 << 20 };
        let result = Scene::parse(&mutated, file).and_then(|s| Model::build_with(&s, &mutated, file, &limits));
        if let Err(e) = result {
            prop_assert!(e.line >= 1 && e.column >= 1, "{e}\n{mutated}");
            prop_assert!(!e.field.is_empty() && e.field != "(document)" && e.field != "(top level)", "{e}\n{mutated}");
            prop_assert!(!e.message.contains("18446744073709551615"), "{e}");
        }
    }
}

fn shipped_scenes_cached() -> &'static [(String, String)] {
    static SCENES: std::sync::OnceLock<Vec<(String, String)>> = std::sync::OnceLock::new();
    SCENES.get_or_init(shipped_scenes)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, failure_persistence: None, ..ProptestConfig::default() })]

    /// Any shipped scene with characters inserted, deleted or replaced at
    /// random (multi-byte ones too) is parsed and built without a panic,
    /// and a refusal is located.
    #[test]
    fn scenes_edited_as_text_build_or_fail_located(
        which in any::<prop::sample::Index>(),
        edits in prop::collection::vec(
            (any::<prop::sample::Index>(), 0usize..4, prop::sample::select(vec![
                "", "=", "[", "]", "{", "}", "\"", ",", "\n", "#", ".", "-", "e", "9", "é", "→", "\u{0}", "[[", "]]", "= [", "nan", "1e400",
            ])),
            1..6,
        ),
    ) {
        let scenes = shipped_scenes_cached();
        let (file, text) = &scenes[which.index(scenes.len())];
        let mut t = text.clone();
        for (at, cut, insert) in &edits {
            let mut k = at.index(t.len() + 1);
            while !t.is_char_boundary(k) {
                k -= 1;
            }
            let mut end = (k + cut).min(t.len());
            while !t.is_char_boundary(end) {
                end += 1;
            }
            t.replace_range(k..end, insert);
        }
        let limits = Limits { max_memory: 64 << 20 };
        if let Err(e) = Scene::parse(&t, file).and_then(|s| Model::build_with(&s, &t, file, &limits)) {
            prop_assert!(e.line >= 1 && e.column >= 1, "{e}\n{t}");
            prop_assert!(!e.field.is_empty() && e.field != "(document)", "{e}\n{t}");
        }
    }
}
