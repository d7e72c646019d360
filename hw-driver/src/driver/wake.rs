//! Waking the loop's wait set from a backend thread: a socket pair whose reading end is
//! attached to the wait set next to the thrust listener. (iceoryx2's wait set multiplexes
//! file descriptors; this keeps backends free of iceoryx2 types.)

use std::sync::{Arc, Mutex};

use iceoryx2_bb_posix::socket_pair::StreamingSocket;

use crate::backend::Waker;

/// The reading end (attach it to the wait set) and a [`Waker`] writing to the other end.
pub struct WakePipe {
    rx: StreamingSocket,
    waker: Waker,
}

impl std::fmt::Debug for WakePipe {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("WakePipe")
    }
}

impl WakePipe {
    /// A new pair; `None` if the OS refuses a socket pair.
    pub fn new() -> Result<WakePipe, String> {
        let (tx, rx) = StreamingSocket::create_pair().map_err(|e| format!("{e:?}"))?;
        let tx = Arc::new(Mutex::new(tx));
        let waker = Waker::new(move || {
            if let Ok(tx) = tx.lock() {
                // A full buffer means the loop has wake-ups pending already: nothing lost.
                let _ = tx.try_send(&[1]);
            }
        });
        Ok(WakePipe { rx, waker })
    }

    /// The waker to hand to the backend.
    pub fn waker(&self) -> Waker {
        self.waker.clone()
    }

    /// The reading end, to attach to the wait set.
    pub fn socket(&self) -> &StreamingSocket {
        &self.rx
    }

    /// Consumes pending wake-ups without blocking.
    pub fn drain(&self) {
        let mut buf = [0u8; 64];
        while matches!(self.rx.try_receive(&mut buf), Ok(n) if n > 0) {}
    }
}
