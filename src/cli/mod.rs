//! The `mocapstore` command line. Each subcommand lives in its own module; this one only
//! parses arguments and dispatches.

use std::process::ExitCode;

use clap::{Args, Parser, Subcommand};

mod archive;
mod bench;
mod convert;
mod export;
mod fetch;
mod ingest;
mod inspect;
mod loadtest;
mod search;
mod stats;
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
    /// Find stored motion like a range of a stored take or of a clip file (a running
    /// service's `POST /v1/search`).
    Search(search::SearchArgs),
    /// A running service's statistics: what its takes cost stored, by codec and library,
    /// and where the database's bytes go (motion, records, indexes, free pages).
    Stats(stats::StatsArgs),
    /// Live-stream ingest over HTTP: frames/s sustained, capture-to-fetchable delay.
    Streamtest(streamtest::StreamArgs),
    /// Train a shared basis on a running service's takes (library, tag, layout or ids).
    TrainBases(train_bases::TrainArgs),
    /// Range-fetch latency and throughput over HTTP against raw SQLite BLOB reads.
    Loadtest(loadtest::LoadArgs),
    /// Read every chunk, check its checksum, decode every take and compare it with what was
    /// measured when it was stored; exits non-zero on anything wrong.
    Verify(archive::VerifyArgs),
    /// Write every take back to files: without --format, from the database, its frames in
    /// an open format and its exact bitstream with a manifest (import reads it back into any
    /// store); with --format (glb, c3d, bvh, …), from a running service, the files people
    /// open, with manifest.csv, resumable.
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
    /// Seconds a background job's lease lasts (5 at least): a server that has not renewed
    /// it for this long (it died) has its job run again by another server on the same
    /// database.
    #[arg(long, env = "MOCAP_JOB_LEASE_S", default_value_t = 30, value_parser = clap::value_parser!(u64).range(5..=3600))]
    job_lease_s: u64,
    /// Seconds a live stream's lease lasts (3 at least): a server that has not renewed it
    /// for this long (it died) has its stream taken over by the next request through
    /// another server on the same database, and closed after one more lease if none comes.
    #[arg(long, env = "MOCAP_STREAM_LEASE_S", default_value_t = 60, value_parser = clap::value_parser!(u64).range(3..=3600))]
    stream_lease_s: u64,
    /// Where the other servers on the same database reach this one (http://host:port), to
    /// forward to it the requests of the live streams it codes. Default: the --listen
    /// address (127.0.0.1 if that is 0.0.0.0): set it when servers run on several machines
    /// or containers.
    #[arg(long, env = "MOCAP_ADVERTISE_URL")]
    advertise_url: Option<String>,
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
    /// A host name requests to a server without tokens may name, besides loopback names
    /// (and IP addresses, with --insecure-no-auth); repeat for several, `*` for any. Other
    /// names are refused, so that a web page cannot reach the server through a name of
    /// its own that resolves to it (DNS rebinding).
    #[arg(long = "allow-host", env = "MOCAP_ALLOW_HOSTS", value_delimiter = ',')]
    allowed_hosts: Vec<String>,
    /// A reverse proxy (an address or a CIDR network, e.g. 10.0.0.0/8) whose
    /// `X-Forwarded-For` names the client: rate limits, budget shares and the audit count
    /// the client's address, not the proxy's; repeat for several. Without it the header is
    /// ignored.
    #[arg(
        long = "trusted-proxy",
        env = "MOCAP_TRUSTED_PROXIES",
        value_delimiter = ','
    )]
    trusted_proxies: Vec<String>,
    /// Also serve GET /metrics without a token on this address (for a Prometheus scraper
    /// on an internal network); on --listen, /metrics needs an admin token.
    #[arg(long, env = "MOCAP_METRICS_LISTEN")]
    metrics_listen: Option<String>,
    #[command(flatten)]
    limits: LimitArgs,
}

