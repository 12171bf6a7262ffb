//! Who may do what: API tokens (scopes, libraries, expiry, revocation), the authentication of
//! a request's bearer secret, and the audit log of every change.
//!
//! # Tokens
//! A token is a random 256-bit secret (`mcs_` and 64 hex digits, the prefix so that secret
//! scanners and people can tell what leaked) shown once when it is created. The store keeps
//! only its BLAKE3 hash: the secrets are random, not passwords, so a slow password hash would
//! buy nothing, and a fast one lets every request be checked by one indexed lookup. A token
//! has a scope — `read` (list, fetch, stats), `write` (also ingest, edit, streams) or `admin`
//! (also delete, bases, skeletons, tokens, the audit log) — and may be limited to libraries
//! (read and write only; admin is over the whole archive).
//!
//! # When tokens are needed
//! As soon as any token exists (revoked ones included: revoking the last token must not open
//! the archive), every request but `/healthz` needs a valid one. Before that, the server
//! serves anyone who reaches it, which is safe only on a loopback address: `serve` refuses to
//! bind any other address without tokens unless told `--insecure-no-auth`.
//!
//! # Servers sharing a database
//! Lookups are cached for [`TOKEN_CACHE`] so that a range fetch does not pay a database
//! round trip; a token revoked through another server (or the CLI) stops working here within
//! that time, and at once on the server that revoked it.

use std::collections::{BTreeSet, HashMap};
use std::fmt;
use std::net::IpAddr;
use std::str::FromStr;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use serde::Serialize;

use super::budget::Holder;
use super::{now_ms, Error, Result};
use crate::limits::{
    AUDIT_FIELD_BYTES, AUDIT_REFUSED_KEYS, MAX_TOKEN_LIBRARIES, TOKEN_CACHE, TOKEN_CACHE_ENTRIES,
    TOKEN_LAST_USED_EVERY,
};
use crate::store::{AuditRow, Filter, Store, TokenRow};

/// What a token may do; each includes the ones before it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Scope {
    /// List, fetch and decode takes, statistics, bases and skeletons.
    Read,
    /// Also ingest, edit takes, open and feed live streams.
    Write,
    /// Also delete takes, train and delete bases, delete skeletons, manage tokens, read the
    /// audit log.
    Admin,
}

impl fmt::Display for Scope {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Scope::Read => "read",
            Scope::Write => "write",
            Scope::Admin => "admin",
        })
    }
}

impl FromStr for Scope {
    type Err = Error;
    fn from_str(s: &str) -> Result<Scope> {
        match s {
            "read" => Ok(Scope::Read),
            "write" => Ok(Scope::Write),
            "admin" => Ok(Scope::Admin),
            _ => Err(Error::InvalidRequest(format!(
                "scope {s:?}: expected read, write or admin"
            ))),
        }
    }
}

/// What a caller may do: a scope, over every library or only some.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Grant {
    pub scope: Scope,
    /// `None`: every library.
    pub libraries: Option<BTreeSet<String>>,
}

impl Grant {
    /// Everything: the server without tokens, and the operator's own CLI on the database.
    pub fn everything() -> Grant {
        Grant {
            scope: Scope::Admin,
            libraries: None,
        }
    }

    /// `Forbidden` unless the grant reaches `scope`.
    pub fn require(&self, scope: Scope) -> Result<()> {
        if self.scope >= scope {
            Ok(())
        } else {
            Err(Error::Forbidden(format!(
                "this needs a {scope} token; this token's scope is {}",
                self.scope
            )))
        }
    }

    /// `Forbidden` unless the grant reaches `library`.
    pub fn library(&self, library: &str) -> Result<()> {
        match &self.libraries {
            Some(l) if !l.contains(library) => Err(Error::Forbidden(format!(
                "library {library:?} is outside this token's libraries ({})",
                l.iter().cloned().collect::<Vec<_>>().join(", ")
            ))),
            _ => Ok(()),
        }
    }

    /// The libraries a listing may show: `None` for all.
    pub fn within(&self) -> Option<Vec<String>> {
        self.libraries.as_ref().map(|l| l.iter().cloned().collect())
    }

    /// `filter`, narrowed to what the grant reaches.
    pub fn restrict(&self, filter: Filter) -> Filter {
        Filter {
            within: self.within(),
            ..filter
        }
    }

