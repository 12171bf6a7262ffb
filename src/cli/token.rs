//! `mocapstore token create|list|revoke` and `mocapstore audit`: the operator's commands on
//! the database itself (the first admin token cannot come from a server that already needs
//! one). Every token change is written to the audit log as done by the CLI.

use mocapstore::dates::{civil_from_days, days_from_civil};
use std::process::ExitCode;

use clap::{Args, Subcommand};

use mocapstore::service::access::{self, Audit, TokenInfo, TokenRequest};
use mocapstore::store::Store;

#[derive(Args)]
pub struct TokenArgs {
    #[command(subcommand)]
    command: TokenCommand,
    /// The service's database: a SQLite file or a postgres:// URL.
    #[arg(
        long,
        env = "DATABASE_URL",
        default_value = "sqlite://mocapstore.db",
        global = true
    )]
    database_url: String,
}

#[derive(Subcommand)]
enum TokenCommand {
    /// Create a token and print its secret (shown this once; only its hash is stored).
    Create {
        /// Who or what holds it; shown in `token list` and the audit log.
        #[arg(long)]
        name: String,
        /// read (list, fetch, stats), write (also ingest, edit, streams) or admin (also
        /// delete, bases, tokens, audit).
        #[arg(long)]
        scope: String,
        /// Limit a read or write token to this library (repeat for several).
        #[arg(long = "library")]
        libraries: Vec<String>,
        /// Expiry: a duration from now (90d, 12h, 30m) or a date (2027-01-31, midnight UTC).
        #[arg(long)]
        expires: Option<String>,
        /// Create it only if the database has no token yet, and print nothing otherwise (for
        /// first start-up scripts).
        #[arg(long)]
        first: bool,
    },
    /// List tokens (never their secrets).
    List,
    /// Revoke a token by id or name; it stops working within seconds on every server.
    Revoke { token: String },
}

#[derive(Args)]
pub struct AuditArgs {
    /// Entries to show, newest first.
    #[arg(long, default_value_t = 50)]
    limit: usize,
    /// The service's database: a SQLite file or a postgres:// URL.
    #[arg(long, env = "DATABASE_URL", default_value = "sqlite://mocapstore.db")]
    database_url: String,
}

fn runtime() -> Result<tokio::runtime::Runtime, String> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| e.to_string())
}

