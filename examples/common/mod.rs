//! What the examples that run the `trispline` binary as a process share (not an example of
//! its own: cargo only takes `examples/*.rs` and `examples/*/main.rs`).

use std::path::{Path, PathBuf};

pub type Res<T> = Result<T, Box<dyn std::error::Error>>;

/// The `trispline` binary of the same target folder as the running example.
pub fn binary() -> Res<PathBuf> {
    let exe = std::env::current_exe()?;
    let bin = exe
        .parent()
        .and_then(Path::parent)
        .ok_or("cannot locate the target folder")?
        .join("trispline");
    if !bin.exists() {
        return Err(format!(
            "{} missing: run `cargo build --release --bin trispline` first",
            bin.display()
        )
        .into());
    }
    Ok(bin)
}