    /// The library a new take goes into: the one asked for (`""`: none, the default
    /// library), if the grant reaches it; with none asked for, the token's only library when
    /// it has exactly one.
    pub fn library_for_new(&self, asked: &str) -> Result<String> {
        let name = match &self.libraries {
            Some(l) if asked.is_empty() && l.len() == 1 => {
                l.iter().next().cloned().unwrap_or_default()
            }
            _ => asked.to_string(),
        };
        self.library(&name)?;
        Ok(name)
    }
}

/// `NotFound` unless take (or stream) `id` exists and `grant` reaches its library: a take
/// in another library answers as one that does not exist, so that a limited token learns
/// neither that the id exists nor which library holds it. A grant over every library costs
/// no lookup.
pub async fn check_take(store: &Store, grant: &Grant, id: &str) -> Result<()> {
    if grant.libraries.is_none() {
        return Ok(());
    }
    match store.library_of(id).await? {
        Some(library) if grant.library(&library).is_ok() => Ok(()),
        _ => Err(Error::NotFound(format!("take {id}"))),
    }
}

/// The token a request came with, as the audit log names it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct TokenRef {
    pub id: String,
    pub name: String,
}

/// An authenticated caller: its token (none when the server has no tokens) and its grant.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Caller {
    pub token: Option<TokenRef>,
    pub grant: Grant,
}

impl Caller {
    /// Anyone, on a server without tokens.
    pub fn anonymous() -> Caller {
        Caller {
            token: None,
            grant: Grant::everything(),
        }
    }
}

/// A token as the API and the CLI show it (never its secret or hash).
#[derive(Debug, Clone, PartialEq)]
pub struct TokenInfo {
    pub id: String,
    pub name: String,
    pub scope: Scope,
    /// `None`: every library.
    pub libraries: Option<Vec<String>>,
    pub created_at: i64,
    pub expires_at: Option<i64>,
    pub revoked_at: Option<i64>,
    /// When a request last presented it (to within [`TOKEN_LAST_USED_EVERY`]).
    pub last_used_at: Option<i64>,
}

/// A new token, with its secret: the only time the secret is seen.
#[derive(Debug, Clone)]
pub struct NewToken {
    pub info: TokenInfo,
    pub secret: String,
}

/// What to create.
#[derive(Debug, Clone, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TokenRequest {
    pub name: String,
    pub scope: String,
    #[serde(default)]
    pub libraries: Option<Vec<String>>,
    /// Milliseconds since the Unix epoch.
    #[serde(default)]
    pub expires_at: Option<i64>,
}

const SECRET_PREFIX: &str = "mcs_";

fn hash(secret: &str) -> [u8; 32] {
    *blake3::hash(secret.as_bytes()).as_bytes()
}

fn info_of(row: &TokenRow) -> Result<TokenInfo> {
    let corrupt = |what: &str| Error::Corrupt(format!("token {}: {what}", row.id));
    let scope = row
        .scope
        .parse::<Scope>()
        .map_err(|_| corrupt(&format!("scope {:?}", row.scope)))?;
    let libraries = row
        .libraries
        .as_deref()
        .map(serde_json::from_str::<Vec<String>>)
        .transpose()
        .map_err(|e| corrupt(&format!("libraries: {e}")))?;
    Ok(TokenInfo {
        id: row.id.clone(),
        name: row.name.clone(),
        scope,
        libraries,
        created_at: row.created_at,
        expires_at: row.expires_at,
        revoked_at: row.revoked_at,
        last_used_at: row.last_used_at,
    })
}