/// The tunable limits (every limit is explained in `src/limits.rs` and the README).
#[derive(Args)]
#[command(next_help_heading = "Limits")]
struct LimitArgs {
    /// Largest upload (POST /v1/takes body), MiB: a larger Content-Length gets 413
    /// before the body is read.
    #[arg(long, env = "MOCAP_MAX_UPLOAD_MIB", default_value_t = d().upload_bytes >> 20)]
    max_upload_mib: u64,
    /// Request bodies held at once across the server, MiB; past it requests get 503 with
    /// Retry-After instead of memory.
    #[arg(long, env = "MOCAP_MAX_INFLIGHT_MIB", default_value_t = d().inflight_bytes >> 20)]
    max_inflight_mib: u64,
    /// Largest frames append to a live stream, MiB.
    #[arg(long, env = "MOCAP_MAX_APPEND_MIB", default_value_t = d().append_bytes >> 20)]
    max_append_mib: u64,
    /// Points (markers, joints) in one take.
    #[arg(long, env = "MOCAP_MAX_POINTS", default_value_t = d().points)]
    max_points: u64,
    /// Frames in one take.
    #[arg(long, env = "MOCAP_MAX_FRAMES", default_value_t = d().frames)]
    max_frames: u64,
    /// Frames × points in one take.
    #[arg(long, env = "MOCAP_MAX_SAMPLES", default_value_t = d().samples)]
    max_samples: u64,
    /// Nesting depth of a BVH hierarchy.
    #[arg(long, env = "MOCAP_MAX_DEPTH", default_value_t = d().hierarchy_depth)]
    max_depth: u64,
    /// Analog values (rows × channels) in one take.
    #[arg(long, env = "MOCAP_MAX_ANALOG_SAMPLES", default_value_t = d().analog_samples)]
    max_analog_samples: u64,
    /// Points in one live stream (each open stream holds 3 × points² basis values).
    #[arg(long, env = "MOCAP_MAX_STREAM_POINTS", default_value_t = d().stream_points)]
    max_stream_points: u64,
    /// Live streams open at once; past it, opening one gets 503 with Retry-After.
    #[arg(long, env = "MOCAP_MAX_OPEN_STREAMS", default_value_t = d().open_streams)]
    max_open_streams: u64,
    /// Requests per second each token may make, sustained (each address for anonymous
    /// requests beyond loopback); past it, 429 with Retry-After. 0: no limit.
    #[arg(long, env = "MOCAP_REQUESTS_PER_S", default_value_t = d().requests_per_s)]
    requests_per_s: u64,
    /// Requests a token may make at once above the sustained rate.
    #[arg(long, env = "MOCAP_REQUEST_BURST", default_value_t = d().request_burst)]
    request_burst: u64,
    /// Of the in-flight budget, what one caller (a token, or an address without one) may
    /// hold across its uploads at once, MiB; alone, a caller may still send one upload of
    /// the full size.
    #[arg(long, env = "MOCAP_BODY_SHARE_MIB", default_value_t = d().body_share_bytes >> 20)]
    body_share_mib: u64,
    /// An upload from which nothing arrives for this many seconds gets 408 and is dropped.
    #[arg(long, env = "MOCAP_BODY_IDLE_S", default_value_t = d().body_idle.as_secs())]
    body_idle_s: u64,
    /// The largest range answer, frames × points.
    #[arg(long, env = "MOCAP_MAX_ANSWER_SAMPLES", default_value_t = d().answer_samples)]
    max_answer_samples: u64,
    /// Memory range answers hold at once across the server, MiB (each holds about one
    /// decoded chunk and its output, whatever the take's length); past it, 503.
    #[arg(long, env = "MOCAP_ANSWER_BUDGET_MIB", default_value_t = d().answer_bytes >> 20)]
    answer_budget_mib: u64,
    /// Of the answer budget, what one caller's answers may hold at once, MiB.
    #[arg(long, env = "MOCAP_ANSWER_SHARE_MIB", default_value_t = d().answer_share_bytes >> 20)]
    answer_share_mib: u64,
    /// Connections open at once; past it a new one gets 503 and is closed. With the
    /// database's files, the default fits a process allowed 1,024 files (`ulimit -n`).
    #[arg(long, env = "MOCAP_MAX_CONNECTIONS", default_value_t = d().connections)]
    max_connections: u64,
    /// Connections open at once from one client address.
    #[arg(long, env = "MOCAP_MAX_CONNECTIONS_PER_ADDRESS", default_value_t = d().connections_per_address)]
    max_connections_per_address: u64,
    /// Seconds a client has to send a request's headers.
    #[arg(long, env = "MOCAP_HEADER_TIMEOUT_S", default_value_t = d().header_timeout.as_secs())]
    header_timeout_s: u64,
    /// Seconds a connection may stay open with no request in progress.
    #[arg(long, env = "MOCAP_IDLE_TIMEOUT_S", default_value_t = d().idle_timeout.as_secs())]
    idle_timeout_s: u64,
    /// Seconds a client may read nothing of an answer before its connection is closed.
    #[arg(long, env = "MOCAP_SEND_TIMEOUT_S", default_value_t = d().send_timeout.as_secs())]
    send_timeout_s: u64,
    /// Live streams one caller may have open at once.
    #[arg(long, env = "MOCAP_MAX_STREAMS_PER_CALLER", default_value_t = d().streams_per_caller)]
    max_streams_per_caller: u64,
    /// Watchers one caller may have on one live stream at once.
    #[arg(long, env = "MOCAP_MAX_WATCHERS_PER_CALLER", default_value_t = d().watchers_per_caller)]
    max_watchers_per_caller: u64,
    /// How long audit entries are kept: days, or a number with d, h or m (`90d`, `12h`).
    #[arg(long, env = "MOCAP_AUDIT_RETENTION", default_value = "90d", value_parser = parse_retention)]
    audit_retention: std::time::Duration,
}

