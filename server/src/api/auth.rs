//! Who may write and view: random scene ids and tokens, token checks, and the per-client
//! write rate limit.
//!
//! Tokens are 256-bit random hex strings from the OS generator, returned once at scene
//! creation; the store keeps only their SHA-256, compared in constant time. Scene ids are
//! 128-bit random hex, so they cannot be guessed or enumerated.

use crate::error::AppError;
use axum::http::{HeaderMap, StatusCode};
use sha2::{Digest, Sha256};
use std::collections::HashMap;
use std::net::IpAddr;
use std::sync::Mutex;
use std::time::Instant;

/// Hex SHA-256 of a token, as stored.
pub fn token_hash(token: &str) -> String {
    Sha256::digest(token.as_bytes())
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// The bearer token of a request, if any.
pub fn bearer(headers: &HeaderMap) -> Option<&str> {
    headers
        .get(axum::http::header::AUTHORIZATION)?
        .to_str()
        .ok()?
        .strip_prefix("Bearer ")
        .map(str::trim)
}

/// Checks that `presented` is one of the accepted tokens (given by their hashes).
pub fn require(
    presented: Option<&str>,
    accepted_hashes: &[&str],
    what: &str,
) -> Result<(), AppError> {
    let Some(token) = presented else {
        return Err(AppError::new(
            StatusCode::UNAUTHORIZED,
            "missing_token",
            format!("{what} needs a token: send `Authorization: Bearer <token>`"),
        )
        .field("Authorization"));
    };
    let hash = token_hash(token);
    if accepted_hashes
        .iter()
        .any(|h| constant_time_eq(h.as_bytes(), hash.as_bytes()))
    {
        Ok(())
    } else {
        Err(AppError::new(
            StatusCode::FORBIDDEN,
            "invalid_token",
            format!("the token does not allow {what}"),
        )
        .field("Authorization"))
    }
}

/// A token bucket per client address for write requests.
pub struct RateLimiter {
    rate_per_sec: f64,
    burst: f64,
    buckets: Mutex<HashMap<Option<IpAddr>, (f64, Instant)>>,
}

/// Buckets kept before idle ones are dropped.
const MAX_BUCKETS: usize = 10_000;

impl RateLimiter {
    pub fn new(rate_per_sec: f64, burst: u32) -> RateLimiter {
        RateLimiter {
            rate_per_sec,
            burst: f64::from(burst),
            buckets: Mutex::new(HashMap::new()),
        }
    }

    /// Takes one write from `client`'s bucket, or says how long to wait.
    pub fn check(&self, client: Option<IpAddr>) -> Result<(), AppError> {
        let now = Instant::now();
        let mut buckets = self.buckets.lock().unwrap_or_else(|e| e.into_inner());
        if buckets.len() >= MAX_BUCKETS {
            let full = self.burst;
            let rate = self.rate_per_sec;
            buckets.retain(|_, (tokens, at)| {
                *tokens + now.duration_since(*at).as_secs_f64() * rate < full
            });
        }
        let (tokens, at) = buckets.entry(client).or_insert((self.burst, now));
        *tokens =
            (*tokens + now.duration_since(*at).as_secs_f64() * self.rate_per_sec).min(self.burst);
        *at = now;
        if *tokens >= 1.0 {
            *tokens -= 1.0;
            Ok(())
        } else {
            let wait = (1.0 - *tokens) / self.rate_per_sec;
            Err(AppError::new(
                StatusCode::TOO_MANY_REQUESTS,
                "rate_limited",
                format!(
                    "too many writes from this client; retry in {:.0} ms (limit {} per second)",
                    (wait * 1000.0).ceil(),
                    self.rate_per_sec
                ),
            ))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::random::random_hex;

    #[test]
    fn tokens_are_checked_by_hash() {
        let token = random_hex(32);
        assert_eq!(token.len(), 64);
        let hash = token_hash(&token);
        require(Some(&token), &[&hash], "pushing").expect("right token");
        let e = require(Some("nope"), &[&hash], "pushing").expect_err("wrong token");
        assert_eq!(e.status, StatusCode::FORBIDDEN);
        let e = require(None, &[&hash], "pushing").expect_err("no token");
        assert_eq!(e.status, StatusCode::UNAUTHORIZED);
    }

    #[test]
    fn bucket_refuses_past_the_burst() {
        let limiter = RateLimiter::new(0.001, 2);
        limiter.check(None).expect("first");
        limiter.check(None).expect("second");
        let e = limiter.check(None).expect_err("third is over the burst");
        assert_eq!(e.status, StatusCode::TOO_MANY_REQUESTS);
        limiter
            .check(Some(IpAddr::from([10, 0, 0, 1])))
            .expect("another client has its own bucket");
    }
}
