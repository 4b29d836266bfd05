//! A root search's entry and exit events, handed out in order one at a time.
//!
//! How it works: the walk over a search's sections (`roots::walk_sections`) takes every
//! ball's entry and exit on `[lo, hi]` in the order of their keys ([`Real::event_key`]:
//! parameter, then ball, an entry before an exit at the same parameter and ball). Sorting all
//! of them is wasted on a search that ends early, and most do: a camera ray's search through
//! a leaf of Pool or Molecule finds its root after about 5 of its 16 events (counted over a
//! 640×480 ray cast of each). A ball's exit key is above its entry key (`t0 < t1`), so the
//! next event is either the next entry in key order or the smallest exit key among the balls
//! entered and not yet left: only the entries are sorted, and the exits of the few active
//! balls are kept with the smallest of them at hand. The events come out in exactly the
//! order the sort of all of them gives, and the active list is the one a walk over those
//! sorted events keeps (entries pushed, exits swap-removed).

use crate::kinds::metaballs::real::Real;

/// The events of one search: the sorted entries, and the balls entered and not yet left with
/// their exit keys.
#[derive(Debug)]
pub(crate) struct Events<R: Real> {
    /// Sorted, then closed by [`Real::NO_EVENT`].
    entries: Vec<R::EventKey>,
    next: usize,
    active: Vec<u32>,
    /// The exit key of each ball of `active`, in its order.
    exits: Vec<R::EventKey>,
    /// The smallest of `exits` ([`Real::NO_EVENT`] when none) and its position.
    soonest: (R::EventKey, usize),
}

/// Which event [`Events::next`] hands out.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Event {
    Entry,
    /// The exit of the active ball at this position.
    Exit(usize),
}

impl<R: Real> Default for Events<R> {
    fn default() -> Self {
        Events {
            entries: Vec::new(),
            next: 0,
            active: Vec::new(),
            exits: Vec::new(),
            soonest: (R::NO_EVENT, 0),
        }
    }
}

impl<R: Real> Events<R> {
    /// Empties the queue for a new search.
    #[inline(always)]
    pub(crate) fn clear(&mut self) {
        self.entries.clear();
        self.next = 0;
        self.active.clear();
        self.exits.clear();
        self.soonest = (R::NO_EVENT, 0);
    }

    /// Adds a ball's entry key; [`Events::sort`] once every entry is in.
    #[inline(always)]
    pub(crate) fn push_entry(&mut self, key: R::EventKey) {
        self.entries.push(key);
    }

    #[inline(always)]
    pub(crate) fn sort(&mut self) {
        self.entries.sort_unstable();
        self.entries.push(R::NO_EVENT);
    }

    /// The next event's key ([`Real::NO_EVENT`] when every event is handed out) and where it
    /// comes from.
    #[inline(always)]
    pub(crate) fn next(&self) -> (R::EventKey, Event) {
        let entry = self.entries[self.next];
        if self.soonest.0 < entry {
            (self.soonest.0, Event::Exit(self.soonest.1))
        } else {
            (entry, Event::Entry)
        }
    }

    /// Takes the next entry ([`Events::next`] said so): `ball` is active until `exit`.
    #[inline(always)]
    pub(crate) fn enter(&mut self, ball: u32, exit: R::EventKey) {
        self.next += 1;
        if exit < self.soonest.0 {
            self.soonest = (exit, self.exits.len());
        }
        self.active.push(ball);
        self.exits.push(exit);
    }

    /// Takes the exit of the active ball at `pos` ([`Events::next`] said so).
    #[inline(always)]
    pub(crate) fn leave(&mut self, pos: usize) {
        self.active.swap_remove(pos);
        self.exits.swap_remove(pos);
        let mut soonest = (R::NO_EVENT, 0);
        for (pos, &k) in self.exits.iter().enumerate() {
            if k < soonest.0 {
                soonest = (k, pos);
            }
        }
        self.soonest = soonest;
    }

    /// The balls entered and not yet left.
    #[inline(always)]
    pub(crate) fn active(&self) -> &[u32] {
        &self.active
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The events of `spans` (ball `i` on `[t0, t1]`, kept when `t0 < t1`) in the sort of all
    /// of them, each with the active list after it, as the walk kept it before this queue:
    /// entries pushed, exits searched for and swap-removed.
    fn sorted_walk(spans: &[(f32, f32)]) -> Vec<(u64, Vec<u32>)> {
        let mut events = Vec::new();
        for (i, &(t0, t1)) in spans.iter().enumerate() {
            if t0 < t1 {
                events.push(t0.event_key((i as u32) << 1));
                events.push(t1.event_key(((i as u32) << 1) | 1));
            }
        }
        events.sort();
        let mut active = Vec::new();
        let mut out = Vec::new();
        for key in events {
            let code = f32::of_event_key(key).1;
            if code & 1 == 0 {
                active.push(code >> 1);
            } else if let Some(pos) = active.iter().position(|&a| a == code >> 1) {
                active.swap_remove(pos);
            }
            out.push((key, active.clone()));
        }
        out
    }

    fn queue_walk(spans: &[(f32, f32)]) -> Vec<(u64, Vec<u32>)> {
        let mut q = Events::<f32>::default();
        q.clear();
        for (i, &(t0, t1)) in spans.iter().enumerate() {
            if t0 < t1 {
                q.push_entry(t0.event_key((i as u32) << 1));
            }
        }
        q.sort();
        let mut out = Vec::new();
        loop {
            let (key, from) = q.next();
            if key == f32::NO_EVENT {
                return out;
            }
            let ball = f32::of_event_key(key).1 >> 1;
            match from {
                Event::Entry => q.enter(ball, spans[ball as usize].1.event_key(ball << 1 | 1)),
                Event::Exit(pos) => q.leave(pos),
            }
            out.push((key, q.active().to_vec()));
        }
    }

    /// Parameters drawn mostly from a few values (four arms in five), so that ties, and `-0`
    /// against `+0`, are common.
    fn span() -> impl Strategy<Value = (f32, f32)> {
        let value = prop_oneof![
            Just(-0.0f32),
            Just(0.0),
            Just(1.0),
            Just(2.5),
            -10.0f32..10.0,
        ];
        (value.clone(), value)
    }

    proptest! {
        #[test]
        fn the_queue_hands_out_the_sorted_events_with_the_same_active_lists(
            spans in prop::collection::vec(span(), 0..24)
        ) {
            prop_assert_eq!(queue_walk(&spans), sorted_walk(&spans));
        }
    }

    #[test]
    fn an_entry_where_another_ball_leaves_comes_in_ball_order() {
        // At 1, ball 0 enters, ball 1 leaves and ball 2 enters: by key, in that order.
        let spans = [(1.0, 3.0), (0.0, 1.0), (1.0, 2.0)];
        let walk = queue_walk(&spans);
        let codes: Vec<u32> = walk.iter().map(|&(k, _)| f32::of_event_key(k).1).collect();
        assert_eq!(codes, [2, 0, 3, 4, 5, 1]);
        assert_eq!(walk, sorted_walk(&spans));
    }
}
