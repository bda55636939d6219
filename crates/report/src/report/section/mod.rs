//! The sections of the report, one module each, in the order of the page; each writes its
//! heading, figures, captions and tables into the [`Page`](super::html::Page).

pub(super) mod camera;
pub(super) mod contrast;
pub(super) mod failures;
pub(super) mod overview;
pub(super) mod preview;
pub(super) mod provenance;
pub(super) mod scenes;
pub(super) mod splits;
pub(super) mod visibility;
