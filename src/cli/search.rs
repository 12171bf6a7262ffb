//! `mocapstore search (--take ID | CLIP) --server URL`: the ranges of stored takes whose
//! motion is most like a range of a stored take or of a clip file, printed as a table (or
//! the service's JSON with `--json`). The service searches (`POST /v1/search`), so the
//! answer is what any client of the API gets.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;

#[derive(Args)]
pub struct SearchArgs {
    /// A clip to search with (any format ingest reads); or give --take.
    clip: Option<PathBuf>,
    /// A stored take to search with (its id), instead of a clip.
    #[arg(long, conflicts_with = "clip")]
    take: Option<String>,
    /// The query's range in seconds of its take or clip (default: all of it).
    #[arg(long)]
    t0: Option<f64>,
    #[arg(long)]
    t1: Option<f64>,
    /// Results to print.
    #[arg(short, default_value_t = 10)]
    k: usize,
    /// Results from one take (ranges that do not overlap).
    #[arg(long, default_value_t = 1)]
    per_take: usize,
    /// Search only this library's takes.
    #[arg(long)]
    library: Option<String>,
    /// Search only takes with this tag.
    #[arg(long)]
    tag: Option<String>,
    /// Search only takes with this label: key=value (repeat for several).
    #[arg(long = "label")]
    labels: Vec<String>,
    /// Print the service's answer as JSON.
    #[arg(long)]
    json: bool,
    /// The service to search.
    #[arg(long, env = "MOCAP_SERVER", default_value = "http://127.0.0.1:8080")]
    server: String,
    /// API token of a server that needs one (`mocapstore token create`).
    #[arg(long, env = "MOCAP_TOKEN", hide_env_values = true)]
    token: Option<String>,
}

pub fn run(args: &SearchArgs) -> ExitCode {
    match search(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("mocapstore search: {e}");
            ExitCode::FAILURE
        }
    }
}

fn search(args: &SearchArgs) -> Result<(), String> {
    let mut query: Vec<(String, String)> = vec![
        ("k".into(), args.k.to_string()),
        ("per_take".into(), args.per_take.to_string()),
    ];
    for (k, v) in [("t0", args.t0), ("t1", args.t1)] {
        if let Some(v) = v {
            query.push((k.into(), v.to_string()));
        }
    }
    for (k, v) in [
        ("library", &args.library),
        ("tag", &args.tag),
        ("take", &args.take),
    ] {
        if let Some(v) = v {
            query.push((k.into(), v.clone()));
        }
    }
    for l in &args.labels {
        let (k, v) = l
            .split_once('=')
            .ok_or_else(|| format!("--label {l:?}: give key=value"))?;
        query.push((format!("label.{k}"), v.to_string()));
    }
    let body = match (&args.clip, &args.take) {
        (Some(path), None) => {
            std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?
        }
        (None, Some(_)) => Vec::new(),
        _ => return Err("give a clip file or --take ID to search with".into()),
    };
    let url = format!("{}/v1/search", args.server.trim_end_matches('/'));
    let runtime = tokio::runtime::Runtime::new().map_err(|e| e.to_string())?;
    let answer: serde_json::Value = runtime.block_on(async {
        let r = super::token::client(args.token.as_deref())?
            .post(&url)
            .query(&query)
            .body(body)
            .send()
            .await
            .map_err(|e| format!("cannot reach the server at {}: {e}", args.server))?;
        let status = r.status();
        let bytes = r.bytes().await.map_err(|e| e.to_string())?;
        if !status.is_success() {
            let what = match (&args.clip, &args.take) {
                (Some(p), _) => p.display().to_string(),
                (_, Some(t)) => format!("take {t}"),
                _ => String::new(),
            };
            return Err(format!(
                "{what}: {status}: {}",
                super::token::error_message(&bytes)
            ));
        }
        serde_json::from_slice(&bytes).map_err(|e| format!("the server's answer: {e}"))
    })?;
    if args.json {
        println!("{answer:#}");
        return Ok(());
    }
    let q = &answer["query"];
    let s = &answer["searched"];
    println!(
        "query: {:.2}-{:.2} s ({} windows); searched {} takes ({} windows){}",
        q["t0"].as_f64().unwrap_or(0.0),
        q["t1"].as_f64().unwrap_or(0.0),
        q["windows"],
        s["takes"],
        s["windows"],
        match s["unindexed"].as_u64() {
            Some(n) if n > 0 => format!(", {n} not indexed yet"),
            _ => String::new(),
        }
    );
    println!(
        "{:>8}  {:>8}  {:>8}  {:<36}  name",
        "score", "t0 s", "t1 s", "take"
    );
    for r in answer["results"].as_array().into_iter().flatten() {
        println!(
            "{:>8.3}  {:>8.2}  {:>8.2}  {:<36}  {}",
            r["score"].as_f64().unwrap_or(f64::NAN),
            r["t0"].as_f64().unwrap_or(f64::NAN),
            r["t1"].as_f64().unwrap_or(f64::NAN),
            r["take"].as_str().unwrap_or(""),
            r["name"].as_str().unwrap_or("")
        );
    }
    Ok(())
}
