//! IMU samples whose notifications stop reaching the daemon, with the real daemon in lockstep
//! and the test as its driver over real iceoryx2: every sample is still answered (on the
//! loop's other wake-ups), the daemon says the notifications stopped and names its listener's
//! socket as the kernel has it, replaces the listener when re-arming does not bring them back,
//! the driver's notifier reaches the new one, and the daemon says when they wake it again.
//! Why: twice a lockstep run crawled for minutes at 11 samples/s with nothing in either log
//! (docs/reliability.md).

use std::time::{Duration, Instant};

use system_tests::World;
use thruster_protocol::services::{Inbox, Port};
use thruster_protocol::{ImuSample, ThrustCommand};

const PERIOD_NS: u64 = 5_000_000;

struct Driver {
    imu: Port<ImuSample>,
    thrust: Inbox<ThrustCommand>,
    seq: u64,
}

impl Driver {
    fn sample(&mut self) -> ImuSample {
        self.seq += 1;
        ImuSample {
            seq: self.seq,
            t_ns: self.seq * PERIOD_NS,
            gyro: [0.0, 0.0, 0.0],
            accel: [0.0, 0.0, -9.80665],
            mag: [20.0, 0.0, 45.0],
            depth: 5.0,
            flags: ImuSample::HAS_MAG | ImuSample::HAS_DEPTH,
        }
    }

    /// Publishes the next sample (notifying or not) and waits for its answer; how long it
    /// took, or None if nothing answered it within `within`.
    fn step(&mut self, notify: bool, within: Duration) -> Option<Duration> {
        let s = self.sample();
        let start = Instant::now();
        if notify {
            self.imu.send(&s).unwrap();
        } else {
            // The sample without its notification: what the daemon saw in the stalls.
            self.imu.publisher().send_copy(s).unwrap();
        }
        while start.elapsed() < within {
            while let Some(c) = self.thrust.recv().unwrap() {
                assert!(
                    c.thrusters()
                        .iter()
                        .all(|v| v.is_finite() && v.abs() <= 1.0),
                    "{c:?}"
                );
                if c.imu_seq == s.seq {
                    return Some(start.elapsed());
                }
            }
            std::thread::sleep(Duration::from_micros(200));
        }
        None
    }
}

#[test]
fn samples_without_their_notifications_are_answered_and_the_stop_is_named() {
    let world = World::new("nonotify");
    {
        let mut daemon = world.daemon(&["--thrusters", "4", "--lockstep"]);
        let mut d = Driver {
            imu: Port::create(world.node(), world.ipc()).unwrap(),
            thrust: Inbox::create(world.node(), world.ipc()).unwrap(),
            seq: 0,
        };
        // The first sample again until the daemon subscribes and answers.
        let first = Instant::now();
        loop {
            d.seq = 0;
            if d.step(true, Duration::from_millis(200)).is_some() {
                break;
            }
            assert!(
                first.elapsed() < Duration::from_secs(30),
                "the daemon never answered\n{}",
                daemon.log_text()
            );
        }
        let within = Duration::from_secs(5);
        let phase = |d: &mut Driver, notify: bool, n: usize| -> Vec<Duration> {
            (0..n)
                .map(|_| {
                    d.step(notify, within).unwrap_or_else(|| {
                        panic!(
                            "sample {} (notify {notify}) unanswered\n{}",
                            d.seq,
                            daemon.log_text()
                        )
                    })
                })
                .collect()
        };
        let before = phase(&mut d, true, 40);
        // Past the re-arm (3rd wake-up) and the replacement (10th).
        let without = phase(&mut d, false, 14);
        let after = phase(&mut d, true, 40);
        let median = |v: &[Duration]| {
            let mut v = v.to_vec();
            v.sort();
            v[v.len() / 2]
        };
        println!(
            "answer latency, median: notified {:?}, without notifications {:?}, notified again {:?}",
            median(&before),
            median(&without),
            median(&after)
        );
        // Unnotified samples wait for the loop's own wake-ups (its 100 ms status period and
        // IMU deadline): an answer far quicker than that would mean they were not unnotified.
        assert!(median(&without) >= Duration::from_millis(20), "{without:?}");
        // The driver's notifier found the replaced listener: notified samples wake the daemon
        // again (answered in well under a millisecond on the idle VM; its 100 ms wake-ups
        // otherwise).
        assert!(median(&after) < Duration::from_millis(20), "{after:?}");
        daemon.stop();
        let log = daemon.log_text();
        for line in log.lines().filter(|l| {
            l.contains("IMU notifications")
                || l.contains("IMU listener")
                || l.contains("without their notifications")
        }) {
            println!("{line}");
        }
        assert!(
            log.contains(
                "IMU samples are being read without their notifications (3 wake-ups in a row)"
            ),
            "{log}"
        );
        assert!(
            log.contains("listener fd ") && log.contains("-> socket:["),
            "the listener's socket is named: {log}"
        );
        assert!(
            log.contains("IMU notifications wake this loop again"),
            "{log}"
        );
        assert_eq!(
            log.matches("IMU listener replaced").count(),
            1,
            "replaced once: {log}"
        );
        assert!(!log.contains("left open"), "{log}");
        // Said once per stop, not per sample.
        assert_eq!(
            log.matches("IMU samples are being read without").count(),
            1,
            "{log}"
        );
    }
    world.assert_nothing_left();
}
