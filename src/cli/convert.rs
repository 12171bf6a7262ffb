//! `mocapstore convert IN OUT`

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;

use super::ReadArgs;
use mocapstore::motion::analog::per_frame_at;
use mocapstore::motion::body::{Axis, Body, Given};
use mocapstore::motion::formats::{self, Format};
use mocapstore::motion::transform::resample::trial_frame_at;
use mocapstore::motion::transform::{whole, Options, Root};
use mocapstore::motion::units::parse_unit;

#[derive(Args)]
pub struct ConvertArgs {
    /// Input file (format detected from its content).
    input: PathBuf,
    /// Output file.
    output: PathBuf,
    /// Output format (bvh, trc, c3d, json, npy, csv, f32, glb, gltf); default: from
    /// OUTPUT's extension.
    #[arg(long)]
    to: Option<Format>,
    #[command(flatten)]
    read: ReadArgs,
    /// Resample to this frame rate (the input's rate is --fps, for files that lack one).
    #[arg(long)]
    out_fps: Option<f64>,
    /// Root motion: keep, in-place or extract.
    #[arg(long, default_value = "keep")]
    root: Root,
    /// Up axis of the output (y, z, or signed: -z); glTF is always y.
    #[arg(long)]
    up: Option<Axis>,
    /// The input's up axis, when its body does not tell (`inspect` shows what it tells).
    #[arg(long)]
    source_up: Option<Axis>,
    /// The input's forward axis, when its body does not tell.
    #[arg(long)]
    source_forward: Option<Axis>,
    /// Unit of the output (mm, cm, m, in, ft, cmu or metres per unit); glTF is always m.
    /// (The input's unit is --unit.)
    #[arg(long)]
    out_unit: Option<String>,
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
    let mut transform = Options {
        fps: args.out_fps,
        root: args.root,
        up: args.up,
        metres_per_unit: args
            .out_unit
            .as_deref()
            .map(parse_unit)
            .transpose()
            .map_err(|e| format!("--out-unit: {e}"))?,
    };
    if format == Format::C3d
        && (transform.root != Root::Keep
            || transform.up.is_some()
            || transform.metres_per_unit.is_some())
    {
        return Err(
            "C3D keeps the lab's axes, units and root motion (its parameters place the force \
             plates in them): leave out --root, --up and --out-unit (--out-fps applies)"
                .into(),
        );
    }
    if format == Format::Fbx {
        // FBX states its axes: +Y up unless +Z is asked for.
        if transform.up.is_some_and(|u| u != Axis::Y && u != Axis::Z) {
            return Err("FBX is written +Y or +Z up: --up y or --up z".into());
        }
        transform.up = Some(transform.up.unwrap_or(Axis::Y));
    }
    let gltf = matches!(format, Format::Glb | Format::Gltf);
    if gltf {
        if transform.metres_per_unit.is_some_and(|m| m != 1.0)
            || transform.up.is_some_and(|u| u != Axis::Y)
        {
            return Err("glTF is in metres and +Y up: leave out --out-unit and --up".into());
        }
        transform.metres_per_unit = Some(1.0);
        transform.up = Some(Axis::Y);
    }
    let given = Given {
        up: args.source_up,
        forward: args.source_forward,
    };
    let body = Body::of(&loaded.motion, given, loaded.up.as_ref()).map_err(|e| e.to_string())?;
    let motion = whole::apply(&loaded.motion, &body, &transform).map_err(|e| {
        let hint = match e {
            mocapstore::motion::Error::Unsupported(_) => {
                " (state the input's axes with --source-up)"
            }
            _ => "",
        };
        format!("{input}: {e}{hint}")
    })?;
    let out = if gltf {
        let name = args
            .input
            .file_stem()
            .map_or_else(String::new, |s| s.to_string_lossy().to_string());
        Ok(formats::gltf::of_motion(
            &motion,
            &name,
            format == Format::Glb,
            serde_json::json!({ "mocapstore": { "source": name } }),
        ))
    } else if format == Format::Fbx {
        let name = args
            .input
            .file_stem()
            .map_or_else(String::new, |s| s.to_string_lossy().to_string());
        formats::fbx::write::of_motion(&motion, &name, transform.up.unwrap_or(Axis::Y))
    } else if format == Format::C3d {
        // Everything the input held: analog channels, events and parameters too (analog
        // keeps its rate: resampled, it must be a whole number of samples a frame).
        let analog = match &loaded.extras.analog {
            Some(a) if motion.fps != loaded.motion.fps => {
                let k = per_frame_at(a.per_frame, loaded.motion.fps, motion.fps)
                    .map_err(|e| format!("{input}: {e}"))?;
                Some(a.with_per_frame(k, motion.frame_count()))
            }
            other => other.clone(),
        };
        // The trial frame of the first frame, at the output's rate (as the service writes).
        let first = loaded.extras.first_frame.unwrap_or(1);
        let first_frame = trial_frame_at(first, loaded.motion.fps, motion.fps);
        let outputs = loaded
            .extras
            .outputs
            .as_ref()
            .map(|o| o.resampled(loaded.motion.fps, motion.fps));
        formats::c3d::write::write(&formats::c3d::write::Out {
            motion: &motion,
            analog: analog.as_ref(),
            outputs: outputs.as_ref(),
            parameters: loaded.extras.parameters.as_ref(),
            first_frame,
        })
    } else {
        formats::write(&motion, format)
    }
    .map_err(|e| format!("{input}: {e}"))?;
    // Write beside the target and rename, so a failure never leaves half a file.
    let tmp = args.output.with_extension("partial");
    std::fs::write(&tmp, out).map_err(|e| format!("{}: {e}", tmp.display()))?;
    std::fs::rename(&tmp, &args.output).map_err(|e| format!("{out_name}: {e}"))?;
    Ok(loaded.warnings)
}