/// Create a token. A name taken already is a `Conflict`; an admin token cannot be limited to
/// libraries (it manages the whole archive), and an expiry must lie ahead.
pub async fn create_token(store: &Store, req: TokenRequest) -> Result<NewToken> {
    let name = req.name.trim();
    if name.is_empty() || name.len() > 100 {
        return Err(Error::InvalidRequest(
            "a token needs a name of 1 to 100 bytes".into(),
        ));
    }
    let scope = req.scope.parse::<Scope>()?;
    let libraries = match req.libraries {
        None => None,
        Some(_) if scope == Scope::Admin => {
            return Err(Error::InvalidRequest(
                "an admin token is over every library; give read or write to limit one".into(),
            ))
        }
        Some(l) => {
            let set: BTreeSet<String> = l.iter().map(|s| s.trim().to_string()).collect();
            if set.is_empty() || set.iter().any(String::is_empty) {
                return Err(Error::InvalidRequest(
                    "libraries must name at least one library, none empty".into(),
                ));
            }
            if set.len() > MAX_TOKEN_LIBRARIES {
                return Err(Error::InvalidRequest(format!(
                    "a token names at most {MAX_TOKEN_LIBRARIES} libraries"
                )));
            }
            Some(set.into_iter().collect::<Vec<_>>())
        }
    };
    let now = now_ms();
    if req.expires_at.is_some_and(|e| e <= now) {
        return Err(Error::InvalidRequest("expires_at lies in the past".into()));
    }
    let mut random = [0u8; 32];
    getrandom::fill(&mut random)
        .map_err(|e| Error::Internal(format!("no randomness for a token: {e}")))?;
    let secret = format!("{SECRET_PREFIX}{}", crate::codec::basis::hex(&random));
    let row = TokenRow {
        id: uuid::Uuid::now_v7().to_string(),
        name: name.to_string(),
        secret_hash: hash(&secret).to_vec(),
        scope: scope.to_string(),
        libraries: libraries
            .as_ref()
            .map(|l| serde_json::to_string(l).expect("strings serialise")),
        created_at: now,
        expires_at: req.expires_at,
        revoked_at: None,
        last_used_at: None,
    };
    store.insert_token(&row).await?;
    Ok(NewToken {
        info: info_of(&row)?,
        secret,
    })
}

/// Every token, without secrets.
pub async fn list_tokens(store: &Store) -> Result<Vec<TokenInfo>> {
    store.tokens().await?.iter().map(info_of).collect()
}

/// Revoke the token with this id or name.
pub async fn revoke_token(store: &Store, id_or_name: &str) -> Result<()> {
    if store.revoke_token(id_or_name, now_ms()).await? {
        Ok(())
    } else {
        Err(Error::NotFound(format!("live token {id_or_name:?}")))
    }
}

/// One entry for the audit log.
#[derive(Debug, Clone)]
pub struct Audit<'a> {
    pub caller: Option<&'a TokenRef>,
    pub action: String,
    pub target: String,
    pub status: u16,
    pub detail: String,
}

/// `text` cut to [`AUDIT_FIELD_BYTES`] (at a character boundary), saying how long it was.
fn clip(text: &str) -> String {
    if text.len() <= AUDIT_FIELD_BYTES {
        return text.to_string();
    }
    let mut end = AUDIT_FIELD_BYTES;
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    format!("{}… ({} bytes)", &text[..end], text.len())
}

/// Append one entry to the audit log (its free-text fields cut to [`AUDIT_FIELD_BYTES`]).
pub async fn record(store: &Store, a: Audit<'_>) -> Result<()> {
    store.audit(&row_of(a, now_ms(), 1)).await?;
    Ok(())
}

fn row_of(a: Audit<'_>, at: i64, count: i64) -> AuditRow {
    AuditRow {
        seq: 0,
        at,
        token_id: a.caller.map(|t| t.id.clone()),
        token_name: a.caller.map(|t| t.name.clone()),
        action: clip(&a.action),
        target: clip(&a.target),
        status: i64::from(a.status),
        detail: clip(&a.detail),
        count,
    }
}

/// The audit log of a server: a row for each request that changed something, and for
/// refused or failed ones (any status but 2xx) a count per caller, status and minute, with
/// the first one's action and target.
///
/// Why counts: every refused request was a row with its full path, twice, so 4.3 s of
/// refused POSTs with 65,000-character paths added 165 MB. Counted, a flood from one caller
/// adds a row a minute per status; from many addresses, at most [`AUDIT_REFUSED_KEYS`] rows
/// a minute and one for the rest. IPv6 addresses are counted by their /64, the block one
/// client holds.
#[derive(Debug, Default)]
pub struct AuditLog {
    counts: Mutex<HashMap<CountKey, Counted>>,
}

/// A request to audit, as the HTTP layer saw it.
#[derive(Debug, Clone)]
pub struct Attempt<'a> {
    pub caller: Option<&'a TokenRef>,
    pub address: IpAddr,
    /// `METHOD /route/{id}` (the route's template, or the path when none matched).
    pub action: String,
    pub path: &'a str,
    pub status: u16,
    pub detail: String,
}

