//! Prepared stored steps, shared by every session and bounded in bytes across all scenes
//! (`--cache-bytes`), least recently used first out.
//!
//! How it works: the recency order is the `lru` crate's `LruCache` (a linked hash map; the
//! byte bound is kept here by popping its least recently used entries), rather than a
//! hand-kept queue searched linearly. Builds are single-flight: the first caller for a key
//! builds it outside the lock while later callers for the same key wait for that build
//! (blocking, on the render pool, as every caller already is), so N viewers of a newly
//! pushed step cost one build, not N. If the builder panics, one waiter takes over.

use crate::scenes::prepared::PreparedState;
use lru::LruCache;
use std::collections::HashMap;
use std::sync::{Arc, Condvar, Mutex};

type CacheKey = (String, u64, u128);

/// Prepared stored steps, bounded in bytes, least recently used evicted first.
pub struct PreparedCache {
    max_bytes: u64,
    inner: Mutex<CacheInner>,
}

struct CacheInner {
    entries: LruCache<CacheKey, (PreparedState, u64)>,
    bytes: u64,
    /// Builds in progress, by key.
    building: HashMap<CacheKey, Arc<Flight>>,
}

/// One build in progress: `None` while building, then the state, or `Some(None)` if the
/// builder failed (panicked) and a waiter should build instead.
struct Flight {
    outcome: Mutex<Option<Option<PreparedState>>>,
    done: Condvar,
}

impl Flight {
    fn finish(&self, outcome: Option<PreparedState>) {
        *self.outcome.lock().unwrap_or_else(|e| e.into_inner()) = Some(outcome);
        self.done.notify_all();
    }

    fn wait(&self) -> Option<PreparedState> {
        let mut outcome = self.outcome.lock().unwrap_or_else(|e| e.into_inner());
        loop {
            if let Some(done) = outcome.as_ref() {
                return done.clone();
            }
            outcome = self.done.wait(outcome).unwrap_or_else(|e| e.into_inner());
        }
    }
}

/// Ends a build: if it did not finish (the builder panicked), the flight is removed and its
/// waiters are told to build themselves.
struct FlightGuard<'a> {
    cache: &'a PreparedCache,
    key: Option<CacheKey>,
    flight: Arc<Flight>,
}

impl Drop for FlightGuard<'_> {
    fn drop(&mut self) {
        if let Some(key) = self.key.take() {
            self.cache.lock().building.remove(&key);
            self.flight.finish(None);
        }
    }
}

/// What a caller does for a key that is not cached.
enum Role {
    Build(Arc<Flight>),
    Wait(Arc<Flight>),
}

/// A cached state as a hit reports it: no update or build time spent.
fn as_hit(state: &PreparedState) -> PreparedState {
    PreparedState {
        update_us: 0,
        build_us: 0,
        ..state.clone()
    }
}

