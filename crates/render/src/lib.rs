//! Drives headless Blender to render scene files, and turns its output into the published
//! dataset layout.
#![deny(missing_docs)]
