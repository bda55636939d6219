//! Integration tests for `clevrtex materials`.
