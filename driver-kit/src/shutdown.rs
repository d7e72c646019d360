//! The stop flag set by SIGINT, SIGTERM and SIGHUP.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// A cloneable flag that asks the loops to stop. A driver's loops poll it at least a few
/// times a second, so a signal ends the process within a fraction of a second.
#[derive(Debug, Clone, Default)]
pub struct Shutdown(Arc<AtomicBool>);

impl Shutdown {
    /// A flag that nothing sets yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// A flag set by SIGINT, SIGTERM and SIGHUP (ctrlc with its `termination` feature). Call
    /// once per process.
    pub fn on_signals() -> Result<Self, ctrlc::Error> {
        let flag = Shutdown::new();
        let set = flag.clone();
        ctrlc::set_handler(move || set.request())?;
        Ok(flag)
    }

    /// Asks to stop.
    pub fn request(&self) {
        self.0.store(true, Ordering::SeqCst);
    }

    /// True once stopping was asked for.
    pub fn requested(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }
}
