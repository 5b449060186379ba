//! `kac serve` configuration: every flag has an environment variable and a documented default, so the service
//! starts on a fresh machine with no configuration at all.

use clap::Args;
pub use kac_engine::config::{at_least_one, lease_seconds, seconds, EngineConfig, MAX_SECONDS};
use std::path::PathBuf;

#[derive(Args, Debug, Clone)]
pub struct Config {
    /// Address to listen on (port 0: any free port; the chosen address is printed on stdout).
    #[arg(long, env = "KAC_ADDR", default_value = "127.0.0.1:8080")]
    pub addr: String,
    /// Largest request body in bytes (uploads).
    #[arg(long, env = "KAC_MAX_BODY_BYTES", default_value_t = 256 * 1024 * 1024, value_parser = at_least_one)]
    pub max_body_bytes: usize,
    /// Seconds a client has to send a request's whole header (also the longest idle time of a kept-alive
    /// connection between requests); then the connection is closed.
    #[arg(long, env = "KAC_HEADER_READ_TIMEOUT_S", default_value_t = 10.0, value_parser = seconds)]
    pub header_read_timeout_s: f64,
    /// Longest pause, in seconds, while a request body is being sent; then 408 `body-timeout`.
    #[arg(long, env = "KAC_BODY_READ_TIMEOUT_S", default_value_t = 30.0, value_parser = seconds)]
    pub body_read_timeout_s: f64,
    /// Bytes all request bodies in flight may hold together (each reserves its Content-Length, or
    /// --max-body-bytes when it sends none); a body beyond it gets 503 `memory-busy` with Retry-After.
    #[arg(long, env = "KAC_MAX_BODY_MEMORY_BYTES", default_value_t = 1024 * 1024 * 1024, value_parser = at_least_one)]
    pub max_body_memory_bytes: usize,
    /// Slowest a request body may arrive, in bytes per second, once --body-read-timeout-s has passed since it
    /// began (0: no floor); a slower body gets 408 `body-timeout` and its connection is freed. With the default,
    /// the largest body allowed holds its reservation for at most about an hour.
    #[arg(long, env = "KAC_MIN_BODY_RATE_BYTES_PER_S", default_value_t = 65536)]
    pub min_body_rate_bytes_per_s: u64,
    /// Connections served at once; one more is answered 503 `too-many-connections` and closed.
    #[arg(long, env = "KAC_MAX_CONNECTIONS", default_value_t = 1024, value_parser = at_least_one)]
    pub max_connections: usize,
    /// Failed API-key attempts (missing or wrong key) one client address may make per minute; beyond it, 429
    /// `rate-limited` for that address until the minute is over (0: no throttling).
    #[arg(long, env = "KAC_AUTH_FAILURES_PER_MINUTE", default_value_t = 10)]
    pub auth_failures_per_minute: u32,
    /// Longest `wait` a synchronous request may ask for, in seconds.
    #[arg(long, env = "KAC_MAX_WAIT_S", default_value_t = 60, value_parser = clap::value_parser!(u64).range(0..=MAX_SECONDS as u64))]
    pub max_wait_s: u64,
    /// On SIGTERM, seconds to let running jobs finish before exiting (the rest are re-queued at the next start).
    #[arg(long, env = "KAC_SHUTDOWN_GRACE_S", default_value_t = 10, value_parser = clap::value_parser!(u64).range(0..=MAX_SECONDS as u64))]
    pub shutdown_grace_s: u64,
    /// API keys (comma-separated); when any is set, every /v1 request needs `Authorization: Bearer KEY`.
    /// Off by default.
    #[arg(long, env = "KAC_API_KEYS", value_delimiter = ',', hide_env_values = true, value_parser = api_key)]
    pub api_keys: Vec<String>,
    /// A file with one API key per line (added to --api-keys).
    #[arg(long, env = "KAC_API_KEYS_FILE")]
    pub api_keys_file: Option<PathBuf>,
    /// Origins of web front ends allowed to call the API from a browser (comma-separated, e.g.
    /// `https://app.example.org`, or `*` for any); none by default (same origin only).
    #[arg(long, env = "KAC_CORS_ORIGINS", value_delimiter = ',')]
    pub cors_origins: Vec<String>,
    /// Requests per minute each API key may make (0: unlimited); beyond it, 429 with Retry-After.
    #[arg(long, env = "KAC_RATE_LIMIT_PER_MINUTE", default_value_t = 0)]
    pub rate_limit_per_minute: u32,
    /// What the engine is given: the store, the workers and queue, the limits of analyses, the caches.
    #[command(flatten)]
    pub engine: EngineConfig,
}

