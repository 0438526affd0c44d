//! `vmls check`: the hard-case and convergence suite, one line per measured number.

use crate::{CliError, DeviceArgs, context, plan_outputs, write_json};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct CheckArgs {
    /// The small configuration CI runs (smaller images, fewer refinements; the same bounds).
    #[arg(long)]
    quick: bool,
    /// Run only the cases whose name contains this (e.g. converge, tf-spike).
    #[arg(long)]
    case: Option<String>,
    /// List the cases and what each checks, then exit.
    #[arg(long)]
    list: bool,
    /// Write the outcomes as JSON.
    #[arg(long)]
    json: Option<PathBuf>,
    #[command(flatten)]
    device: DeviceArgs,
}

pub fn check(args: &CheckArgs) -> Result<(), CliError> {
    if args.list {
        for c in vmls::check::all_cases() {
            println!("{:<18} {}", c.name, c.about);
        }
        return Ok(());
    }
    if let Some(f) = &args.case
        && !vmls::check::all_cases()
            .iter()
            .any(|c| c.name.contains(f.as_str()))
    {
        return Err(CliError::Usage(format!(
            "no case matches '{f}' (vmls check --list names them)"
        )));
    }
    let outputs = plan_outputs(None, None, &[("--json", args.json.as_deref())])?;
    let ctx = context(&args.device)?;
    println!("device: {} ({})", ctx.info().name, ctx.info().driver);
    let outcomes = vmls::check::run(&ctx, args.quick, args.case.as_deref(), |o| {
        println!(
            "{} {:<16} {:<64} {:>10.3e}  {:<16} {}",
            if o.passed { "PASS" } else { "FAIL" },
            o.case,
            o.quantity,
            o.measured,
            o.bound.to_string(),
            o.detail
        );
    });
    if let Some(path) = &args.json {
        write_json(
            outputs,
            path,
            &serde_json::json!({
                "device": ctx.info().name,
                "driver": ctx.info().driver,
                "commit": vmls::bench::commit(),
                "quick": args.quick,
                "outcomes": outcomes,
            }),
        )?;
    }
    let failed = outcomes.iter().filter(|o| !o.passed).count();
    if failed > 0 {
        return Err(CliError::Usage(format!(
            "{failed} of {} checks failed",
            outcomes.len()
        )));
    }
    println!("all {} checks passed", outcomes.len());
    Ok(())
}
