//! Domain-randomized batch rollouts (`twin randomize`).
//!
//! The rollout engine arrives with its issue; this crate holds the workspace slot so the layout
//! is stable for dependents.
