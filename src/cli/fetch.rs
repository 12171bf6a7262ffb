//! `mocapstore fetch ID OUT --server URL`: any range of a stored take to a file, in the
//! format of the file's extension (or `--to`). The service writes it — a BVH through the
//! same writer as `convert` and `export` — so what the file holds is what any client of the
//! API gets.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;

#[derive(Args)]
pub struct FetchArgs {
    /// The take's id.
    id: String,
    /// The file to write (its extension names the format: bvh, json, csv, npy, trc, f32).
    out: PathBuf,
    /// The service to fetch from.
    #[arg(long, env = "MOCAP_SERVER", default_value = "http://127.0.0.1:8080")]
    server: String,
    /// API token of a server that needs one (`mocapstore token create`).
    #[arg(long, env = "MOCAP_TOKEN", hide_env_values = true)]
    token: Option<String>,
    /// The output format, when the extension does not say.
    #[arg(long)]
    to: Option<String>,
    /// First frame (default 0).
    #[arg(long)]
    start: Option<usize>,
    /// Frame after the last (default the take's end).
    #[arg(long)]
    end: Option<usize>,
    /// Start time in seconds (instead of --start).
    #[arg(long)]
    t0: Option<f64>,
    /// End time in seconds (instead of --end).
    #[arg(long)]
    t1: Option<f64>,
}

pub fn run(args: &FetchArgs) -> ExitCode {
    match fetch(args) {
        Ok(n) => {
            println!("wrote {} ({n} bytes)", args.out.display());
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("mocapstore fetch: {e}");
            ExitCode::FAILURE
        }
    }
}

fn fetch(args: &FetchArgs) -> Result<usize, String> {
    let format = match (&args.to, args.out.extension().and_then(|e| e.to_str())) {
        (Some(f), _) => f.clone(),
        (None, Some(ext)) => ext.to_ascii_lowercase(),
        (None, None) => {
            return Err(format!(
                "{}: no extension to name the format; give --to",
                args.out.display()
            ))
        }
    };
    let mut query = vec![("format", format)];
    for (k, v) in [("start", args.start), ("end", args.end)] {
        if let Some(v) = v {
            query.push((k, v.to_string()));
        }
    }
    for (k, v) in [("t0", args.t0), ("t1", args.t1)] {
        if let Some(v) = v {
            query.push((k, v.to_string()));
        }
    }
    let url = format!(
        "{}/v1/takes/{}/frames",
        args.server.trim_end_matches('/'),
        args.id
    );
    let runtime = tokio::runtime::Runtime::new().map_err(|e| e.to_string())?;
    let body = runtime.block_on(async {
        let r = super::token::client(args.token.as_deref())?
            .get(&url)
            .query(&query)
            .send()
            .await
            .map_err(|e| format!("cannot reach the server: {e}"))?;
        let status = r.status();
        let body = r.bytes().await.map_err(|e| e.to_string())?;
        if !status.is_success() {
            let msg = super::token::error_message(&body);
            return Err(format!("take {}: {status}: {msg}", args.id));
        }
        Ok(body)
    })?;
    std::fs::write(&args.out, &body).map_err(|e| format!("{}: {e}", args.out.display()))?;
    Ok(body.len())
}