pub fn run(args: &TokenArgs) -> ExitCode {
    match runtime().and_then(|rt| rt.block_on(token(args))) {
        Ok(out) => {
            print!("{out}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("mocapstore token: {e}");
            ExitCode::FAILURE
        }
    }
}

pub fn audit(args: &AuditArgs) -> ExitCode {
    let run = async {
        let store = open(&args.database_url).await?;
        let limit = args.limit.clamp(1, mocapstore::limits::MAX_AUDIT_PAGE);
        let rows = access::audit_log(&store, None, limit)
            .await
            .map_err(|e| e.to_string())?;
        store.close().await;
        let mut out = String::from("| when (UTC) | token | action | target | status | count | detail |\n|---|---|---|---|---:|---:|---|\n");
        for r in rows {
            out += &format!(
                "| {} | {} | {} | {} | {} | {} | {} |\n",
                utc(r.at),
                r.token_name.as_deref().unwrap_or("—"),
                r.action,
                r.target,
                r.status,
                r.count,
                r.detail
            );
        }
        Ok::<_, String>(out)
    };
    match runtime().and_then(|rt| rt.block_on(run)) {
        Ok(out) => {
            print!("{out}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("mocapstore audit: {e}");
            ExitCode::FAILURE
        }
    }
}

async fn open(url: &str) -> Result<Store, String> {
    Store::open(url).await.map_err(|e| format!("{url}: {e}"))
}

/// Who ran the command, for the audit log.
fn operator() -> String {
    let user = std::env::var("USER")
        .or_else(|_| std::env::var("USERNAME"))
        .unwrap_or_else(|_| "unknown user".into());
    format!("by the CLI as {user}")
}

async fn token(args: &TokenArgs) -> Result<String, String> {
    let store = open(&args.database_url).await?;
    let out = match &args.command {
        TokenCommand::Create {
            name,
            scope,
            libraries,
            expires,
            first,
        } => {
            if *first
                && !access::list_tokens(&store)
                    .await
                    .map_err(|e| e.to_string())?
                    .is_empty()
            {
                store.close().await;
                return Ok(String::new());
            }
            let expires_at = expires
                .as_deref()
                .map(|e| expiry(e, mocapstore::service::now_ms()))
                .transpose()?;
            let req = TokenRequest {
                name: name.clone(),
                scope: scope.clone(),
                libraries: (!libraries.is_empty()).then(|| libraries.clone()),
                expires_at,
            };
            let result = access::create_token(&store, req).await;
            let (status, target) = match &result {
                Ok(t) => (201, t.info.id.clone()),
                Err(_) => (400, name.clone()),
            };
            record(&store, "token create", target, status).await;
            let t = result.map_err(|e| e.to_string())?;
            format!(
                "created {} token {:?} (id {}{}{})\n\
                 secret, shown this once: {}\n\
                 use it as:  export MOCAP_TOKEN={}   (the CLI's commands read it)\n\
                 or send:    Authorization: Bearer <secret>\n",
                t.info.scope,
                t.info.name,
                t.info.id,
                t.info
                    .libraries
                    .as_ref()
                    .map(|l| format!(", libraries {}", l.join(", ")))
                    .unwrap_or_default(),
                t.info
                    .expires_at
                    .map(|e| format!(", expires {}", utc(e)))
                    .unwrap_or_default(),
                t.secret,
                t.secret,
            )
        }
        TokenCommand::List => listing(
            &access::list_tokens(&store)
                .await
                .map_err(|e| e.to_string())?,
        ),
        TokenCommand::Revoke { token } => {
            let result = access::revoke_token(&store, token).await;
            record(
                &store,
                "token revoke",
                token.clone(),
                if result.is_ok() { 204 } else { 404 },
            )
            .await;
            result.map_err(|e| e.to_string())?;
            format!("revoked {token}\n")
        }
    };
    store.close().await;
    Ok(out)
}

async fn record(store: &Store, action: &str, target: String, status: u16) {
    let entry = Audit {
        caller: None,
        action: action.to_string(),
        target,
        status,
        detail: operator(),
    };
    if let Err(e) = access::record(store, entry).await {
        eprintln!("mocapstore token: could not write the audit log: {e}");
    }
}

fn listing(tokens: &[TokenInfo]) -> String {
    let mut out = String::from(
        "| id | name | scope | libraries | created (UTC) | expires | revoked | last used |\n|---|---|---|---|---|---|---|---|\n",
    );
    for t in tokens {
        out += &format!(
            "| {} | {} | {} | {} | {} | {} | {} | {} |\n",
            t.id,
            t.name,
            t.scope,
            t.libraries.as_ref().map_or("all".into(), |l| l.join(", ")),
            utc(t.created_at),
            t.expires_at.map_or("never".into(), utc),
            t.revoked_at.map_or("—".into(), utc),
            t.last_used_at.map_or("never".into(), utc),
        );
    }
    out
}

/// Milliseconds since the epoch as `YYYY-MM-DD hh:mm`.
fn utc(ms: i64) -> String {
    let (days, rem) = (ms.div_euclid(86_400_000), ms.rem_euclid(86_400_000));
    let (y, m, d) = civil_from_days(days);
    let minutes = rem / 60_000;
    format!(
        "{y:04}-{m:02}-{d:02} {:02}:{:02}",
        minutes / 60,
        minutes % 60
    )
}

/// `--expires`: `90d`, `12h`, `30m` from `now` (ms), or `YYYY-MM-DD` (midnight UTC).
fn expiry(text: &str, now: i64) -> Result<i64, String> {
    let t = text.trim();
    let bad =
        || format!("--expires {text:?}: give a duration (90d, 12h, 30m) or a date (2027-01-31)");
    if let Some((unit_ms, n)) = [("d", 86_400_000i64), ("h", 3_600_000), ("m", 60_000)]
        .iter()
        .find_map(|(u, ms)| t.strip_suffix(u).map(|n| (*ms, n)))
    {
        let n: i64 = n.parse().map_err(|_| bad())?;
        if !(1..=36_500 * 86_400_000 / unit_ms).contains(&n) {
            return Err(bad());
        }
        return Ok(now + n * unit_ms);
    }
    let parts: Vec<&str> = t.split('-').collect();
    let [y, m, d] = parts[..] else {
        return Err(bad());
    };
    let (y, m, d): (i64, i64, i64) = (
        y.parse().map_err(|_| bad())?,
        m.parse().map_err(|_| bad())?,
        d.parse().map_err(|_| bad())?,
    );
    if !(1970..=9999).contains(&y) || !(1..=12).contains(&m) || !(1..=31).contains(&d) {
        return Err(bad());
    }
    let days = days_from_civil(y, m, d);
    if civil_from_days(days) != (y, m, d) {
        return Err(bad());
    }
    Ok(days * 86_400_000)
}

/// A client for the service, sending `token` (if any) as a bearer token with every request.
/// The server's message in a JSON error body, else the body as text.
pub fn error_message(body: &[u8]) -> String {
    serde_json::from_slice::<serde_json::Value>(body)
        .ok()
        .and_then(|v| v["error"]["message"].as_str().map(str::to_string))
        .unwrap_or_else(|| String::from_utf8_lossy(body).into_owned())
}

pub fn client(token: Option<&str>) -> Result<reqwest::Client, String> {
    let mut headers = reqwest::header::HeaderMap::new();
    if let Some(t) = token.map(str::trim).filter(|t| !t.is_empty()) {
        let mut v = reqwest::header::HeaderValue::from_str(&format!("Bearer {t}"))
            .map_err(|_| "the token has characters a header cannot carry".to_string())?;
        v.set_sensitive(true);
        headers.insert(reqwest::header::AUTHORIZATION, v);
    }
    reqwest::Client::builder()
        .default_headers(headers)
        .build()
        .map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn expiries_parse_as_durations_or_dates() {
        assert_eq!(expiry("2d", 1_000).unwrap(), 1_000 + 2 * 86_400_000);
        assert_eq!(expiry("30m", 0).unwrap(), 1_800_000);
        assert_eq!(expiry("1970-01-02", 0).unwrap(), 86_400_000);
        assert_eq!(expiry("2027-01-31", 0).unwrap(), 1_801_353_600_000);
        for bad in [
            "",
            "soon",
            "0d",
            "-1h",
            "2027-02-30",
            "2027-13-01",
            "99999d",
        ] {
            assert!(expiry(bad, 0).is_err(), "{bad}");
        }
    }

    #[test]
    fn times_print_as_utc() {
        assert_eq!(utc(0), "1970-01-01 00:00");
        assert_eq!(utc(1_801_353_600_000 + 90 * 60_000), "2027-01-31 01:30");
    }
}
