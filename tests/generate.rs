//! Integration tests for `clevrtex generate`.
