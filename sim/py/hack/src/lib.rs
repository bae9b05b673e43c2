//! The workspace-hack crate of cargo-hakari (`.config/hakari.toml`): no code, only dependencies
//! with the features the whole workspace resolves for them, so that building the Python
//! bindings alone (maturin, after `cargo test --workspace` in `scripts/test.sh`) reuses the
//! dependencies the test build compiled. Regenerate its `Cargo.toml` with `cargo hakari
//! generate` after changing dependencies.
