//! Shared values built on first use whose builders fork on the rayon pool.
//!
//! `OnceLock::get_or_init` holds the cell while its closure runs. A closure that forks (rayon
//! `join`, `par_iter`) may, while it waits for its forked halves, pick up a queued job of the
//! same pool that asks for the same cell: that thread then waits on itself, and with every
//! other worker waiting on the cell too, the pool stops. (Seen: a surfel demo's first frame
//! never came when a viewer opened it on a loaded machine, the next state's build having
//! been queued while the first was still simulating the demo.) [`built`] runs the builder
//! with no lock held and keeps the first value stored: two threads may both build, and the
//! builders are deterministic, so the value is the same whichever is kept.

use std::sync::OnceLock;

/// The value in `cell`, built by `build` (outside any lock) if there is none yet.
pub fn built<T>(cell: &OnceLock<T>, build: impl FnOnce() -> T) -> &T {
    if let Some(value) = cell.get() {
        return value;
    }
    let value = build();
    // Holds the cell only to move the finished value in; another thread's may have won.
    cell.get_or_init(|| value)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::cell::Cell;

    #[test]
    fn a_builder_that_asks_for_its_own_cell_finishes_and_the_first_value_is_kept() {
        // The deadlock's core: while the cell is being built, the building thread asks for
        // the same cell (a forked job it picked up, here a direct call). `get_or_init` would
        // wait on itself; `built` builds the inner copy, stores it, and the outer build's
        // value is dropped.
        static CELL: OnceLock<u32> = OnceLock::new();
        thread_local!(static DEPTH: Cell<u32> = const { Cell::new(0) });
        fn value() -> u32 {
            *built(&CELL, || {
                let depth = DEPTH.get();
                DEPTH.set(depth + 1);
                if depth == 0 {
                    value() + 100 // the outer build: asks for its own cell first
                } else {
                    7 // the inner build
                }
            })
        }
        assert_eq!(value(), 7, "the first value stored is kept");
        assert_eq!(value(), 7);
        assert_eq!(DEPTH.get(), 2, "built twice, once inside the other");
    }
}
