//! Reading a dataset folder someone else wrote (`verify`, `export`, `preview`, `report`,
//! `eval`): its files are data, not instructions. One place decides what is followed and what
//! is read:
//!
//! - a symbolic link is followed only when its target (resolved) lies inside the dataset's
//!   root; one that leads out of it is reported and never opened;
//! - only regular files are read: a FIFO, socket or device (also behind a link) is skipped
//!   without blocking (files are opened with `O_NONBLOCK` and checked with `fstat` before a
//!   byte is read);
//! - a file is read with a cap ([`MAX_FILE_BYTES`]), never to the end of whatever it holds.
//!
//! On top of that, the one read side of the layout ([`crate::layout`]): [`Dataset::open`]
//! walks a dataset once and finds its variant folders, samples ([`SampleRef`]: variant, index,
//! stem, folder, the files found; paths from the pass table), manifests, ledgers, temporaries
//! and what was not followed; [`MetadataView`] is the typed, bounded view of a sample's
//! metadata (errors name the file and the key); the manifests' union is
//! [`crate::manifest::union`]. No other module walks a dataset folder or parses a stem.
//!
//! By concern: `files.rs` (the root, what an entry is, capped reads and deletes beneath the
//! root's handle), `walk.rs` ([`Dataset::open`], [`SampleRef`], [`VariantDir`]), `metadata.rs`
//! ([`MetadataView`], [`check_metadata`], a pass PNG's mode), `splits.rs` ([`splits()`]: the
//! one split rule). Everything is re-exported here: readers outside this crate name
//! `dataset::X`.

pub(crate) mod files;
pub(crate) mod metadata;
pub(crate) mod splits;
#[cfg(test)]
mod tests;
pub(crate) mod walk;

pub use files::*;
pub use metadata::*;
pub use splits::*;
pub use walk::*;
