//! The in-process harness the tests share: thruster-inprocess's (the lab's sweeps drive the
//! same one).
#![allow(unused_imports)]

pub use thruster_inprocess::*;
