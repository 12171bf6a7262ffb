//! `mocapstore train-bases --library L|--tag T|--layout H|--ids …`: ask a running service to
//! train a shared basis from a selection of its takes, follow the job with a progress bar,
//! and print the basis it stored.

use std::process::ExitCode;
use std::time::Duration;

use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::{json, Value};

#[derive(Args)]
pub struct TrainArgs {
    /// The service whose takes to train on.
    #[arg(long, env = "MOCAP_SERVER", default_value = "http://127.0.0.1:8080")]
    server: String,
    /// API token of a server that needs one (`mocapstore token create`).
    #[arg(long, env = "MOCAP_TOKEN", hide_env_values = true)]
    token: Option<String>,
    /// Basis kind.
    #[arg(long, default_value = "lsdt")]
    kind: String,
    #[arg(long)]
    library: Option<String>,
    #[arg(long)]
    tag: Option<String>,
    /// Layout signature (needed when the selection spans several layouts).
    #[arg(long)]
    layout: Option<String>,
    /// Exactly these takes, comma-separated ids.
    #[arg(long, value_delimiter = ',')]
    ids: Vec<String>,
    /// Non-zero coefficients per sample (the paper's P).
    #[arg(long)]
    sparsity: Option<usize>,
    #[arg(long)]
    max_iterations: Option<usize>,
    #[arg(long)]
    max_samples: Option<usize>,
}

pub fn run(args: &TrainArgs) -> ExitCode {
    let runtime = match tokio::runtime::Runtime::new() {
        Ok(r) => r,
        Err(e) => {
            eprintln!("mocapstore train-bases: {e}");
            return ExitCode::FAILURE;
        }
    };
    match runtime.block_on(train(args)) {
        Ok(basis) => {
            println!(
                "{}",
                serde_json::to_string_pretty(&basis).unwrap_or_default()
            );
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("mocapstore train-bases: {e}");
            ExitCode::FAILURE
        }
    }
}

async fn train(args: &TrainArgs) -> Result<Value, String> {
    let client = super::token::client(args.token.as_deref())?;
    let base = args.server.trim_end_matches('/');
    let mut body = json!({ "kind": args.kind });
    let fields = [
        ("library", args.library.clone().map(Value::from)),
        ("tag", args.tag.clone().map(Value::from)),
        ("layout", args.layout.clone().map(Value::from)),
        ("sparsity", args.sparsity.map(Value::from)),
        ("max_iterations", args.max_iterations.map(Value::from)),
        ("max_samples", args.max_samples.map(Value::from)),
    ];
    for (k, v) in fields {
        if let Some(v) = v {
            body[k] = v;
        }
    }
    if !args.ids.is_empty() {
        body["ids"] = json!(args.ids);
    }
    let r = client
        .post(format!("{base}/v1/bases"))
        .json(&body)
        .send()
        .await
        .map_err(|e| format!("{base}: {e}"))?;
    let status = r.status();
    let job: Value = r.json().await.map_err(|e| e.to_string())?;
    if status.as_u16() != 202 {
        return Err(format!(
            "{status}: {}",
            job["error"]["message"].as_str().unwrap_or("no message")
        ));
    }
    let id = job["id"].as_str().ok_or("the service sent no job id")?;
    let bar = ProgressBar::new(1000);
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {elapsed} {wide_msg}").map_err(|e| e.to_string())?,
    );
    loop {
        let job: Value = client
            .get(format!("{base}/v1/jobs/{id}"))
            .send()
            .await
            .and_then(|r| r.error_for_status())
            .map_err(|e| e.to_string())?
            .json()
            .await
            .map_err(|e| e.to_string())?;
        bar.set_position((job["progress"].as_f64().unwrap_or(0.0) * 1000.0) as u64);
        bar.set_message(job["message"].as_str().unwrap_or("").to_string());
        match job["state"].as_str() {
            Some("succeeded") => {
                bar.finish_and_clear();
                return Ok(job["result"].clone());
            }
            Some("failed") => {
                bar.finish_and_clear();
                return Err(job["error"].as_str().unwrap_or("failed").to_string());
            }
            _ => tokio::time::sleep(Duration::from_millis(200)).await,
        }
    }
}
