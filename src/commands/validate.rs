//! `photometeor validate`: a bake judged against theory it did not come from.

use anyhow::Result;
use bake::validate::{Status, validate};
use clap::Args as ClapArgs;

#[derive(Debug, ClapArgs)]
pub struct ValidateArgs {
    /// Bake directory (holding manifest.json).
    #[arg(default_value = "photometeor-tables")]
    dir: std::path::PathBuf,
    /// Print the checks as JSON instead of a table.
    #[arg(long)]
    json: bool,
}

pub fn run(a: ValidateArgs) -> Result<()> {
    let report = validate(&a.dir)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        let num = |v: Option<f64>| v.map_or("—".to_string(), |v| format!("{v:.3}"));
        println!(
            "{:<8} {:<3} {:<58} {:>9} {:>9} {:>7} {:<5} status",
            "field", "ch", "check", "measured", "expected", "± tol", "unit"
        );
        for c in &report.checks {
            let status = match c.status {
                Status::Pass => "pass",
                Status::Fail => "FAIL",
                Status::Info => "info",
            };
            let tol = c.tolerance.filter(|t| t.is_finite());
            println!(
                "{:<8} {:<3} {:<58} {:>9} {:>9} {:>7} {:<5} {status}  {}",
                c.field,
                c.channel,
                c.name,
                num(c.measured),
                num(c.expected),
                num(tol),
                c.unit,
                c.note
            );
        }
    }
    let failures = report.failures();
    if !failures.is_empty() {
        let names: Vec<String> = failures
            .iter()
            .map(|c| format!("{} {} {}", c.field, c.channel, c.name))
            .collect();
        eprintln!(
            "validate: {} check(s) failed: {}",
            failures.len(),
            names.join("; ")
        );
        std::process::exit(1);
    }
    Ok(())
}