#[derive(Debug, Clone, PartialEq, Eq, Hash)]
struct CountKey {
    minute: i64,
    /// A token's id, an address (a /64 for IPv6), or "others" past the key limit.
    who: String,
    status: u16,
}

#[derive(Debug)]
struct Counted {
    first: AuditRow,
    count: i64,
}

const MINUTE_MS: i64 = 60_000;

impl AuditLog {
    /// Record a request: a row now if it changed something (2xx), else a count.
    pub async fn note(&self, store: &Store, a: Attempt<'_>) -> Result<()> {
        let entry = Audit {
            caller: a.caller,
            action: a.action,
            target: a.path.to_string(),
            status: a.status,
            detail: a.detail,
        };
        if (200..300).contains(&a.status) {
            return record(store, entry).await;
        }
        let now = now_ms();
        let who = match a.caller {
            Some(t) => format!("token {}", t.id),
            None => Holder::address(a.address).to_string(),
        };
        let mut key = CountKey {
            minute: now - now.rem_euclid(MINUTE_MS),
            who,
            status: a.status,
        };
        let mut counts = self.counts.lock().expect("audit lock");
        if !counts.contains_key(&key) && counts.len() >= AUDIT_REFUSED_KEYS {
            key.who = "others".into();
        }
        let others = key.who == "others";
        counts
            .entry(key.clone())
            .or_insert_with(|| {
                let mut first = row_of(entry, key.minute, 0);
                if others {
                    first.token_id = None;
                    first.token_name = None;
                }
                Counted { first, count: 0 }
            })
            .count += 1;
        Ok(())
    }

    /// Write the counts of minutes that have ended (with `all`, every count so far: at
    /// shutdown, and before the log is read). Servers run this with their maintenance.
    pub async fn flush(&self, store: &Store, all: bool) -> Result<usize> {
        let now = now_ms();
        let minute = now - now.rem_euclid(MINUTE_MS);
        let done: Vec<(CountKey, Counted)> = {
            let mut counts = self.counts.lock().expect("audit lock");
            let keys: Vec<CountKey> = counts
                .keys()
                .filter(|k| all || k.minute < minute)
                .cloned()
                .collect();
            keys.into_iter()
                .filter_map(|k| counts.remove_entry(&k))
                .collect()
        };
        let n = done.len();
        let mut done = done.into_iter();
        while let Some((key, counted)) = done.next() {
            let mut row = counted.first.clone();
            row.count = counted.count;
            row.detail = clip(&format!(
                "{} request(s) from {} ended {} in the minute from {} (ms since the \
                 epoch); the target is the first's{}",
                counted.count,
                key.who,
                key.status,
                key.minute,
                if counted.first.detail.is_empty() {
                    String::new()
                } else {
                    format!("; {}", counted.first.detail)
                }
            ));
            if let Err(e) = store.audit(&row).await {
                // Not written: counted again, and written at the next flush.
                let mut counts = self.counts.lock().expect("audit lock");
                for (k, c) in std::iter::once((key, counted)).chain(done) {
                    counts
                        .entry(k)
                        .and_modify(|now| now.count += c.count)
                        .or_insert(c);
                }
                return Err(e.into());
            }
        }
        Ok(n)
    }

    /// Delete entries older than `retention`; how many.
    pub async fn prune(store: &Store, retention: std::time::Duration) -> Result<u64> {
        let before = now_ms().saturating_sub(retention.as_millis().min(i64::MAX as u128) as i64);
        Ok(store.prune_audit(before).await?)
    }
}

/// The audit log, newest first, `limit` entries before `before` (a `seq`).
pub async fn audit_log(store: &Store, before: Option<i64>, limit: usize) -> Result<Vec<AuditRow>> {
    Ok(store.audit_log(before, limit).await?)
}

/// How long a [`Authenticator::recheck`] that said yes is taken as said: half the time a
/// revocation may take to reach a server, so that a watch a caller may no longer see ends
/// within [`TOKEN_CACHE`] of the change (a watch asks every second).
pub const RECHECK_REUSE: std::time::Duration = std::time::Duration::from_millis(1_000);

/// A looked-up secret, parsed once: the caller it makes and when that stops, or none.
type Looked = Option<Arc<Known>>;

#[derive(Debug)]
struct Known {
    caller: Caller,
    name: String,
    expires_at: Option<i64>,
    revoked: bool,
}

