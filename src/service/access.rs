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
use std::str::FromStr;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use serde::Serialize;

use super::{now_ms, Error, Result};
use crate::limits::{MAX_TOKEN_LIBRARIES, TOKEN_CACHE, TOKEN_CACHE_ENTRIES};
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

/// `Forbidden` unless `grant` reaches the library of take (or stream) `id`; `NotFound` if
/// there is no such take. A grant over every library costs no lookup.
pub async fn check_take(store: &Store, grant: &Grant, id: &str) -> Result<()> {
    if grant.libraries.is_none() {
        return Ok(());
    }
    let library = store
        .library_of(id)
        .await?
        .ok_or_else(|| Error::NotFound(format!("sequence {id}")))?;
    grant.library(&library)
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
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TokenInfo {
    pub id: String,
    pub name: String,
    pub scope: Scope,
    /// `None`: every library.
    pub libraries: Option<Vec<String>>,
    pub created_at: i64,
    pub expires_at: Option<i64>,
    pub revoked_at: Option<i64>,
}

/// A new token, with its secret: the only time the secret is seen.
#[derive(Debug, Clone, Serialize)]
pub struct NewToken {
    #[serde(flatten)]
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

/// Append to the audit log.
pub async fn record(store: &Store, a: Audit<'_>) -> Result<()> {
    store
        .audit(&AuditRow {
            seq: 0,
            at: now_ms(),
            token_id: a.caller.map(|t| t.id.clone()),
            token_name: a.caller.map(|t| t.name.clone()),
            action: a.action,
            target: a.target,
            status: i64::from(a.status),
            detail: a.detail,
        })
        .await?;
    Ok(())
}

/// The audit log, newest first, `limit` entries before `before` (a `seq`).
pub async fn audit_log(store: &Store, before: Option<i64>, limit: usize) -> Result<Vec<AuditRow>> {
    Ok(store.audit_log(before, limit).await?)
}

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
}

impl Default for Authenticator {
    fn default() -> Self {
        Authenticator {
            required: Mutex::new(None),
            lookups: Mutex::new(HashMap::new()),
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
        Ok(known.caller.clone())
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
