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

/// Runs `photometeor shaders`: translates everything first, then writes each file atomically
/// (a temporary file renamed), so a failure leaves no half-written output.
pub fn run(a: ShadersArgs) -> Result<()> {
    let outputs = runtime::shaders::translate()?;
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    for o in &outputs {
        let path = a.out.join(o.name);
        let tmp = a.out.join(format!(".{}.tmp", o.name));
        std::fs::write(&tmp, &o.bytes).with_context(|| format!("writing {}", tmp.display()))?;
        std::fs::rename(&tmp, &path).with_context(|| format!("writing {}", path.display()))?;
        println!("{} ({} bytes)", path.display(), o.bytes.len());
    }
    Ok(())
}
