//! The `mocapstore` command line. Each subcommand lives in its own module; this one only
//! parses arguments and dispatches.

use std::process::ExitCode;

use clap::{Args, Parser, Subcommand};

mod bench;
mod convert;
mod ingest;
mod inspect;
mod loadtest;
mod plot;
mod streamtest;
mod train_bases;

#[derive(Parser)]
#[command(
    name = "mocapstore",
    version,
    about = "Archive motion capture with error-bounded compression"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Start the HTTP service (SQLite file by default).
    Serve(ServeArgs),
    /// Describe mocap files: format, points, frames, fps, duration, unit, gaps, warnings.
    Inspect(inspect::InspectArgs),
    /// Convert a take between formats (output format from the extension or --to).
    Convert(convert::ConvertArgs),
    /// Compare codecs on real files: ratio, errors, speed (Markdown, CSV, plot).
    Bench(bench::BenchArgs),
    /// Upload files or whole folders to a running service.
    Ingest(ingest::IngestArgs),
    /// Live-stream ingest over HTTP: frames/s sustained, capture-to-fetchable delay.
    Streamtest(streamtest::StreamArgs),
    /// Train a shared basis on a running service's takes (library, tag, layout or ids).
    TrainBases(train_bases::TrainArgs),
    /// Range-fetch latency and throughput over HTTP against raw SQLite BLOB reads.
    Loadtest(loadtest::LoadArgs),
}

#[derive(Args)]
struct ServeArgs {
    /// Address to listen on.
    #[arg(long, env = "MOCAP_LISTEN", default_value = "127.0.0.1:8080")]
    listen: String,
    /// Database: a SQLite file (created with its tables if missing) or a postgres:// URL.
    #[arg(long, env = "DATABASE_URL", default_value = "sqlite://mocapstore.db")]
    database_url: String,
    /// Largest upload accepted, in MiB (larger ones get 413).
    #[arg(long, env = "MOCAP_MAX_UPLOAD_MIB", default_value_t = 512)]
    max_upload_mib: usize,
    /// Memory for decoded chunks kept between range requests, in MiB (0 turns it off).
    #[arg(long, env = "MOCAP_DECODED_CACHE_MIB", default_value_t = 256)]
    decoded_cache_mib: usize,
}

/// Options every command that reads takes accepts.
#[derive(Args, Debug, Clone, Default)]
pub struct ReadArgs {
    /// Unit of the input coordinates (mm, cm, m, in, ft, cmu, or metres per unit);
    /// overrides the file's own and disables inference.
    #[arg(long)]
    pub unit: Option<String>,
    /// Frame rate of the input (needed for NPY, which has none).
    #[arg(long)]
    pub fps: Option<f64>,
}

impl ReadArgs {
    pub fn options(&self) -> Result<mocapstore_motion::ReadOptions, String> {
        let unit = match &self.unit {
            Some(u) => Some(mocapstore_motion::parse_unit(u).map_err(|e| e.to_string())?),
            None => None,
        };
        Ok(mocapstore_motion::ReadOptions {
            unit,
            fps: self.fps,
            ..Default::default()
        })
    }
}

/// Short paths to the motion layer for the subcommands.
mod mocapstore_motion {
    pub use crate::motion::formats::ReadOptions;
    pub use crate::motion::units::parse_unit;
}

pub fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        Command::Serve(args) => serve(args),
        Command::Inspect(args) => inspect::run(&args),
        Command::Convert(args) => convert::run(&args),
        Command::Bench(args) => bench::run(&args),
        Command::Ingest(args) => ingest::run(&args),
        Command::Loadtest(args) => loadtest::run(&args),
        Command::TrainBases(args) => train_bases::run(&args),
        Command::Streamtest(args) => streamtest::run(&args),
    }
}

fn serve(args: ServeArgs) -> ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| "info,tower_http=info,sqlx=warn".into()),
        )
        .init();
    let config = crate::http::Config {
        listen: args.listen,
        database_url: args.database_url,
        max_body_bytes: args.max_upload_mib << 20,
        decoded_cache_mib: args.decoded_cache_mib,
    };
    let runtime = match tokio::runtime::Runtime::new() {
        Ok(r) => r,
        Err(e) => {
            eprintln!("mocapstore serve: cannot start the runtime: {e}");
            return ExitCode::FAILURE;
        }
    };
    runtime.block_on(async move {
        let database = config.database_url.clone();
        let app = match crate::http::Application::build(config).await {
            Ok(a) => a,
            Err(e) => {
                eprintln!("mocapstore serve: {e}");
                return ExitCode::FAILURE;
            }
        };
        tracing::info!(address = %app.local_addr(), %database, "mocapstore listening");
        match app.run_until(crate::http::shutdown_signal()).await {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("mocapstore serve: {e}");
                ExitCode::FAILURE
            }
        }
    })
}