/// The default limits, which the flags' defaults quote.
fn d() -> mocapstore::limits::Limits {
    mocapstore::limits::Limits::default()
}

/// `90d`, `12h`, `30m`, or a number of days.
fn parse_retention(v: &str) -> Result<std::time::Duration, String> {
    let v = v.trim();
    let (n, unit) = match v.char_indices().last() {
        Some((i, c)) if c.is_ascii_alphabetic() => (&v[..i], c),
        _ => (v, 'd'),
    };
    let seconds = match unit {
        'd' => 86_400,
        'h' => 3_600,
        'm' => 60,
        _ => return Err(format!("{v:?}: give days, or a number with d, h or m")),
    };
    let n: u64 = n
        .parse()
        .map_err(|_| format!("{v:?}: give days, or a number with d, h or m"))?;
    if n == 0 {
        return Err("a retention of 0 would delete every entry as it is written".into());
    }
    Ok(std::time::Duration::from_secs(n.saturating_mul(seconds)))
}

/// Whole seconds, at least one (a timeout of 0 would close everything at once).
fn secs(s: u64) -> std::time::Duration {
    std::time::Duration::from_secs(s.max(1))
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
            analog_samples: self.max_analog_samples,
            stream_points: self.max_stream_points,
            open_streams: self.max_open_streams,
            requests_per_s: self.requests_per_s,
            request_burst: self.request_burst,
            body_share_bytes: self.body_share_mib << 20,
            body_idle: secs(self.body_idle_s),
            answer_samples: self.max_answer_samples,
            answer_bytes: self.answer_budget_mib << 20,
            answer_share_bytes: self.answer_share_mib << 20,
            connections: self.max_connections,
            connections_per_address: self.max_connections_per_address,
            header_timeout: secs(self.header_timeout_s),
            idle_timeout: secs(self.idle_timeout_s),
            send_timeout: secs(self.send_timeout_s),
            streams_per_caller: self.max_streams_per_caller,
            watchers_per_caller: self.max_watchers_per_caller,
            audit_retention: self.audit_retention,
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
        Command::Search(args) => search::run(&args),
        Command::Stats(args) => stats::run(&args),
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
    let trusted_proxies =
        match mocapstore::http::proxy::TrustedProxies::parse(&args.trusted_proxies) {
            Ok(t) => t,
            Err(e) => {
                eprintln!("error: {e}");
                return ExitCode::from(2);
            }
        };
    let config = mocapstore::http::Config {
        listen: args.listen,
        trusted_proxies,
        database_url: args.database_url,
        limits: args.limits.limits(),
        decoded_cache_mib: args.decoded_cache_mib,
        exhaustive_choice: args.exhaustive_choice,
        job_lease: std::time::Duration::from_secs(args.job_lease_s),
        stream_lease: std::time::Duration::from_secs(args.stream_lease_s),
        advertise_url: args.advertise_url,
        metrics_listen: args.metrics_listen,
        policy: mocapstore::http::auth::Policy {
            allowed_origins: args.cors_origins,
            open_beyond_loopback: args.insecure_no_auth,
            allowed_hosts: args.allowed_hosts,
        },
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
        // The build the codecs' hot loops run (`MOCAP_SCALAR=1` forces the plain one).
        let simd = mocapstore::codec::simd::path().name();
        tracing::info!(address = %app.local_addr(), %database, simd, "mocapstore listening");
        if let Some(m) = app.metrics_addr() {
            tracing::info!(address = %m, "GET /metrics without a token");
        }
        match app.run_until(mocapstore::http::shutdown_signal()).await {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("mocapstore serve: {e}");
                ExitCode::FAILURE
            }
        }
    })
}
