//! The terminal: lines to stdout and the Ctrl-C flag, shared by the commands that print and
//! the ones that wait.

use std::io::Write;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};

/// Prints a line to stdout; a closed pipe (`| head`) surfaces as an error main ignores.
pub fn say(text: &str) -> Result<()> {
    let mut out = std::io::stdout().lock();
    writeln!(out, "{text}").context("writing to stdout")?;
    out.flush().context("writing to stdout")
}

/// After a failed blocking wait: true when Ctrl-C caused it. The signal makes the wait
/// fail (EINTR) at once, but ctrlc sets our flag from its own thread, a moment later.
pub fn interrupted_during_wait(flag: &AtomicBool) -> bool {
    let deadline = Instant::now() + Duration::from_millis(200);
    loop {
        if flag.load(Ordering::SeqCst) {
            return true;
        }
        if Instant::now() >= deadline {
            return false;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// Set by Ctrl-C (and SIGTERM). Installed only by commands that wait, so a quick command
/// killed by Ctrl-C dies at once as usual.
pub fn interrupt_flag() -> Result<Arc<AtomicBool>> {
    let flag = Arc::new(AtomicBool::new(false));
    let f = flag.clone();
    ctrlc::set_handler(move || f.store(true, Ordering::SeqCst))
        .context("installing the Ctrl-C handler")?;
    Ok(flag)
}
