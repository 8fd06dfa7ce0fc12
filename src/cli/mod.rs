//! The command line, one module per command (`run`, `check` and `list`,
//! `sweep` and `sweep-run`, `verify`, `repair`, `replay`, `tui`), with the
//! arguments (`args`), the run table (`table`, `summary`) and what
//! commands share (`common`, `files`, `validate`).

/// `println!` that ignores a closed stdout (e.g. `mpmlab run ... | head`)
/// instead of panicking.
macro_rules! out {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout(), $($t)*);
    }};
}

pub mod args;
pub mod check;
pub mod common;
pub mod files;
pub mod repair;
pub mod replay;
pub mod run;
pub mod summary;
pub mod sweep;
pub mod table;
pub mod target;
pub mod tui;
pub mod validate;
pub mod verify;
