//! Holder crate for the workspace-wide integration tests in `tests/tests/`.
