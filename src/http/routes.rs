//! The route table's builder: every route is declared once, with who may call it and its
//! handler, and both the router and the check made before any handler runs ([`require`])
//! come from that one declaration — so a route cannot be added without a scope, and a
//! route that names a take cannot forget to check the caller's libraries.

use std::collections::HashMap;
use std::sync::Arc;

use axum::extract::{MatchedPath, RawPathParams, Request, State};
use axum::handler::Handler;
use axum::http::Method;
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use axum::routing::{on, MethodFilter};
use axum::Router;

use super::auth::Route;
use super::error::ApiError;
use super::AppState;
use crate::service::access::{self, Caller, Scope};

/// Who may call a route.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Access {
    /// Anyone: health, readiness, the viewer's files.
    Public,
    /// A caller whose token has this scope.
    Scope(Scope),
    /// A caller whose token has this scope and whose libraries hold the take the route's
    /// `{id}` names; a take elsewhere answers 404, as one that does not exist
    /// ([`access::check_take`]).
    Take(Scope),
}

impl Access {
    /// The scope it needs, if any.
    pub fn scope(self) -> Option<Scope> {
        match self {
            Access::Public => None,
            Access::Scope(s) | Access::Take(s) => Some(s),
        }
    }
}

/// Older names of routes, kept so that clients written against them go on working: every
/// route declared under the first prefix answers under the second too, with the same access
/// and handler (docs/ARCHITECTURE.md, "Words": *sequence* was the API's word for a take).
pub const ALIASES: &[(&str, &str)] = &[("/v1/takes", "/v1/sequences")];

/// A route as declared: an alias's route named by the route it stands for (what logs,
/// metrics and the audit log say, whichever name a client used).
pub fn canonical(route: &str) -> String {
    for (current, older) in ALIASES {
        if let Some(rest) = route.strip_prefix(older) {
            return format!("{current}{rest}");
        }
    }
    route.to_string()
}

/// The older names a declared route also answers under ([`ALIASES`]).
fn aliases_of(path: &str) -> impl Iterator<Item = String> + '_ {
    ALIASES.iter().filter_map(move |(current, older)| {
        let rest = path.strip_prefix(current)?;
        (rest.is_empty() || rest.starts_with('/')).then(|| format!("{older}{rest}"))
    })
}

/// Every route's access: by path as the router matches it, then by method.
pub type Table = Arc<HashMap<String, Vec<(Method, Access)>>>;

/// Routes being declared.
pub struct Routes {
    router: Router<AppState>,
    table: HashMap<String, Vec<(Method, Access)>>,
}

impl Routes {
    pub fn new() -> Routes {
        Routes {
            router: Router::new(),
            table: HashMap::new(),
        }
    }

    /// Route `method path` (and its [`ALIASES`]) to `handler` for callers `access` lets in.
    /// Panics when the same method and path is declared twice (a mistake in the table, found
    /// by every test that builds a router).
    pub fn add<H, T>(
        mut self,
        method: Method,
        path: &'static str,
        access: Access,
        handler: H,
    ) -> Routes
    where
        H: Handler<T, AppState>,
        T: 'static,
    {
        let filter = MethodFilter::try_from(method.clone()).expect("a method the router routes");
        for path in std::iter::once(path.to_string()).chain(aliases_of(path)) {
            self.router = self.router.route(&path, on(filter, handler.clone()));
            let methods = self.table.entry(path.clone()).or_default();
            assert!(
                methods.iter().all(|(m, _)| *m != method),
                "{method} {path} is declared twice"
            );
            methods.push((method.clone(), access));
        }
        self
    }

    pub fn get<H: Handler<T, AppState>, T: 'static>(
        self,
        path: &'static str,
        access: Access,
        handler: H,
    ) -> Routes {
        self.add(Method::GET, path, access, handler)
    }

    pub fn post<H: Handler<T, AppState>, T: 'static>(
        self,
        path: &'static str,
        access: Access,
        handler: H,
    ) -> Routes {
        self.add(Method::POST, path, access, handler)
    }

    pub fn patch<H: Handler<T, AppState>, T: 'static>(
        self,
        path: &'static str,
        access: Access,
        handler: H,
    ) -> Routes {
        self.add(Method::PATCH, path, access, handler)
    }

    pub fn delete<H: Handler<T, AppState>, T: 'static>(
        self,
        path: &'static str,
        access: Access,
        handler: H,
    ) -> Routes {
        self.add(Method::DELETE, path, access, handler)
    }

    /// The router and the table [`require`] checks against.
    pub fn finish(self) -> (Router<AppState>, Table) {
        (self.router, Arc::new(self.table))
    }
}

/// The access a request needs: its route's, `HEAD` as `GET`. A method the route does not
/// declare never gets here (the router answers 405 before its route layer runs); were one
/// to, it would need read for a read and write otherwise, never nothing.
pub fn access_of(table: &Table, method: &Method, route: &str) -> Access {
    let read = *method == Method::GET || *method == Method::HEAD;
    let wanted = if read { &Method::GET } else { method };
    let mut declared = table.get(route).into_iter().flatten();
    declared.find(|(m, _)| m == wanted).map_or(
        Access::Scope(if read { Scope::Read } else { Scope::Write }),
        |(_, a)| *a,
    )
}

