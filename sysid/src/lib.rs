//! System identification of link inertias and joint friction from robot logs (`twin sysid`).
//!
//! The identification pipeline arrives with its issue; this crate holds the workspace slot so
//! the layout is stable for dependents.
