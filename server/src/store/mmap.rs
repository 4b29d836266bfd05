//! The one place the server memory-maps files: stored step files, read-only.
//!
//! Safety argument: a step file is written once under a temporary name, fsynced, and renamed
//! into place; nothing ever opens it for writing again. Replacing a step renames a new file
//! over the name and deleting unlinks it, and on Linux an existing mapping keeps the old
//! inode alive, so a mapped view never changes underneath a reader. Another process editing
//! the data directory by hand is outside this contract, as it is for any database.
#![allow(unsafe_code)]

use memmap2::Mmap;
use std::fs::File;

/// Maps `file` read-only. Empty files are not mapped (`mmap` refuses length zero).
pub fn map_readonly(file: &File) -> std::io::Result<Mmap> {
    // SAFETY: see the module documentation: step files are immutable once renamed into place.
    unsafe { Mmap::map(file) }
}
