//! Integration tests for `clevrtex sample`.
