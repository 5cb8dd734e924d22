//! `photometeor shaders`: the WGSL sampling functions translated to HLSL, GLSL, MSL and
//! SPIR-V (`runtime::shaders`), written to a directory.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;

#[derive(Debug, Args)]
pub struct ShadersArgs {
    /// Directory to write photometeor.{wgsl,hlsl,comp.glsl,es310.comp.glsl,metal,spv} into
    /// (created if missing; existing files of those names are replaced).
    #[arg(long)]
    out: PathBuf,
}

/// Runs `photometeor shaders`: translates everything first, then writes each file through
/// `format::write_output` (a temporary file renamed; never over a device, FIFO or directory),
/// so a failure leaves no half-written output.
pub fn run(a: ShadersArgs) -> Result<()> {
    format::check_output_dir(&a.out, &[])?;
    let outputs = runtime::shaders::translate()?;
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    for o in &outputs {
        let path = a.out.join(o.name);
        format::write_output(&path, &o.bytes, &[])?;
        println!("{} ({} bytes)", path.display(), o.bytes.len());
    }
    Ok(())
}
