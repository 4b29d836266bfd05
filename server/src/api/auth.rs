//! Who may write and view: random scene ids and tokens, token checks, and the per-client
//! rate limits (writes, renders).
//!
//! Tokens are 256-bit random hex strings from the OS generator, returned once at scene
//! creation; the store keeps only their SHA-256, compared in constant time. Scene ids are
//! 128-bit random hex, so they cannot be guessed or enumerated.

use crate::error::AppError;
use axum::http::{HeaderMap, StatusCode};
use sha2::{Digest, Sha256};
use std::net::IpAddr;
use std::num::NonZeroU32;
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

/// A rate limit per client address (GCRA, from `governor`): `rate` requests per second on
/// average, `burst` at once. Clients are told how long to wait (429 with `Retry-After`).
///
/// The key map is bounded in practice: once it holds [`MAX_CLIENTS`] addresses, those whose
/// allowance is whole again (the state a new client starts in, so dropping them changes no
/// answer) are dropped, at most once a second.
pub struct RateLimiter {
    limiter: governor::DefaultKeyedRateLimiter<Option<IpAddr>>,
    rate_per_sec: f64,
    what: &'static str,
    last_sweep: Mutex<Instant>,
}

/// Client addresses kept before idle ones are dropped.
pub const MAX_CLIENTS: usize = 10_000;

impl RateLimiter {
    /// `what` names the requests in the refusal ("writes", "renders").
    pub fn new(rate_per_sec: f64, burst: u32, what: &'static str) -> RateLimiter {
        // The config checks both are positive; a period below a nanosecond is one nanosecond.
        let period = std::time::Duration::from_secs_f64(1.0 / rate_per_sec)
            .max(std::time::Duration::from_nanos(1));
        let quota = governor::Quota::with_period(period)
            .unwrap_or(governor::Quota::per_second(NonZeroU32::MIN))
            .allow_burst(NonZeroU32::new(burst).unwrap_or(NonZeroU32::MIN));
        RateLimiter {
            limiter: governor::RateLimiter::keyed(quota),
            rate_per_sec,
            what,
            last_sweep: Mutex::new(Instant::now()),
        }
    }

    /// Takes one request from `client`'s allowance, or says how long to wait.
    pub fn check(&self, client: Option<IpAddr>) -> Result<(), AppError> {
        self.sweep();
        match self.limiter.check_key(&client) {
            Ok(()) => Ok(()),
            Err(not_until) => {
                let wait = not_until.wait_time_from(governor::clock::Clock::now(
                    &governor::clock::DefaultClock::default(),
                ));
                let ms = wait.as_millis().max(1);
                let mut e = AppError::new(
                    StatusCode::TOO_MANY_REQUESTS,
                    "rate_limited",
                    format!(
                        "too many {} from this client; retry in {ms} ms (limit {} per second)",
                        self.what, self.rate_per_sec
                    ),
                );
                e.retry_after = Some(wait.as_secs() + u64::from(wait.subsec_nanos() > 0));
                Err(e)
            }
        }
    }

    /// Addresses held now.
    pub fn clients(&self) -> usize {
        self.limiter.len()
    }

    fn sweep(&self) {
        if self.limiter.len() < MAX_CLIENTS {
            return;
        }
        let mut last = self.last_sweep.lock().unwrap_or_else(|e| e.into_inner());
        if last.elapsed() >= std::time::Duration::from_secs(1) {
            *last = Instant::now();
            self.limiter.retain_recent();
            self.limiter.shrink_to_fit();
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
        let limiter = RateLimiter::new(0.001, 2, "writes");
        limiter.check(None).expect("first");
        limiter.check(None).expect("second");
        let e = limiter.check(None).expect_err("third is over the burst");
        assert_eq!(e.status, StatusCode::TOO_MANY_REQUESTS);
        // 1000 s per request at 0.001 per second.
        assert!(
            e.retry_after.is_some_and(|s| (990..=1000).contains(&s)),
            "{e:?}"
        );
        limiter
            .check(Some(IpAddr::from([10, 0, 0, 1])))
            .expect("another client has its own bucket");
    }
}
