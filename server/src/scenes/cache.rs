//! Prepared stored steps, shared by every session and bounded in bytes across all scenes
//! (`--cache-bytes`), least recently used first out.

use crate::scenes::prepared::PreparedState;
use std::collections::VecDeque;
use std::sync::Mutex;

type CacheKey = (String, u64, u128);

/// Prepared stored steps, bounded in bytes, least recently used evicted first.
pub struct PreparedCache {
    max_bytes: u64,
    inner: Mutex<CacheInner>,
}

#[derive(Default)]
struct CacheInner {
    entries: VecDeque<(CacheKey, PreparedState, u64)>,
    bytes: u64,
}

impl PreparedCache {
    pub(crate) fn new(max_bytes: u64) -> PreparedCache {
        PreparedCache {
            max_bytes,
            inner: Mutex::new(CacheInner::default()),
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, CacheInner> {
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The cached state for `key`, or one built now (outside the lock) and cached if it fits.
    pub(crate) fn get_or_build(
        &self,
        key: CacheKey,
        bytes: u64,
        build: impl FnOnce() -> PreparedState,
    ) -> PreparedState {
        {
            let mut inner = self.lock();
            if let Some(pos) = inner.entries.iter().position(|(k, _, _)| *k == key) {
                let hit = inner.entries.remove(pos).expect("position is in range");
                let state = PreparedState {
                    update_us: 0,
                    build_us: 0,
                    ..hit.1.clone()
                };
                inner.entries.push_back(hit);
                return state;
            }
        }
        let state = build();
        if bytes <= self.max_bytes {
            let mut inner = self.lock();
            if !inner.entries.iter().any(|(k, _, _)| *k == key) {
                while inner.bytes + bytes > self.max_bytes {
                    let Some((_, _, b)) = inner.entries.pop_front() else {
                        break;
                    };
                    inner.bytes -= b;
                }
                inner.bytes += bytes;
                inner.entries.push_back((key, state.clone(), bytes));
            }
        }
        state
    }

    pub(crate) fn forget_scene(&self, id: &str) {
        let mut inner = self.lock();
        let mut freed = 0;
        inner.entries.retain(|(k, _, b)| {
            let keep = k.0 != id;
            if !keep {
                freed += b;
            }
            keep
        });
        inner.bytes -= freed;
    }

    /// Bytes held now.
    pub fn bytes(&self) -> u64 {
        self.lock().bytes
    }
}