/// Authenticates requests, caching what the store says for [`TOKEN_CACHE`].
#[derive(Debug)]
pub struct Authenticator {
    /// Whether tokens are needed, and when that was read.
    required: Mutex<Option<(Instant, bool)>>,
    /// Secret hash → token, and when it was read. Bounded: a flood of made-up secrets
    /// empties it rather than growing it.
    lookups: Mutex<HashMap<[u8; 32], (Instant, Looked)>>,
    /// Token id → when this server last wrote its `last_used_at`.
    touched: Mutex<HashMap<String, Instant>>,
    /// (token id, take id) → when a [`Authenticator::recheck`] last found the caller may
    /// still read the take: the watchers of one stream with one token cost one lookup a
    /// period, not one each.
    rechecked: Mutex<HashMap<(Option<String>, String), Instant>>,
}

impl Default for Authenticator {
    fn default() -> Self {
        Authenticator {
            required: Mutex::new(None),
            lookups: Mutex::new(HashMap::new()),
            touched: Mutex::new(HashMap::new()),
            rechecked: Mutex::new(HashMap::new()),
        }
    }
}

impl Authenticator {
    /// Whether requests need a token (any token exists).
    pub async fn required(&self, store: &Store) -> Result<bool> {
        if let Some((at, r)) = *self.required.lock().expect("auth cache") {
            // Once on, it stays on: tokens are never deleted.
            if r || at.elapsed() < TOKEN_CACHE {
                return Ok(r);
            }
        }
        let r = store.any_token().await?;
        *self.required.lock().expect("auth cache") = Some((Instant::now(), r));
        Ok(r)
    }

    /// Forget what was cached, after this server changed tokens.
    pub fn forget(&self) {
        *self.required.lock().expect("auth cache") = None;
        self.lookups.lock().expect("auth cache").clear();
    }

    /// The caller presenting `bearer` (the secret of an `Authorization: Bearer` header, if
    /// any): anonymous on a server without tokens, else `Unauthorized` unless the secret is
    /// a token's that is neither revoked nor expired.
    pub async fn authenticate(&self, store: &Store, bearer: Option<&str>) -> Result<Caller> {
        if !self.required(store).await? {
            return Ok(Caller::anonymous());
        }
        let Some(secret) = bearer else {
            return Err(Error::Unauthorized(
                "this server needs a token: send Authorization: Bearer <token>".into(),
            ));
        };
        let h = hash(secret);
        let cached = {
            let lookups = self.lookups.lock().expect("auth cache");
            lookups
                .get(&h)
                .filter(|(at, _)| at.elapsed() < TOKEN_CACHE)
                .map(|(_, t)| t.clone())
        };
        let known = match cached {
            Some(k) => k,
            None => {
                let k = match store.token_by_hash(&h).await? {
                    None => None,
                    Some(row) => {
                        let info = info_of(&row)?;
                        Some(Arc::new(Known {
                            caller: Caller {
                                token: Some(TokenRef {
                                    id: info.id,
                                    name: info.name.clone(),
                                }),
                                grant: Grant {
                                    scope: info.scope,
                                    libraries: info.libraries.map(|l| l.into_iter().collect()),
                                },
                            },
                            name: info.name,
                            expires_at: info.expires_at,
                            revoked: info.revoked_at.is_some(),
                        }))
                    }
                };
                let mut lookups = self.lookups.lock().expect("auth cache");
                if lookups.len() >= TOKEN_CACHE_ENTRIES {
                    lookups.clear();
                }
                lookups.insert(h, (Instant::now(), k.clone()));
                k
            }
        };
        let Some(known) = known else {
            return Err(Error::Unauthorized("unknown token".into()));
        };
        if known.revoked {
            return Err(Error::Unauthorized(format!(
                "token {:?} was revoked",
                known.name
            )));
        }
        if known.expires_at.is_some_and(|e| e <= now_ms()) {
            return Err(Error::Unauthorized(format!(
                "token {:?} has expired",
                known.name
            )));
        }
        if let Some(t) = &known.caller.token {
            self.touch(store, &t.id);
        }
        Ok(known.caller.clone())
    }

