//! Service configuration: `config.toml` (every key documented in the shipped file), overridden by
//! environment variables `VECTORFUSION_<SECTION>_<KEY>` (e.g. `VECTORFUSION_SERVER_BIND`), then by
//! command-line flags. Every setting has a default, so the service starts with no file at all.

use crate::models::ComputeDevice;
use crate::pipeline::{EncoderChoice, Limits, ModelDirs};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Configuration errors.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("cannot read config file {path}: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("invalid config: {0}")]
    Parse(String),
    #[error("invalid environment override {var}: {reason}")]
    Env { var: String, reason: String },
    #[error("invalid setting {key}: {reason}")]
    Invalid { key: &'static str, reason: String },
}

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Config {
    pub server: ServerConfig,
    pub database: DatabaseConfig,
    pub queue: QueueConfig,
    pub limits: Limits,
    pub models: ModelsConfig,
    pub log: LogConfig,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ServerConfig {
    pub bind: String,
    /// The operator's key (sees every job, reads /metrics); empty with no tenants: no auth.
    pub api_key: String,
    /// When set, `/metrics` needs this key (and no other).
    pub metrics_key: String,
    /// Tenants: each key sees only its own jobs (`server::tenant`).
    pub tenants: Vec<TenantConfig>,
    pub max_body_bytes: usize,
    /// Bytes of uploads (images, starting SVGs) the active jobs may hold in the store together;
    /// a submit past it gets 429 `upload_quota_exceeded`.
    pub max_stored_upload_bytes: u64,
    /// Open connections at most; further connections are closed at once.
    pub max_connections: usize,
    /// Seconds a connection may take to send a request's headers (also the keep-alive idle
    /// limit: the clock starts when the connection waits for its next request).
    pub header_read_timeout_secs: u64,
    /// Seconds a submit may take to send its body; slower gets 408 `body_timeout`.
    pub body_read_timeout_secs: u64,
    pub max_queue_depth: i64,
    /// Uploads (PNG/JPEG, SVG) validated at once; more wait up to 10 s, then get 429 `busy`.
    pub max_concurrent_decodes: usize,
    /// Event streams open at once; more get 429 `busy`.
    pub max_sse_streams: usize,
    pub sse_heartbeat_secs: u64,
    pub progress_interval_ms: u64,
    pub snapshot_interval_ms: u64,
    pub shutdown_grace_secs: u64,
}

/// One `[[server.tenants]]` entry.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TenantConfig {
    /// 1–64 of `A-Z a-z 0-9 . _ -`, unique.
    pub name: String,
    /// At least 16 characters, unique among all keys.
    pub key: String,
    /// Queued + running jobs at most; 0: no cap.
    #[serde(default)]
    pub max_active_jobs: u32,
    /// Bytes of its active jobs' uploads at most; 0: only the server's cap.
    #[serde(default)]
    pub max_upload_bytes: u64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DatabaseConfig {
    /// The SQLite file, when `url` is empty.
    pub path: PathBuf,
    /// `postgres://…` for a PostgreSQL queue shared by many nodes (or `sqlite://PATH`); empty:
    /// the SQLite file at `path`. Env: `VECTORFUSION_DATABASE_URL`.
    pub url: String,
    /// Connections per pool (SQLite: the reader pool; PostgreSQL: each of the two pools).
    pub max_connections: u32,
}

impl DatabaseConfig {
    /// The database this configuration names: `url` if set, else the file at `path`.
    pub fn location(&self) -> Result<crate::store::DbLocation, crate::store::LocationError> {
        if self.url.trim().is_empty() {
            Ok(crate::store::DbLocation::Sqlite(self.path.clone()))
        } else {
            crate::store::DbLocation::parse(&self.url)
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct QueueConfig {
    pub workers: usize,
    pub lease_secs: u64,
    pub heartbeat_secs: u64,
    pub poll_interval_ms: u64,
    pub max_attempts: u32,
    /// Attempts lost with their worker (crash, OOM kill) after which a job fails as `poison`.
    pub max_lost_attempts: u32,
    pub retry_backoff_ms: u64,
    pub retry_backoff_max_ms: u64,
    pub checkpoint_every_steps: u32,
    pub max_snapshots_per_job: u32,
    pub retention_hours: u64,
    pub prune_interval_secs: u64,
    /// `process`: each job runs in a child process of the server (`worker::isolate`) under
    /// `job_memory_mb` and `job_wall_secs`; `thread`: on the worker thread, in the server.
    pub isolation: String,
    /// Resident memory of one job process, in MiB; past it the job fails `resource_limit`.
    /// 0: no limit.
    pub job_memory_mb: u64,
    /// Running time of one job process, in seconds; past it the job fails `resource_limit`.
    /// 0: no limit.
    pub job_wall_secs: u64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ModelsConfig {
    /// Empty = the embedded default model, if present.
    pub sd_dir: String,
    pub clip_dir: String,
    /// TAESD for the SDS encoder; empty = a `taesd/` folder in or beside `sd_dir`.
    pub taesd_dir: String,
    /// `auto`, `vae` or `taesd`.
    pub encoder: String,
    /// `cpu`, `cuda` or `cuda:N` (CUDA needs a build with the `cuda` feature).
    pub device: String,
}

impl Default for ModelsConfig {
    fn default() -> Self {
        ModelsConfig {
            sd_dir: String::new(),
            clip_dir: String::new(),
            taesd_dir: String::new(),
            encoder: "auto".into(),
            device: "cpu".into(),
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LogConfig {
    /// `text` or `json`.
    pub format: String,
    /// A tracing filter, e.g. `info` or `vectorfusion=debug,info`.
    pub level: String,
}

impl Default for ServerConfig {
    fn default() -> Self {
        ServerConfig {
            bind: "127.0.0.1:8080".into(),
            api_key: String::new(),
            metrics_key: String::new(),
            tenants: Vec::new(),
            max_body_bytes: 16 * 1024 * 1024,
            max_stored_upload_bytes: 1 << 30,
            max_connections: 1024,
            header_read_timeout_secs: 10,
            body_read_timeout_secs: 30,
            max_queue_depth: 1000,
            max_concurrent_decodes: 2,
            max_sse_streams: 256,
            sse_heartbeat_secs: 15,
            progress_interval_ms: 250,
            snapshot_interval_ms: 1000,
            shutdown_grace_secs: 20,
        }
    }
}

impl Default for DatabaseConfig {
    fn default() -> Self {
        DatabaseConfig {
            path: PathBuf::from("vectorfusion.db"),
            url: String::new(),
            max_connections: 8,
        }
    }
}

impl Default for QueueConfig {
    fn default() -> Self {
        QueueConfig {
            workers: 2,
            lease_secs: 30,
            heartbeat_secs: 5,
            poll_interval_ms: 250,
            max_attempts: 3,
            max_lost_attempts: 2,
            retry_backoff_ms: 2000,
            retry_backoff_max_ms: 60_000,
            checkpoint_every_steps: 25,
            max_snapshots_per_job: 200,
            isolation: "process".into(),
            job_memory_mb: 12 * 1024,
            job_wall_secs: 2 * 3600,
            retention_hours: 168,
            prune_interval_secs: 3600,
        }
    }
}

impl Default for LogConfig {
    fn default() -> Self {
        LogConfig {
            format: "text".into(),
            level: "info".into(),
        }
    }
}

const ENV_PREFIX: &str = "VECTORFUSION_";

impl Config {
    /// Loads `path` (if given) over the defaults, then applies environment overrides.
    pub fn load(path: Option<&Path>) -> Result<Config, ConfigError> {
        let text = match path {
            Some(p) => std::fs::read_to_string(p).map_err(|source| ConfigError::Read {
                path: p.to_path_buf(),
                source,
            })?,
            None => String::new(),
        };
        Config::from_toml_and_env(&text, std::env::vars())
    }

    /// Parses TOML text and applies `VECTORFUSION_SECTION_KEY` overrides from `env`.
    pub fn from_toml_and_env(
        text: &str,
        env: impl IntoIterator<Item = (String, String)>,
    ) -> Result<Config, ConfigError> {
        let mut table: toml::Table =
            toml::from_str(text).map_err(|e| ConfigError::Parse(e.to_string()))?;
        let defaults = toml::Table::try_from(Config::default())
            .map_err(|e| ConfigError::Parse(e.to_string()))?;
        for (var, value) in env {
            let Some(rest) = var.strip_prefix(ENV_PREFIX) else {
                continue;
            };
            let rest = rest.to_ascii_lowercase();
            // find the section whose name is a prefix followed by `_`
            let found = defaults.iter().find_map(|(section, keys)| {
                let key = rest.strip_prefix(section.as_str())?.strip_prefix('_')?;
                let default = keys.as_table()?.get(key)?;
                Some((section.clone(), key.to_string(), default.clone()))
            });
            let Some((section, key, default)) = found else {
                // Not a setting (e.g. VECTORFUSION_TEST_*): ignore.
                continue;
            };
            let parsed = parse_like(&default, &value).map_err(|e| ConfigError::Env {
                var: var.clone(),
                reason: e.to_string(),
            })?;
            let entry = table
                .entry(section)
                .or_insert_with(|| toml::Value::Table(toml::Table::new()));
            match entry.as_table_mut() {
                Some(t) => {
                    t.insert(key, parsed);
                }
                None => {
                    return Err(ConfigError::Env {
                        var,
                        reason: "the config file has this section as a non-table".into(),
                    });
                }
            }
        }
        let cfg: Config = toml::Value::Table(table)
            .try_into()
            .map_err(|e: toml::de::Error| ConfigError::Parse(e.to_string()))?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// Checks value ranges that serde cannot.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.validate_storage()?;
        self.validate_service()?;
        self.validate_models()?;
        self.validate_keys()?;
        self.validate_streams()?;
        self.limits
            .validate()
            .map_err(|(key, reason)| ConfigError::Invalid { key, reason })
    }

    /// The address, the database and the queue's leases and attempts.
    fn validate_storage(&self) -> Result<(), ConfigError> {
        if self.server.bind.parse::<std::net::SocketAddr>().is_err() {
            return invalid("server.bind", "must be ADDR:PORT, e.g. 127.0.0.1:8080");
        }
        if let Err(e) = self.database.location() {
            return Err(ConfigError::Invalid {
                key: "database.url",
                reason: e.to_string(),
            });
        }
        if self.database.max_connections < 1 {
            return invalid("database.max_connections", "must be at least 1");
        }
        if self.queue.lease_secs == 0 || self.queue.heartbeat_secs == 0 {
            return invalid("queue.lease_secs", "lease and heartbeat must be positive");
        }
        if self.queue.heartbeat_secs >= self.queue.lease_secs {
            return invalid(
                "queue.heartbeat_secs",
                "must be shorter than queue.lease_secs (a lease must survive a heartbeat gap)",
            );
        }
        if self.queue.max_attempts == 0 {
            return invalid("queue.max_attempts", "must be at least 1");
        }
        if self.queue.max_lost_attempts == 0 {
            return invalid("queue.max_lost_attempts", "must be at least 1");
        }
        Ok(())
    }

    /// Logging, the queue depth, isolation, connections and upload sizes.
    fn validate_service(&self) -> Result<(), ConfigError> {
        if !matches!(self.log.format.as_str(), "text" | "json") {
            return invalid("log.format", "must be \"text\" or \"json\"");
        }
        if self.server.max_queue_depth < 1 {
            return invalid("server.max_queue_depth", "must be at least 1");
        }
        if !matches!(self.queue.isolation.as_str(), "process" | "thread") {
            return invalid("queue.isolation", "must be \"process\" or \"thread\"");
        }
        if self.server.max_connections < 1 {
            return invalid("server.max_connections", "must be at least 1");
        }
        if self.server.header_read_timeout_secs < 1 {
            return invalid("server.header_read_timeout_secs", "must be at least 1");
        }
        if self.server.body_read_timeout_secs < 1 {
            return invalid("server.body_read_timeout_secs", "must be at least 1");
        }
        if self.server.max_stored_upload_bytes < self.server.max_body_bytes as u64 {
            return invalid(
                "server.max_stored_upload_bytes",
                "must be at least server.max_body_bytes (one upload must fit)",
            );
        }
        Ok(())
    }

    /// The model encoder and device.
    fn validate_models(&self) -> Result<(), ConfigError> {
        if let Err(e) = self.models.encoder.parse::<EncoderChoice>() {
            return Err(ConfigError::Invalid {
                key: "models.encoder",
                reason: e.to_string(),
            });
        }
        if let Err(e) = ComputeDevice::parse_built(&self.models.device) {
            return Err(ConfigError::Invalid {
                key: "models.device",
                reason: e.to_string(),
            });
        }
        Ok(())
    }

    /// The API and metrics keys and the tenants: valid names, long keys, all different.
    fn validate_keys(&self) -> Result<(), ConfigError> {
        let mut keys: Vec<&str> = [&self.server.api_key, &self.server.metrics_key]
            .into_iter()
            .map(String::as_str)
            .filter(|k| !k.is_empty())
            .collect();
        let mut names = std::collections::HashSet::new();
        for t in &self.server.tenants {
            let ok_name = (1..=64).contains(&t.name.len())
                && t.name
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-'));
            if !ok_name || !names.insert(t.name.as_str()) {
                return invalid(
                    "server.tenants.name",
                    "must be 1 to 64 of A-Z a-z 0-9 . _ - and unique",
                );
            }
            if t.key.trim().len() < 16 || t.key.trim() != t.key {
                return invalid(
                    "server.tenants.key",
                    "must be at least 16 characters without surrounding spaces",
                );
            }
            keys.push(&t.key);
        }
        let distinct: std::collections::HashSet<&str> = keys.iter().copied().collect();
        if distinct.len() != keys.len() {
            return invalid("server.tenants.key", "every key must be different");
        }
        Ok(())
    }

    /// SSE streams, concurrent decodes and the body size.
    fn validate_streams(&self) -> Result<(), ConfigError> {
        if self.server.max_sse_streams == 0 {
            return invalid("server.max_sse_streams", "must be at least 1");
        }
        if self.server.max_concurrent_decodes == 0 {
            return invalid("server.max_concurrent_decodes", "must be at least 1");
        }
        if self.server.max_body_bytes < 1024 {
            return invalid("server.max_body_bytes", "must be at least 1024");
        }
        Ok(())
    }

    /// The job limits (`[limits]`).
    pub fn limits(&self) -> Limits {
        self.limits.clone()
    }

    /// The configured model directories (no default applied: see
    /// [`ModelDirs::or_default_model`]).
    pub fn model_dirs(&self) -> ModelDirs {
        let opt = |s: &str| (!s.trim().is_empty()).then(|| PathBuf::from(s));
        ModelDirs {
            sd_dir: opt(&self.models.sd_dir),
            clip_dir: opt(&self.models.clip_dir),
            taesd_dir: opt(&self.models.taesd_dir),
            encoder: self.models.encoder.parse().unwrap_or_default(),
            device: self.models.device.parse().unwrap_or_default(),
            ..ModelDirs::default()
        }
    }
}

/// `Err(Invalid)` for `key`.
fn invalid(key: &'static str, reason: &str) -> Result<(), ConfigError> {
    Err(ConfigError::Invalid {
        key,
        reason: reason.into(),
    })
}

/// An environment override that is not of its setting's type.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("expected {expected}, got {value:?}")]
pub struct OverrideTypeError {
    /// What the setting takes: `an integer`, `a number`, `true or false`.
    pub expected: &'static str,
    pub value: String,
}

/// `value` read as the type of the setting whose default is `default`.
fn parse_like(default: &toml::Value, value: &str) -> Result<toml::Value, OverrideTypeError> {
    let wrong = |expected| OverrideTypeError {
        expected,
        value: value.to_string(),
    };
    let t = value.trim();
    Ok(match default {
        toml::Value::Integer(_) => {
            toml::Value::Integer(t.parse().map_err(|_| wrong("an integer"))?)
        }
        toml::Value::Float(_) => toml::Value::Float(t.parse().map_err(|_| wrong("a number"))?),
        toml::Value::Boolean(_) => {
            toml::Value::Boolean(t.parse().map_err(|_| wrong("true or false"))?)
        }
        _ => toml::Value::String(value.to_string()),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shipped_config_file_parses_to_the_defaults() {
        let text = include_str!("../config.toml");
        let cfg = Config::from_toml_and_env(text, Vec::new()).unwrap();
        assert_eq!(cfg, Config::default());
    }

    #[test]
    fn env_overrides_file_and_unknown_keys_are_rejected() {
        let cfg = Config::from_toml_and_env(
            "[queue]\nworkers = 3\n",
            vec![
                ("VECTORFUSION_QUEUE_WORKERS".to_string(), "5".to_string()),
                ("VECTORFUSION_SERVER_BIND".into(), "0.0.0.0:9000".into()),
                ("VECTORFUSION_DATABASE_PATH".into(), "/tmp/x.db".into()),
                ("VECTORFUSION_TEST_SOMETHING".into(), "ignored".into()),
                ("PATH".into(), "/bin".into()),
            ],
        )
        .unwrap();
        assert_eq!(cfg.queue.workers, 5);
        assert_eq!(cfg.server.bind, "0.0.0.0:9000");
        assert_eq!(cfg.database.path, PathBuf::from("/tmp/x.db"));
        let err = Config::from_toml_and_env(
            "",
            vec![("VECTORFUSION_QUEUE_WORKERS".into(), "many".into())],
        )
        .unwrap_err();
        assert!(
            err.to_string().contains("VECTORFUSION_QUEUE_WORKERS"),
            "{err}"
        );
        assert!(Config::from_toml_and_env("[queue]\nwrokers = 1\n", Vec::new()).is_err());
        // 0 workers: an API-only node.
        assert!(Config::from_toml_and_env("[queue]\nworkers = 0\n", Vec::new()).is_ok());
        let pg = Config::from_toml_and_env(
            "",
            vec![(
                "VECTORFUSION_DATABASE_URL".to_string(),
                "postgres://vf@db/vf".to_string(),
            )],
        )
        .unwrap();
        assert_eq!(
            pg.database.location().unwrap().backend(),
            crate::store::Backend::Postgres
        );
        let err = Config::from_toml_and_env("[database]\nurl = \"mysql://x/y\"\n", Vec::new())
            .unwrap_err();
        assert!(err.to_string().contains("database.url"), "{err}");
    }

    #[test]
    fn models_device_is_parsed_and_checked_against_the_build() {
        let env = |v: &str| vec![("VECTORFUSION_MODELS_DEVICE".to_string(), v.to_string())];
        let cfg = Config::from_toml_and_env("", env("cpu")).unwrap();
        assert_eq!(cfg.model_dirs().device, ComputeDevice::Cpu);
        let err = Config::from_toml_and_env("[models]\ndevice = \"tpu\"\n", Vec::new())
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("models.device") && err.contains("tpu"),
            "{err}"
        );
        let cuda = Config::from_toml_and_env("", env("cuda:1"));
        if cfg!(feature = "cuda") {
            assert_eq!(cuda.unwrap().model_dirs().device, ComputeDevice::Cuda(1));
        } else {
            let err = cuda.unwrap_err().to_string();
            assert!(err.contains("--features cuda"), "{err}");
        }
    }

    #[test]
    fn limits_load_from_the_config_and_max_paths_is_what_the_stages_can_run() {
        let cfg = Config::from_toml_and_env("[limits]\nmax_paths = 512\n", Vec::new()).unwrap();
        assert_eq!(cfg.limits().max_paths, 512);
        assert_eq!(cfg.limits().max_steps, Limits::default().max_steps);
        // Raising it past what LIVE and the pipeline accept would admit jobs the workers fail.
        let err = Config::from_toml_and_env("[limits]\nmax_paths = 5000\n", Vec::new())
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("limits.max_paths") && err.contains(&crate::scene::MAX_PATHS.to_string()),
            "{err}"
        );
        assert!(Config::from_toml_and_env("[limits]\nmax_steps = 0\n", Vec::new()).is_err());
        assert!(Config::from_toml_and_env("[limits]\nmax_pahts = 5\n", Vec::new()).is_err());
    }
}
