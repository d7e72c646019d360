//! A stand-in daemon: answers every IMU sample with a neutral thrust command.
//!
//! Used by `thruster-sim respond`, the process tests and the lockstep speed measurement,
//! until the real daemon drives the simulator. It answers exactly as the lockstep protocol
//! asks: `imu_seq` and `t_ns` of the sample, `count` from the simulator's truth message
//! (which follows reconfigurations) unless a fixed count is given.

use std::time::{Duration, Instant};

use thruster_protocol::services::{Inbox, IpcConfig, IpcError, Port};
use thruster_protocol::{ImuSample, ThrustCommand, TruthMsg, Validate};
use tracing::warn;

use crate::driver::shutdown::Shutdown;
use crate::driver::wait::{recv_until, AdaptiveSpin, Received};

/// Node name of the responder in iceoryx2 listings.
pub const NODE_NAME: &str = "thruster-sim-respond";

/// How the responder behaves.
#[derive(Debug, Clone)]
pub struct ResponderOptions {
    /// Thruster count to command; `None`: from the truth message.
    pub count: Option<u32>,
    /// Busy-poll for the next sample this long before blocking.
    pub spin: Duration,
    /// Return when no sample arrived for this long after the first one.
    pub idle_exit: Option<Duration>,
}

impl Default for ResponderOptions {
    fn default() -> Self {
        ResponderOptions {
            count: None,
            spin: Duration::from_micros(200),
            idle_exit: None,
        }
    }
}

/// What the responder saw.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ResponderReport {
    /// Samples answered.
    pub answered: u64,
    /// Samples not answered (invalid, or the thruster count not known yet).
    pub skipped: u64,
    /// `t_ns` of the first answered sample and when it arrived.
    pub first: Option<(u64, Instant)>,
    /// `t_ns` of the last answered sample and when it arrived.
    pub last: Option<(u64, Instant)>,
}

impl ResponderReport {
    /// Vehicle seconds per wall second between the first and the last answered sample.
    pub fn speedup(&self) -> Option<f64> {
        let ((t0, w0), (t1, w1)) = (self.first?, self.last?);
        let wall = w1.duration_since(w0).as_secs_f64();
        (wall > 0.0).then(|| (t1 - t0) as f64 * 1e-9 / wall)
    }
}

/// Answers samples in `ipc`'s namespace until `stop` or the idle exit.
pub fn respond(
    ipc: &IpcConfig,
    opts: &ResponderOptions,
    stop: &Shutdown,
) -> Result<ResponderReport, IpcError> {
    let node = ipc.create_node(NODE_NAME)?;
    // Truth before IMU: once the simulator sees an IMU subscriber, the truth subscriber
    // exists too and gets the history on the simulator's next connection update.
    let truth = Inbox::<TruthMsg>::create_with_buffer(&node, ipc, 1)?;
    let thrust = Port::<ThrustCommand>::create(&node, ipc)?;
    let imu = Inbox::<ImuSample>::create(&node, ipc)?;
    let mut report = ResponderReport::default();
    let mut count = opts.count;
    let mut seq = 0u64;
    let mut warned = false;
    let mut spin = AdaptiveSpin::new(opts.spin);
    loop {
        let deadline = match (opts.idle_exit, report.last) {
            (Some(idle), Some((_, at))) => at + idle,
            _ => Instant::now() + Duration::from_secs(1),
        };
        let window = spin.window();
        let waiting_since = Instant::now();
        match recv_until(&imu, deadline, window, stop)? {
            Received::Message(sample) => {
                spin.record(window, waiting_since.elapsed());
                if opts.count.is_none() {
                    if let Some(t) = truth.recv_latest()? {
                        if t.validate().is_ok() {
                            count = Some(t.count);
                        }
                    }
                }
                let (Some(n), Ok(())) = (count, sample.validate()) else {
                    if !warned {
                        warn!(
                            seq = sample.seq,
                            "sample not answered (invalid, or no truth yet)"
                        );
                        warned = true;
                    }
                    report.skipped += 1;
                    continue;
                };
                seq += 1;
                thrust.send(&ThrustCommand::neutral(seq, sample.seq, sample.t_ns, n))?;
                let now = Instant::now();
                report.answered += 1;
                report.first.get_or_insert((sample.t_ns, now));
                report.last = Some((sample.t_ns, now));
            }
            Received::Timeout => {
                if let (Some(idle), Some((_, at))) = (opts.idle_exit, report.last) {
                    if at.elapsed() >= idle {
                        break;
                    }
                }
            }
            Received::Shutdown => break,
        }
    }
    Ok(report)
}
