//! Integration tests for `clevrtex bench`.