impl PreparedCache {
    pub(crate) fn new(max_bytes: u64) -> PreparedCache {
        PreparedCache {
            max_bytes,
            inner: Mutex::new(CacheInner {
                entries: LruCache::unbounded(),
                bytes: 0,
                building: HashMap::new(),
            }),
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, CacheInner> {
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The cached state for `key`, or one built now (outside the lock, once however many
    /// callers ask at the same time) and cached if it fits. Blocking: call it on the render
    /// pool.
    pub(crate) fn get_or_build(
        &self,
        key: CacheKey,
        bytes: u64,
        build: impl FnOnce() -> PreparedState,
    ) -> PreparedState {
        let mut build = Some(build);
        loop {
            let role = {
                let mut inner = self.lock();
                if let Some((state, _)) = inner.entries.get(&key) {
                    return as_hit(state);
                }
                match inner.building.get(&key) {
                    Some(flight) => Role::Wait(Arc::clone(flight)),
                    None => {
                        let flight = Arc::new(Flight {
                            outcome: Mutex::new(None),
                            done: Condvar::new(),
                        });
                        inner.building.insert(key.clone(), Arc::clone(&flight));
                        Role::Build(flight)
                    }
                }
            };
            match role {
                Role::Wait(flight) => match flight.wait() {
                    Some(state) => return as_hit(&state),
                    None => continue, // the builder failed: try again, maybe as the builder
                },
                Role::Build(flight) => {
                    let mut guard = FlightGuard {
                        cache: self,
                        key: Some(key.clone()),
                        flight: Arc::clone(&flight),
                    };
                    let build = build.take().expect("a caller builds at most once");
                    let state = build();
                    {
                        let mut inner = self.lock();
                        inner.building.remove(&key);
                        if bytes <= self.max_bytes {
                            while inner.bytes + bytes > self.max_bytes {
                                let Some((_, (_, b))) = inner.entries.pop_lru() else {
                                    break;
                                };
                                inner.bytes -= b;
                            }
                            inner.bytes += bytes;
                            inner.entries.put(key, (state.clone(), bytes));
                        }
                    }
                    guard.key = None;
                    flight.finish(Some(state.clone()));
                    return state;
                }
            }
        }
    }

    pub(crate) fn forget_scene(&self, id: &str) {
        let mut inner = self.lock();
        let gone: Vec<CacheKey> = inner
            .entries
            .iter()
            .filter(|(k, _)| k.0 == id)
            .map(|(k, _)| k.clone())
            .collect();
        for key in gone {
            if let Some((_, b)) = inner.entries.pop(&key) {
                inner.bytes -= b;
            }
        }
    }

    /// Bytes held now.
    pub fn bytes(&self) -> u64 {
        self.lock().bytes
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};

    fn some_state() -> PreparedState {
        let scene = isoray_render::scenes::DemoScene::ALL[0].state_at(0.0);
        PreparedState {
            prepared: Arc::new(scene).prepare(),
            update_us: 1,
            build_us: 1,
            step_time: Some(0.0),
        }
    }

    /// N viewers of a newly pushed step ask at once: one build. The build does not finish
    /// before every caller has entered `get_or_build`, so without single flight each of them
    /// would miss and build its own.
    #[test]
    fn concurrent_callers_of_one_key_share_a_single_build() {
        const N: usize = 8;
        let cache = Arc::new(PreparedCache::new(1 << 30));
        let entered = Arc::new(AtomicUsize::new(0));
        let builds = Arc::new(AtomicUsize::new(0));
        let threads: Vec<_> = (0..N)
            .map(|_| {
                let (cache, entered, builds) = (
                    Arc::clone(&cache),
                    Arc::clone(&entered),
                    Arc::clone(&builds),
                );
                std::thread::spawn(move || {
                    entered.fetch_add(1, Ordering::SeqCst);
                    cache.get_or_build(("s".into(), 0, 7), 100, || {
                        builds.fetch_add(1, Ordering::SeqCst);
                        while entered.load(Ordering::SeqCst) < N {
                            std::thread::yield_now();
                        }
                        some_state()
                    })
                })
            })
            .collect();
        for t in threads {
            t.join().expect("caller thread");
        }
        assert_eq!(
            builds.load(Ordering::SeqCst),
            1,
            "one build for {N} callers"
        );
        assert_eq!(cache.bytes(), 100);
    }

    /// Bytes stay within the bound, least recently used out first; a scene's entries go
    /// when it is forgotten.
    #[test]
    fn bounded_in_bytes_least_recently_used_first() {
        let cache = PreparedCache::new(250);
        let key = |i: u64| ("s".to_string(), i, 0u128);
        for i in 0..2 {
            cache.get_or_build(key(i), 100, some_state);
        }
        // Touch 0, so 1 is the least recently used when 2 arrives.
        cache.get_or_build(key(0), 100, || panic!("0 is cached"));
        cache.get_or_build(key(2), 100, some_state);
        assert_eq!(cache.bytes(), 200);
        cache.get_or_build(key(0), 100, || panic!("0 stayed"));
        let rebuilt = AtomicUsize::new(0);
        cache.get_or_build(key(1), 100, || {
            rebuilt.fetch_add(1, Ordering::SeqCst);
            some_state()
        });
        assert_eq!(rebuilt.load(Ordering::SeqCst), 1, "1 was evicted");
        cache.forget_scene("s");
        assert_eq!(cache.bytes(), 0);
    }
}
