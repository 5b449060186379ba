//! Operations, one concern a file: Prometheus metrics (`metrics`), request ids and structured request logs
//! (`logging`), API keys, per-key rate limits and the wrong-key throttle (`auth`).

mod auth;
mod logging;
mod metrics;

pub use auth::*;
pub use logging::*;
pub use metrics::*;

use super::error::ApiError;
use super::jobs::Status;
use super::AppState;
use axum::extract::{MatchedPath, Request, State};
use axum::http::{header, HeaderValue};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use sha2::{Digest, Sha256};
use std::collections::{BTreeMap, HashMap};
use std::fmt::Write;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;
use std::time::Instant;
use subtle::ConstantTimeEq;