/// After routing, before the handler (and before its body is read): the route's scope
/// (403), and for a route that names a take, the caller's libraries (404).
pub async fn require(
    State((state, table)): State<(AppState, Table)>,
    params: RawPathParams,
    req: Request,
    next: Next,
) -> Response {
    let route = req
        .extensions()
        .get::<MatchedPath>()
        .map_or_else(|| req.uri().path().to_string(), |m| m.as_str().to_string());
    let access = access_of(&table, req.method(), &route);
    let allowed = check(&state, access, req.extensions().get::<Caller>(), &params).await;
    let mut response = match allowed {
        Ok(()) => next.run(req).await,
        Err(e) => e.into_response(),
    };
    response.extensions_mut().insert(Route(canonical(&route)));
    response
}

async fn check(
    state: &AppState,
    access: Access,
    caller: Option<&Caller>,
    params: &RawPathParams,
) -> Result<(), ApiError> {
    let Some(scope) = access.scope() else {
        return Ok(());
    };
    let caller = caller.ok_or_else(|| ApiError::unauthorized("no credentials were checked"))?;
    caller.grant.require(scope)?;
    if let Access::Take(_) = access {
        let id = params
            .iter()
            .find_map(|(k, v)| (k == "id").then_some(v))
            .ok_or_else(|| ApiError::bad_request("this route names no take"))?;
        access::check_take(&state.store, &caller.grant, id).await?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::limits::Limits;
    use crate::service::budget::Budget;

    fn table() -> Table {
        let limits = Limits::default();
        let bodies = Arc::new(Budget::new(limits.inflight_bytes, limits.body_share_bytes));
        super::super::declare(&bodies, &limits).finish().1
    }

    /// The scopes the README and the module docs of `auth` give.
    #[test]
    fn routes_need_the_scopes_the_docs_give() {
        let t = table();
        let s = |m: Method, r: &str| access_of(&t, &m, r).scope();
        assert_eq!(s(Method::GET, "/healthz"), None);
        assert_eq!(s(Method::HEAD, "/ui/{*path}"), None);
        assert_eq!(s(Method::GET, "/v1/takes/{id}/frames"), Some(Scope::Read));
        assert_eq!(s(Method::GET, "/metrics"), Some(Scope::Admin));
        assert_eq!(s(Method::POST, "/v1/takes"), Some(Scope::Write));
        assert_eq!(s(Method::PATCH, "/v1/takes/{id}"), Some(Scope::Write));
        assert_eq!(
            s(Method::POST, "/v1/streams/{id}/frames"),
            Some(Scope::Write)
        );
        assert_eq!(s(Method::DELETE, "/v1/takes/{id}"), Some(Scope::Admin));
        assert_eq!(s(Method::POST, "/v1/bases"), Some(Scope::Admin));
        assert_eq!(s(Method::GET, "/v1/bases"), Some(Scope::Read));
        assert_eq!(s(Method::GET, "/v1/tokens"), Some(Scope::Admin));
        assert_eq!(s(Method::GET, "/v1/audit"), Some(Scope::Admin));
        assert_eq!(s(Method::DELETE, "/v1/skeletons/{id}"), Some(Scope::Admin));
        // A method a route does not declare (the router answers 405 first): never public.
        assert_eq!(s(Method::PUT, "/v1/stats"), Some(Scope::Write));
    }

    /// Every route whose `{id}` is a take (a stored one, under either name, or a live
    /// stream's) checks the caller's libraries.
    #[test]
    fn every_route_that_names_a_take_checks_its_library() {
        let t = table();
        let mut takes = 0;
        for (path, methods) in t.iter() {
            let names_a_take = ["/v1/takes/{id}", "/v1/sequences/{id}", "/v1/streams/{id}"]
                .iter()
                .any(|p| path.starts_with(p));
            for (method, access) in methods {
                assert_eq!(
                    matches!(access, Access::Take(_)),
                    names_a_take,
                    "{method} {path}: {access:?}"
                );
                takes += usize::from(names_a_take);
            }
        }
        assert!(takes >= 11, "the take routes are in the table");
    }

    /// An older route name answers as its route does: the same methods and access, and is
    /// named by its route in logs; nothing else is renamed.
    #[test]
    fn older_route_names_answer_as_their_routes() {
        let t = table();
        let count = |prefix: &str| {
            let mut n = 0;
            for (path, methods) in t.iter() {
                if let Some(rest) = path.strip_prefix(prefix) {
                    if prefix == "/v1/sequences" {
                        let current = format!("/v1/takes{rest}");
                        assert_eq!(Some(methods), t.get(&current), "{path}");
                        assert_eq!(canonical(path), current);
                    }
                    n += methods.len();
                }
            }
            n
        };
        assert!(count("/v1/takes") >= 9);
        assert_eq!(
            count("/v1/sequences"),
            count("/v1/takes"),
            "every route, each method"
        );
        assert_eq!(canonical("/v1/takes/{id}"), "/v1/takes/{id}");
        assert_eq!(canonical("/v1/stats"), "/v1/stats");
        assert_eq!(aliases_of("/v1/takesx").count(), 0, "a whole segment only");
    }
}
