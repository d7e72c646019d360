//! Helpers shared by the system tests: spawning and reaping real processes on a private namespace.
