//! Integration tests for `clevrtex eval`.
