//! The shipped scenes (`scenarios/*.toml`), built into the program by
//! `build.rs`: what `mpmlab verify` runs where no `scenarios` folder is at
//! hand.

include!(concat!(env!("OUT_DIR"), "/shipped_scenes.rs"));
