//! End-to-end tests across `firmware` and `host-sim` live in `tests/tests/`.
