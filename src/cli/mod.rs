//! The `mocapstore` command line. Each subcommand lives in its own module; this one only
//! parses arguments and dispatches.

use std::process::ExitCode;

use clap::{Args, Parser, Subcommand};

mod archive;
mod bench;
mod convert;
mod fetch;
mod ingest;
mod inspect;
mod loadtest;
mod streamtest;
mod token;
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
    /// Write any range of a stored take to a file (BVH for takes that keep their animation).
    Fetch(fetch::FetchArgs),
    /// Live-stream ingest over HTTP: frames/s sustained, capture-to-fetchable delay.
    Streamtest(streamtest::StreamArgs),
    /// Train a shared basis on a running service's takes (library, tag, layout or ids).
    TrainBases(train_bases::TrainArgs),
    /// Range-fetch latency and throughput over HTTP against raw SQLite BLOB reads.
    Loadtest(loadtest::LoadArgs),
    /// Read every chunk, check its checksum, decode every take and compare it with what was
    /// measured when it was stored; exits non-zero on anything wrong.
    Verify(archive::VerifyArgs),
    /// Write every take back to files: its frames in an open format and its exact bitstream,
    /// with a manifest (import reads it back into any store).
    Export(archive::ExportArgs),
    /// Store the takes of an export again, byte for byte (into SQLite or Postgres).
    Import(archive::ImportArgs),
    /// API tokens, on the database itself: create (the secret is shown once), list, revoke.
    Token(token::TokenArgs),
    /// The audit log: every write, delete, basis training and token change, newest first.
    Audit(token::AuditArgs),
}

#[derive(Args)]
struct ServeArgs {
    /// Address to listen on.
    #[arg(long, env = "MOCAP_LISTEN", default_value = "127.0.0.1:8080")]
    listen: String,
    /// Database: a SQLite file (created with its tables if missing) or a postgres:// URL.
    #[arg(long, env = "DATABASE_URL", default_value = "sqlite://mocapstore.db")]
    database_url: String,
    /// Memory for decoded chunks kept between range requests, in MiB (0 turns it off).
    #[arg(long, env = "MOCAP_DECODED_CACHE_MIB", default_value_t = 256)]
    decoded_cache_mib: usize,
    /// Encode every candidate codec of every take in full, as if each were the first of its
    /// layout: slower, and the choice never leaves out a candidate that a layout's earlier
    /// takes say would lose.
    #[arg(long, env = "MOCAP_EXHAUSTIVE_CHOICE")]
    exhaustive_choice: bool,
    /// Serve on a non-loopback address although no token exists: anyone who reaches it may
    /// read, change and delete the archive. Without it, `serve` refuses to start so.
    #[arg(long, env = "MOCAP_INSECURE_NO_AUTH")]
    insecure_no_auth: bool,
    /// A web origin (https://viewer.example) whose pages may call the API (CORS); repeat
    /// for several. Writes from any other origin are refused.
    #[arg(
        long = "cors-origin",
        env = "MOCAP_CORS_ORIGINS",
        value_delimiter = ','
    )]
    cors_origins: Vec<String>,
    #[command(flatten)]
    limits: LimitArgs,
}

