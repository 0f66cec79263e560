//! Host simulator: the 9-DoF vehicle plant of the paper's Section IV, its tyres,
//! tracks and scenarios, and the deterministic timeline that closes the loop on
//! the `firmware` library.
pub mod qp_corpus;