/// An API key: 1 to 1,024 visible ASCII characters (what an `Authorization: Bearer` header can carry), no spaces.
pub fn api_key(s: &str) -> Result<String, String> {
    let k = s.trim();
    if k.is_empty() {
        return Err("an empty API key: give keys of visible ASCII characters, or no --api-keys at all".into());
    }
    if k.len() > 1024 {
        return Err(format!("an API key of {} characters: at most 1024", k.len()));
    }
    if let Some(c) = k.chars().find(|c| !c.is_ascii_graphic()) {
        return Err(format!(
            "an API key holds {c:?}: keys are visible ASCII characters without spaces (a bearer token)"
        ));
    }
    Ok(k.to_string())
}

/// A CORS origin: `*`, or `scheme://host[:port]` (http or https, no path, query or fragment), as a browser sends
/// it in `Origin`. Anything else stops the start (it would otherwise be dropped and match nothing, silently).
pub fn cors_origin(o: &str) -> Result<(), String> {
    let o = o.trim().trim_end_matches('/');
    if o == "*" {
        return Ok(());
    }
    let rest = o.strip_prefix("https://").or_else(|| o.strip_prefix("http://"));
    let ok = rest.is_some_and(|r| {
        !r.is_empty()
            && r.chars().all(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | ':' | '[' | ']'))
            && r.rsplit_once(':').is_none_or(|(h, p)| {
                !h.is_empty() && (p.parse::<u16>().is_ok() || h.ends_with(']') || r.starts_with('['))
            })
    });
    if ok {
        Ok(())
    } else {
        Err(format!(
            "--cors-origins {o:?}: give `*` or origins such as https://app.example.org or http://localhost:3000"
        ))
    }
}

impl Config {
    /// Every configured key (flag, environment, file). Fails closed: a keys file that is missing, unreadable, or
    /// holds no valid key, or any line of it that is not a valid key, is an error that stops the server at start
    /// (never a server open to everyone).
    pub fn api_keys(&self) -> Result<Vec<String>, String> {
        let mut keys: Vec<String> = self.api_keys.iter().map(|k| api_key(k)).collect::<Result<_, _>>()?;
        if let Some(path) = &self.api_keys_file {
            let text = std::fs::read_to_string(path)
                .map_err(|e| format!("--api-keys-file {}: cannot be read ({e})", path.display()))?;
            let before = keys.len();
            for (n, line) in text.lines().enumerate() {
                let line = line.trim();
                if line.is_empty() || line.starts_with('#') {
                    continue;
                }
                keys.push(
                    api_key(line).map_err(|e| format!("--api-keys-file {} line {}: {e}", path.display(), n + 1))?,
                );
            }
            if keys.len() == before {
                return Err(format!(
                    "--api-keys-file {}: holds no key (only blank lines and comments); the server does not start open",
                    path.display()
                ));
            }
        }
        Ok(keys)
    }

    /// Checks what no single flag's parser can: run at start, before anything is opened.
    pub fn check(&self) -> Result<(), String> {
        self.api_keys()?;
        if self.rate_limit_per_minute > 0 && self.api_keys()?.is_empty() {
            return Err("--rate-limit-per-minute counts requests per API key: configure keys too".into());
        }
        self.engine.check()?;
        for o in &self.cors_origins {
            cors_origin(o)?;
        }
        if self.max_body_memory_bytes < self.max_body_bytes {
            return Err(format!(
                "--max-body-memory-bytes {} is below --max-body-bytes {}: the largest body allowed could never be read",
                self.max_body_memory_bytes, self.max_body_bytes
            ));
        }
        Ok(())
    }
}