/// The tunable limits (every limit is explained in `src/limits.rs` and the README).
#[derive(Args)]
#[command(next_help_heading = "Limits")]
struct LimitArgs {
    /// Largest upload (POST /v1/sequences body), MiB: a larger Content-Length gets 413
    /// before the body is read.
    #[arg(long, env = "MOCAP_MAX_UPLOAD_MIB", default_value_t = 512)]
    max_upload_mib: u64,
    /// Request bodies held at once across the server, MiB; past it requests get 503 with
    /// Retry-After instead of memory.
    #[arg(long, env = "MOCAP_MAX_INFLIGHT_MIB", default_value_t = 1024)]
    max_inflight_mib: u64,
    /// Largest frames append to a live stream, MiB.
    #[arg(long, env = "MOCAP_MAX_APPEND_MIB", default_value_t = 64)]
    max_append_mib: u64,
    /// Points (markers, joints) in one take.
    #[arg(long, env = "MOCAP_MAX_POINTS", default_value_t = 10_000)]
    max_points: u64,
    /// Frames in one take.
    #[arg(long, env = "MOCAP_MAX_FRAMES", default_value_t = 20_000_000)]
    max_frames: u64,
    /// Frames × points in one take.
    #[arg(long, env = "MOCAP_MAX_SAMPLES", default_value_t = 200_000_000)]
    max_samples: u64,
    /// Nesting depth of a BVH hierarchy.
    #[arg(long, env = "MOCAP_MAX_DEPTH", default_value_t = 512)]
    max_depth: u64,
    /// Points in one live stream (each open stream holds 3 × points² basis values).
    #[arg(long, env = "MOCAP_MAX_STREAM_POINTS", default_value_t = 1_000)]
    max_stream_points: u64,
    /// Live streams open at once; past it, opening one gets 503 with Retry-After.
    #[arg(long, env = "MOCAP_MAX_OPEN_STREAMS", default_value_t = 32)]
    max_open_streams: u64,
    /// Requests per second each token may make, sustained (each address for anonymous
    /// requests beyond loopback); past it, 429 with Retry-After. 0: no limit.
    #[arg(long, env = "MOCAP_REQUESTS_PER_S", default_value_t = 200)]
    requests_per_s: u64,
    /// Requests a token may make at once above the sustained rate.
    #[arg(long, env = "MOCAP_REQUEST_BURST", default_value_t = 400)]
    request_burst: u64,
}

impl LimitArgs {
    fn limits(&self) -> mocapstore::limits::Limits {
        mocapstore::limits::Limits {
            upload_bytes: self.max_upload_mib << 20,
            inflight_bytes: self.max_inflight_mib << 20,
            append_bytes: self.max_append_mib << 20,
            points: self.max_points,
            frames: self.max_frames,
            samples: self.max_samples,
            hierarchy_depth: self.max_depth,
            stream_points: self.max_stream_points,
            open_streams: self.max_open_streams,
            requests_per_s: self.requests_per_s,
            request_burst: self.request_burst,
            ..mocapstore::limits::Limits::default()
        }
    }
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
    /// Read files whose data contradicts their header (cut short, values beyond any
    /// physical scale), with a warning, instead of refusing them.
    #[arg(long)]
    pub lenient: bool,
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
            lenient: self.lenient,
            ..Default::default()
        })
    }
}

/// Short paths to the motion layer for the subcommands.
mod mocapstore_motion {
    pub use mocapstore::motion::formats::ReadOptions;
    pub use mocapstore::motion::units::parse_unit;
}

pub fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        Command::Serve(args) => serve(args),
        Command::Inspect(args) => inspect::run(&args),
        Command::Convert(args) => convert::run(&args),
        Command::Bench(args) => bench::run(&args),
        Command::Ingest(args) => ingest::run(&args),
        Command::Fetch(args) => fetch::run(&args),
        Command::Loadtest(args) => loadtest::run(&args),
        Command::TrainBases(args) => train_bases::run(&args),
        Command::Streamtest(args) => streamtest::run(&args),
        Command::Verify(args) => archive::verify(&args),
        Command::Export(args) => archive::export(&args),
        Command::Import(args) => archive::import(&args),
        Command::Token(args) => token::run(&args),
        Command::Audit(args) => token::audit(&args),
    }
}

fn serve(args: ServeArgs) -> ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| "info,tower_http=info,sqlx=warn".into()),
        )
        .init();
    let config = mocapstore::http::Config {
        listen: args.listen,
        database_url: args.database_url,
        limits: args.limits.limits(),
        decoded_cache_mib: args.decoded_cache_mib,
        exhaustive_choice: args.exhaustive_choice,
        policy: mocapstore::http::auth::Policy {
            allowed_origins: args.cors_origins,
            open_beyond_loopback: args.insecure_no_auth,
        },
        ..mocapstore::http::Config::default()
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
        let app = match mocapstore::http::Application::build(config).await {
            Ok(a) => a,
            Err(e) => {
                eprintln!("mocapstore serve: {e}");
                return ExitCode::FAILURE;
            }
        };
        tracing::info!(address = %app.local_addr(), %database, "mocapstore listening");
        match app.run_until(mocapstore::http::shutdown_signal()).await {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("mocapstore serve: {e}");
                ExitCode::FAILURE
            }
        }
    })
}
