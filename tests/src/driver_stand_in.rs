//! The test as the daemon's driver: it sends IMU samples itself and times each answer, to
//! show what an operator's request does to control while it runs.

use std::time::{Duration, Instant};

use thruster_protocol::services::{Inbox, Port};
use thruster_protocol::{ImuSample, ThrustCommand};

use crate::World;

/// What the samples met while something else ran ([`DriverStandIn::time_while`]).
pub struct Timed {
    /// The slowest answer.
    pub worst: Duration,
    /// Samples answered.
    pub answered: u64,
    /// From the start until the other thing was done.
    pub done_after: Duration,
}

/// A level vehicle at rest, one sample every 5 ms of its own clock.
pub struct DriverStandIn {
    imu: Port<ImuSample>,
    thrust: Inbox<ThrustCommand>,
    seq: u64,
}

impl DriverStandIn {
    pub fn new(world: &World) -> DriverStandIn {
        DriverStandIn {
            imu: Port::create(world.node(), world.ipc()).unwrap(),
            thrust: Inbox::create(world.node(), world.ipc()).unwrap(),
            seq: 0,
        }
    }

    /// One sample and the time until its command came; None if none within 2 s.
    pub fn round_trip(&mut self) -> Option<Duration> {
        self.seq += 1;
        let seq = self.seq;
        let sample = ImuSample {
            seq,
            t_ns: 1_000_000_000 + seq * 5_000_000,
            gyro: [0.0; 3],
            accel: [0.0, 0.0, -9.80665],
            mag: [0.0; 3],
            depth: 0.0,
            flags: 0,
        };
        let start = Instant::now();
        self.imu.send(&sample).unwrap();
        while start.elapsed() < Duration::from_secs(2) {
            if let Some(c) = self.thrust.recv().unwrap() {
                if c.imu_seq == seq {
                    return Some(start.elapsed());
                }
            }
            std::thread::sleep(Duration::from_micros(50));
        }
        None
    }

    /// Round trips until one is answered (the daemon is up), at most `within`.
    pub fn until_answered(&mut self, within: Duration) -> bool {
        let up = Instant::now();
        while up.elapsed() < within {
            if self.round_trip().is_some() {
                return true;
            }
        }
        false
    }

    /// Round trips every `gap` while `done` says the thing under test still runs, and half a
    /// second beyond; panics on an unanswered sample or when it runs past `limit`.
    pub fn time_while(
        &mut self,
        mut done: impl FnMut() -> bool,
        gap: Duration,
        limit: Duration,
    ) -> Timed {
        let start = Instant::now();
        let mut timed = Timed {
            worst: Duration::ZERO,
            answered: 0,
            done_after: Duration::ZERO,
        };
        let mut done_at: Option<Instant> = None;
        while done_at.is_none_or(|t| t.elapsed() < Duration::from_millis(500)) {
            assert!(start.elapsed() < limit, "still running after {limit:?}");
            let latency = self
                .round_trip()
                .unwrap_or_else(|| panic!("sample {} unanswered", self.seq));
            timed.worst = timed.worst.max(latency);
            timed.answered += 1;
            if done_at.is_none() && done() {
                done_at = Some(Instant::now());
                timed.done_after = start.elapsed();
            }
            std::thread::sleep(gap);
        }
        timed
    }

    /// The sequence number of the last sample sent.
    pub fn seq(&self) -> u64 {
        self.seq
    }
}
