//! What the simulator writes: a run's files and figures, the validity experiment's.
//!
//! | module | concept |
//! |---|---|
//! | [`run_files`] | a run's `log.csv`, `plan_activations.csv`, `summary.json` (and figures) |
//! | [`figures`] | the closed-loop figures (the paper's Figures 5–8, task costs) |
//! | [`validity_files`] | the validity experiment's `validity.csv` and `validity.png` |
//! | [`plot`] | plotting helpers (embedded font) |

pub mod figures;
pub mod plot;
pub mod run_files;
pub mod validity_files;