    /// Whether `caller`, authenticated a while ago, may still read take `id`: its token
    /// still valid (not revoked, not expired, read afresh from the store), the server still
    /// without tokens for a caller who came without one, and the take still in the
    /// token's libraries. What a long-lived answer (a stream's watch) asks again as it goes;
    /// the error says why not (`Unauthorized`, `NotFound`), or that the store could not be
    /// asked. A yes is remembered for [`RECHECK_REUSE`].
    pub async fn recheck(&self, store: &Store, caller: &Caller, id: &str) -> Result<()> {
        let key = (caller.token.as_ref().map(|t| t.id.clone()), id.to_string());
        let fresh = |at: &Instant| at.elapsed() < RECHECK_REUSE;
        if self
            .rechecked
            .lock()
            .expect("auth cache")
            .get(&key)
            .is_some_and(fresh)
        {
            return Ok(());
        }
        self.recheck_now(store, caller, id).await?;
        let mut rechecked = self.rechecked.lock().expect("auth cache");
        if rechecked.len() >= TOKEN_CACHE_ENTRIES {
            rechecked.clear();
        }
        rechecked.insert(key, Instant::now());
        Ok(())
    }

    async fn recheck_now(&self, store: &Store, caller: &Caller, id: &str) -> Result<()> {
        match &caller.token {
            None => {
                if store.any_token().await? {
                    return Err(Error::Unauthorized(
                        "this server needs a token now: send Authorization: Bearer <token>".into(),
                    ));
                }
            }
            Some(t) => {
                let row = store.token_by_id(&t.id).await?;
                let info = row.as_ref().map(info_of).transpose()?;
                match info {
                    None => return Err(Error::Unauthorized("unknown token".into())),
                    Some(i) if i.revoked_at.is_some() => {
                        return Err(Error::Unauthorized(format!(
                            "token {:?} was revoked",
                            i.name
                        )))
                    }
                    Some(i) if i.expires_at.is_some_and(|e| e <= now_ms()) => {
                        return Err(Error::Unauthorized(format!(
                            "token {:?} has expired",
                            i.name
                        )))
                    }
                    Some(_) => {}
                }
            }
        }
        check_take(store, &caller.grant, id).await
    }

    /// Write that token `id` was used, at most once per [`TOKEN_LAST_USED_EVERY`] per
    /// token and in the background: a request never waits on it.
    fn touch(&self, store: &Store, id: &str) {
        {
            let mut touched = self.touched.lock().expect("auth cache");
            if touched
                .get(id)
                .is_some_and(|at| at.elapsed() < TOKEN_LAST_USED_EVERY)
            {
                return;
            }
            if touched.len() >= TOKEN_CACHE_ENTRIES {
                touched.clear();
            }
            touched.insert(id.to_string(), Instant::now());
        }
        let (store, id) = (store.clone(), id.to_string());
        tokio::spawn(async move {
            if let Err(e) = store.touch_token(&id, now_ms()).await {
                tracing::warn!(token = %id, error = %e, "could not note a token's last use");
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limited(scope: Scope, libs: &[&str]) -> Grant {
        Grant {
            scope,
            libraries: Some(libs.iter().map(|s| s.to_string()).collect()),
        }
    }

    #[test]
    fn scopes_include_the_ones_below() {
        let g = limited(Scope::Write, &["a"]);
        assert!(g.require(Scope::Read).is_ok());
        assert!(g.require(Scope::Write).is_ok());
        assert!(matches!(g.require(Scope::Admin), Err(Error::Forbidden(_))));
        assert!(Grant::everything().require(Scope::Admin).is_ok());
    }

    #[test]
    fn libraries_limit_what_a_grant_reaches_and_where_new_takes_go() {
        let g = limited(Scope::Write, &["a"]);
        assert!(g.library("a").is_ok());
        assert!(matches!(g.library("b"), Err(Error::Forbidden(_))));
        assert_eq!(g.library_for_new("").unwrap(), "a");
        assert!(g.library_for_new("b").is_err());
        let two = limited(Scope::Write, &["a", "b"]);
        assert!(two.library_for_new("").is_err());
        assert_eq!(Grant::everything().library_for_new("").unwrap(), "");
        assert_eq!(Grant::everything().library_for_new("c").unwrap(), "c");
        assert_eq!(two.within(), Some(vec!["a".to_string(), "b".to_string()]));
    }

    #[test]
    fn secrets_hash_to_distinct_values_and_parse_scopes() {
        assert_ne!(hash("mcs_a"), hash("mcs_b"));
        assert_eq!("admin".parse::<Scope>().unwrap(), Scope::Admin);
        assert!("root".parse::<Scope>().is_err());
    }
}
