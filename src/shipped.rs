//! The shipped scenes (`scenarios/*.toml`), built into the program by
//! `build.rs`: what `mpmlab verify` runs, and the scene `mpmlab` opens,
//! where no `scenarios` folder is at hand.

include!(concat!(env!("OUT_DIR"), "/shipped_scenes.rs"));

/// The text of the shipped scene `name` (its file stem).
pub fn text(name: &str) -> Option<&'static str> {
    SHIPPED.iter().find(|(n, _)| *n == name).map(|(_, text)| *text)
}
