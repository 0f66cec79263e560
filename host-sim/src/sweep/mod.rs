//! Sweeps: many closed-loop runs (being split along their concepts: see the next commit).

pub mod figures;
