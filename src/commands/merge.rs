//! `photometeor merge`: the shard directories of `bake --shard K/N` into one bake.

use std::path::PathBuf;

use anyhow::{Context, Result};
use bake::{BakePlan, Scene};
use clap::Args as ClapArgs;

use crate::progress::Bars;

#[derive(Debug, ClapArgs)]
pub struct MergeArgs {
    /// The N shard directories (`bake SCENE --shard K/N --out DIR_K`), in any order.
    #[arg(required = true)]
    shards: Vec<PathBuf>,
    /// The bake directory to write (created if missing), as `bake --out`.
    #[arg(long)]
    out: PathBuf,
    /// No summary.
    #[arg(long)]
    quiet: bool,
    /// Print the summary as JSON.
    #[arg(long)]
    json: bool,
}

/// Checks the shards (one scene, one program, each shard once, every field once with its
/// record) before anything is written, then bakes from their records: the bake's own atomic
/// publish, byte-identical to a bake of the scene without shards.
pub fn run(a: MergeArgs) -> Result<()> {
    let merge = bake::shard::check_shards(&a.shards)?;
    // The output may not be, hold or lie inside a shard directory (the shards are inputs).
    let protected: Vec<&std::path::Path> = a.shards.iter().map(PathBuf::as_path).collect();
    format::check_output_dir(&a.out, &protected)?;
    let scene = Scene::parse_in(
        &merge.scene_text,
        "the shards' scene",
        merge.scene_dir.as_deref(),
    )?;
    let mut plan = BakePlan::for_preset(scene, a.out.clone(), merge.quality);
    plan.knobs.seed = merge.seed;
    for (field, (_, hash)) in plan.scene.fields.iter().zip(&merge.records) {
        let ours = bake::cache::content_hash(&plan, field);
        anyhow::ensure!(
            &ours == hash,
            "field {:?}: the shards' record was made from other inputs ({hash}, here {ours})",
            field.name
        );
    }
    // The records go into the bake's cache, where the bake takes every field from.
    for (dir, hash) in &merge.records {
        let from = bake::cache::record_path(dir, hash);
        let to = bake::cache::record_path(&a.out, hash);
        if from != to {
            let bytes =
                std::fs::read(&from).with_context(|| format!("reading {}", from.display()))?;
            std::fs::create_dir_all(to.parent().expect("a cache directory"))
                .with_context(|| format!("creating {}", a.out.display()))?;
            format::write_file_atomically(&to, &bytes)
                .map_err(|(op, e)| anyhow::anyhow!("{}: {op}: {e}", to.display()))?;
        }
    }
    let report = bake::run(&plan, &Bars::new(true))?;
    anyhow::ensure!(
        report.computed.is_empty(),
        "the merge computed {} instead of taking the shards' records",
        super::bake::fields_in_words(
            &report
                .computed
                .iter()
                .map(String::as_str)
                .collect::<Vec<_>>()
        )
    );
    if a.json {
        println!("{}", serde_json::to_string(&report)?);
    } else if !a.quiet {
        let fields: Vec<&str> = report.cached.iter().map(String::as_str).collect();
        println!(
            "merged {} shards of {} into {} in {:.2} s: {}",
            a.shards.len(),
            plan.scene.name,
            plan.out_dir.display(),
            report.seconds,
            super::bake::fields_in_words(&fields)
        );
    }
    Ok(())
}
