//! Who is calling: resolved once per request from its API key by [`super::routes::auth_and_count`]
//! and passed to the handlers as a request extension.
//!
//! - No key configured: a single-user server ([`Caller::Operator`]); every job is visible.
//! - `server.api_key`: the operator's key; it sees and cancels every job and reads `/metrics`.
//! - `[[server.tenants]]`: each key is a tenant; its jobs carry its name, and it sees, streams,
//!   downloads and cancels only those (another tenant's job is `404`, as if it did not exist).
//!   Idempotency keys are per tenant. `max_active_jobs` caps its queued + running jobs.
//! - `/metrics` needs `server.metrics_key` when set, else the operator's key; tenants never.

use crate::config::TenantConfig;

#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Caller {
    /// Sees every job; jobs it submits belong to no tenant.
    Operator,
    Tenant {
        name: String,
        /// Queued + running jobs at most (0: no cap).
        max_active_jobs: u32,
        /// Bytes of its active jobs' uploads at most (0: only the server's cap).
        max_upload_bytes: u64,
    },
}

impl Caller {
    pub fn from_config(t: &TenantConfig) -> Caller {
        Caller::Tenant {
            name: t.name.clone(),
            max_active_jobs: t.max_active_jobs,
            max_upload_bytes: t.max_upload_bytes,
        }
    }

    /// The tenant a submitted job belongs to, and the filter on listings.
    pub fn tenant(&self) -> Option<&str> {
        match self {
            Caller::Operator => None,
            Caller::Tenant { name, .. } => Some(name),
        }
    }

    /// Whether a job of `owner` exists for this caller.
    pub fn may_see(&self, owner: Option<&str>) -> bool {
        match self {
            Caller::Operator => true,
            Caller::Tenant { name, .. } => owner == Some(name.as_str()),
        }
    }

    /// The stored form of an `Idempotency-Key`: tenants' keys are prefixed by the tenant's
    /// name and a unit separator, which no header value can contain.
    pub fn scoped_key(&self, key: &str) -> String {
        match self {
            Caller::Operator => key.to_string(),
            Caller::Tenant { name, .. } => format!("{name}\u{1f}{key}"),
        }
    }
}

/// Compares without an early exit, so the time taken says nothing about the key.
pub fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// Who `given` (the request's key, if any) is; `None`: not authorised. `metrics` asks for the
/// `/metrics` endpoint, which tenants may not read.
pub fn resolve(
    cfg: &crate::config::ServerConfig,
    given: Option<&str>,
    metrics: bool,
) -> Option<Caller> {
    let given = given.map(str::trim);
    let is = |key: &str| {
        !key.is_empty() && given.is_some_and(|g| constant_time_eq(g.as_bytes(), key.as_bytes()))
    };
    if metrics && !cfg.metrics_key.is_empty() {
        return is(&cfg.metrics_key).then_some(Caller::Operator);
    }
    if cfg.api_key.is_empty() && cfg.tenants.is_empty() {
        return Some(Caller::Operator);
    }
    if is(&cfg.api_key) {
        return Some(Caller::Operator);
    }
    if metrics {
        return None;
    }
    // Every tenant key is compared, so the time taken does not say which matched.
    let mut found = None;
    for t in &cfg.tenants {
        if is(&t.key) && found.is_none() {
            found = Some(Caller::from_config(t));
        }
    }
    found
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::ServerConfig;

    fn cfg() -> ServerConfig {
        ServerConfig {
            api_key: "operator-key-0123456789".into(),
            metrics_key: String::new(),
            tenants: vec![
                TenantConfig {
                    name: "a".into(),
                    key: "tenant-a-key-0123456789".into(),
                    max_active_jobs: 0,
                    max_upload_bytes: 0,
                },
                TenantConfig {
                    name: "b".into(),
                    key: "tenant-b-key-0123456789".into(),
                    max_active_jobs: 3,
                    max_upload_bytes: 0,
                },
            ],
            ..ServerConfig::default()
        }
    }

    #[test]
    fn keys_resolve_to_callers() {
        let c = cfg();
        assert_eq!(
            resolve(&c, Some("operator-key-0123456789"), false),
            Some(Caller::Operator)
        );
        let b = resolve(&c, Some(" tenant-b-key-0123456789 "), false).unwrap();
        assert_eq!(b.tenant(), Some("b"));
        assert!(b.may_see(Some("b")) && !b.may_see(Some("a")) && !b.may_see(None));
        assert_eq!(resolve(&c, Some("nope"), false), None);
        assert_eq!(resolve(&c, None, false), None);
        // Tenants cannot read /metrics; the operator can, unless a metrics key is set.
        assert_eq!(resolve(&c, Some("tenant-a-key-0123456789"), true), None);
        assert_eq!(
            resolve(&c, Some("operator-key-0123456789"), true),
            Some(Caller::Operator)
        );
        let m = ServerConfig {
            metrics_key: "metrics-key-0123456789".into(),
            ..cfg()
        };
        assert_eq!(resolve(&m, Some("operator-key-0123456789"), true), None);
        assert_eq!(
            resolve(&m, Some("metrics-key-0123456789"), true),
            Some(Caller::Operator)
        );
        // No keys at all: a single-user server.
        assert_eq!(
            resolve(&ServerConfig::default(), None, false),
            Some(Caller::Operator)
        );
        assert_ne!(
            b.scoped_key("k"),
            resolve(&c, Some("tenant-a-key-0123456789"), false)
                .unwrap()
                .scoped_key("k")
        );
    }
}
