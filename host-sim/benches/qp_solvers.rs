//! Benchmark of our QP solver against OSQP and Clarabel on the QP corpus (next commit).
fn main() {}
