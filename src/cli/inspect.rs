//! `mocapstore inspect FILE…`

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use serde::Serialize;

use super::ReadArgs;
use mocapstore::motion::body::{Body, Given};
use mocapstore::motion::formats::{self, Loaded};

#[derive(Args)]
pub struct InspectArgs {
    /// Files to describe.
    #[arg(required = true)]
    files: Vec<PathBuf>,
    /// One JSON object per file instead of a table.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    read: ReadArgs,
}

#[derive(Serialize)]
struct Summary {
    file: String,
    format: String,
    points: usize,
    frames: usize,
    fps: f64,
    duration_s: f64,
    unit: String,
    unit_inferred: bool,
    gaps_percent: f64,
    skeleton_joints: Option<usize>,
    layout: String,
    /// The body: up, forward, floor, roles ([`mocapstore::motion::body`]), or why not.
    body: Result<Body, String>,
    warnings: Vec<String>,
}

fn summarise(file: String, l: &Loaded) -> Summary {
    let m = &l.motion;
    Summary {
        file,
        format: l.format.name().to_string(),
        points: m.point_count(),
        frames: m.frame_count(),
        fps: m.fps,
        duration_s: m.duration_s(),
        unit: m.unit.name(),
        unit_inferred: m.unit.is_inferred(),
        gaps_percent: 100.0 * m.gap_fraction(),
        skeleton_joints: m.skeleton.as_ref().map(|s| s.joint_count()),
        layout: m.layout_signature().to_hex()[..12].to_string(),
        body: Body::of(m, Given::default(), l.up.as_ref()).map_err(|e| e.to_string()),
        warnings: l.warnings.clone(),
    }
}

pub fn run(args: &InspectArgs) -> ExitCode {
    let options = match args.read.options() {
        Ok(o) => o,
        Err(e) => {
            eprintln!("mocapstore inspect: {e}");
            return ExitCode::from(2);
        }
    };
    let mut failed = 0;
    if !args.json {
        println!(
            "{:<40} {:<5} {:>6} {:>8} {:>8} {:>9} {:<10} {:>6} {:<4} {:<4} {:<13} {:>5}  warnings",
            "file",
            "fmt",
            "points",
            "frames",
            "fps",
            "seconds",
            "unit",
            "gaps%",
            "up",
            "fwd",
            "roles",
            "limbs"
        );
    }
    for path in &args.files {
        let name = path.display().to_string();
        let loaded = std::fs::read(path)
            .map_err(|e| e.to_string())
            .and_then(|b| formats::read(&b, &options).map_err(|e| e.to_string()));
        match loaded {
            Ok(l) => {
                let s = summarise(name, &l);
                if args.json {
                    println!("{}", serde_json::to_string(&s).expect("serialisable"));
                } else {
                    let unit = format!("{}{}", s.unit, if s.unit_inferred { "?" } else { "" });
                    let axis = |a: Option<mocapstore::motion::body::Axis>| {
                        a.map_or("-".to_string(), |a| a.to_string())
                    };
                    let (up, fwd, convention, limbs) = match &s.body {
                        Ok(b) => (
                            axis(b.axes.up),
                            axis(b.axes.forward),
                            b.roles.convention.clone().unwrap_or_else(|| "-".into()),
                            14 - b.roles.missing_limbs().len(),
                        ),
                        Err(e) => (format!("({e})"), String::new(), String::new(), 0),
                    };
                    println!(
                        "{:<40} {:<5} {:>6} {:>8} {:>8.3} {:>9.3} {:<10} {:>6.2} {:<4} {:<4} {:<13} {:>5}  {}",
                        s.file,
                        s.format,
                        s.points,
                        s.frames,
                        s.fps,
                        s.duration_s,
                        unit,
                        s.gaps_percent,
                        up,
                        fwd,
                        convention,
                        limbs,
                        s.warnings.join("; ")
                    );
                }
            }
            Err(e) => {
                failed += 1;
                eprintln!("{name}: {e}");
            }
        }
    }
    if !args.json {
        println!("(unit? = inferred; state it with --unit)");
    }
    if failed > 0 {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    }
}
