//! `mocapstore stats --server URL`: a running service's statistics (`GET /v1/stats`): how
//! much motion its takes hold and what it costs stored, by codec and by library, and where
//! the database's bytes go (motion, records, indexes, free pages) table by table.

use std::process::ExitCode;

use clap::Args;
use serde_json::Value;

#[derive(Args)]
pub struct StatsArgs {
    /// Only this library's takes (the database's bytes are always the whole database's).
    #[arg(long)]
    library: Option<String>,
    /// Print the service's answer as JSON.
    #[arg(long)]
    json: bool,
    /// The service to ask.
    #[arg(long, env = "MOCAP_SERVER", default_value = "http://127.0.0.1:8080")]
    server: String,
    /// API token of a server that needs one (`mocapstore token create`).
    #[arg(long, env = "MOCAP_TOKEN", hide_env_values = true)]
    token: Option<String>,
}

pub fn run(args: &StatsArgs) -> ExitCode {
    match stats(args) {
        Ok(text) => {
            print!("{text}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("mocapstore stats: {e}");
            ExitCode::FAILURE
        }
    }
}

fn stats(args: &StatsArgs) -> Result<String, String> {
    let url = format!("{}/v1/stats", args.server.trim_end_matches('/'));
    let query: Vec<(&str, &str)> = args
        .library
        .iter()
        .map(|l| ("library", l.as_str()))
        .collect();
    let runtime = tokio::runtime::Runtime::new().map_err(|e| e.to_string())?;
    let answer: Value = runtime.block_on(async {
        let r = super::token::client(args.token.as_deref())?
            .get(&url)
            .query(&query)
            .send()
            .await
            .map_err(|e| format!("cannot reach the server at {}: {e}", args.server))?;
        let status = r.status();
        let bytes = r.bytes().await.map_err(|e| e.to_string())?;
        if !status.is_success() {
            return Err(format!("{status}: {}", super::token::error_message(&bytes)));
        }
        serde_json::from_slice(&bytes).map_err(|e| format!("the server's answer: {e}"))
    })?;
    if args.json {
        return Ok(format!("{answer:#}\n"));
    }
    Ok(render(&answer))
}

/// The answer as tables.
fn render(a: &Value) -> String {
    let int = |v: &Value| v.as_i64().unwrap_or(0);
    let mut out = String::from(
        "| takes | frames | raw bytes | stored bytes | ratio |\n|---|---:|---:|---:|---:|\n",
    );
    let row = |name: &str, t: &Value| {
        format!(
            "| {name} | {} | {} | {} | {:.1} |\n",
            int(&t["frames"]),
            int(&t["raw_bytes"]),
            int(&t["stored_bytes"]),
            t["ratio"].as_f64().unwrap_or(0.0)
        )
    };
    out += &row(&format!("all ({})", int(&a["total"]["takes"])), &a["total"]);
    for key in ["by_codec", "by_library"] {
        if let Some(m) = a[key].as_object() {
            for (name, t) in m {
                let name = if name.is_empty() {
                    "(no library)"
                } else {
                    name
                };
                out += &row(&format!("{name} ({})", int(&t["takes"])), t);
            }
        }
    }
    let s = &a["storage"];
    if s.is_null() {
        out += "\n(the database's bytes are shown to a caller who reaches every library)\n";
        return out;
    }
    let total = int(&s["total_bytes"]).max(1);
    let share = |n: i64| format!("{n} | {:.1}%", 100.0 * n as f64 / total as f64);
    out += &format!(
        "\n| the database | bytes | share |\n|---|---:|---:|\n| motion | {} |\n| records | {} |\n| \
         indexes | {} |\n| free pages | {} |\n| total | {total} | 100% |\n",
        share(int(&s["motion_bytes"])),
        share(int(&s["record_bytes"])),
        share(int(&s["index_bytes"])),
        match s["free_bytes"].as_i64() {
            Some(n) => share(n),
            None => "- | (not counted by this database) ".into(),
        },
    );
    out += "\n| table or index | holds | bytes | unused in its pages |\n|---|---|---:|---:|\n";
    for o in s["objects"].as_array().into_iter().flatten() {
        out += &format!(
            "| {} | {} | {} | {} |\n",
            o["name"].as_str().unwrap_or("?"),
            o["holds"].as_str().unwrap_or("?"),
            int(&o["bytes"]),
            o["unused_bytes"]
                .as_i64()
                .map_or_else(|| "-".to_string(), |n| n.to_string())
        );
    }
    out
}
