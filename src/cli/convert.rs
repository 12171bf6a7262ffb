//! `mocapstore convert IN OUT`

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;

use super::ReadArgs;
use mocapstore::motion::formats::{self, Format};

#[derive(Args)]
pub struct ConvertArgs {
    /// Input file (format detected from its content).
    input: PathBuf,
    /// Output file.
    output: PathBuf,
    /// Output format (bvh, trc, c3d, json, npy, csv, f32); default: from OUTPUT's extension.
    #[arg(long)]
    to: Option<Format>,
    #[command(flatten)]
    read: ReadArgs,
}

pub fn run(args: &ConvertArgs) -> ExitCode {
    match convert(args) {
        Ok(warnings) => {
            for w in warnings {
                eprintln!("{}: warning: {w}", args.input.display());
            }
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("mocapstore convert: {e}");
            ExitCode::FAILURE
        }
    }
}

fn convert(args: &ConvertArgs) -> Result<Vec<String>, String> {
    let out_name = args.output.display().to_string();
    let format = args
        .to
        .or_else(|| Format::from_extension(&out_name))
        .ok_or_else(|| format!("{out_name}: cannot tell the output format; use --to"))?;
    let options = args.read.options()?;
    let input = args.input.display();
    let bytes = std::fs::read(&args.input).map_err(|e| format!("{input}: {e}"))?;
    let loaded = formats::read(&bytes, &options).map_err(|e| format!("{input}: {e}"))?;
    let out = if format == Format::C3d {
        // Everything the input held: analog channels, events and parameters too.
        formats::c3d::write::write(&formats::c3d::write::Out {
            motion: &loaded.motion,
            analog: loaded.extras.analog.as_ref(),
            parameters: loaded.extras.parameters.as_ref(),
            first_frame: loaded.extras.first_frame.unwrap_or(1),
        })
    } else {
        formats::write(&loaded.motion, format)
    }
    .map_err(|e| format!("{input}: {e}"))?;
    // Write beside the target and rename, so a failure never leaves half a file.
    let tmp = args.output.with_extension("partial");
    std::fs::write(&tmp, out).map_err(|e| format!("{}: {e}", tmp.display()))?;
    std::fs::rename(&tmp, &args.output).map_err(|e| format!("{out_name}: {e}"))?;
    Ok(loaded.warnings)
}
