//! Builds the shipped scenes (`scenarios/*.toml`) into the program, so that
//! `mpmlab verify` runs its benchmarks from any folder, not only from the
//! checkout: `$OUT_DIR/shipped_scenes.rs` holds `(name, text)` of each.

use std::path::Path;

fn main() {
    // The variable cargo sets when it runs this script, not the one it was
    // compiled with: a build of another checkout may reuse the script.
    let dir = Path::new(&std::env::var("CARGO_MANIFEST_DIR").expect("CARGO_MANIFEST_DIR")).join("scenarios");
    println!("cargo:rerun-if-changed={}", dir.display());
    let mut names: Vec<String> = std::fs::read_dir(&dir)
        .expect("the scenarios folder")
        .filter_map(|e| {
            let p = e.ok()?.path();
            println!("cargo:rerun-if-changed={}", p.display());
            (p.extension()? == "toml").then(|| p.file_stem()?.to_str().map(str::to_string))?
        })
        .collect();
    names.sort();
    let mut out =
        String::from("/// The shipped scenes, `(name, text)`, by name.\npub static SHIPPED: &[(&str, &str)] = &[\n");
    for n in &names {
        let path = dir.join(format!("{n}.toml"));
        out += &format!("    ({n:?}, include_str!({:?})),\n", path.display().to_string());
    }
    out += "];\n";
    let dest = Path::new(&std::env::var("OUT_DIR").expect("OUT_DIR")).join("shipped_scenes.rs");
    std::fs::write(dest, out).expect("write the shipped scenes");
}
