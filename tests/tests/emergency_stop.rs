//! The emergency stop end to end: the real `thrusterd run` and `thruster-sim run --realtime`
//! (AMOUR-5, 200 Hz) on a private namespace, the stop requested over the control service as
//! `thrusterctl stop` and the bridge's `thrusterd/stop` send it. From Pulse, Active and Identify
//! the daemon's answer to the very next IMU sample after the stop (one control period) is
//! neutral, all zeros, and so is every answer after it while the stop holds.
//!
//! "After the stop" is exact: the daemon journals each request it hands the machine on the
//! `input` topic with the last sample before it (`imu_seq`), so the first command after the
//! stop is the one answering sample `imu_seq + 1`.

use std::time::{Duration, Instant};

use system_tests::{state, Operator, World};
use thruster_protocol::services::Inbox;
use thruster_protocol::{
    DaemonState, InputKind, InputMsg, RequestKind, ResponseCode, ThrustCommand, ThrustMode,
};

const LONG: Duration = Duration::from_secs(60);

struct Watch {
    thrust: Inbox<ThrustCommand>,
    input: Inbox<InputMsg>,
}

impl Watch {
    /// Every thrust command buffered now and arriving for `d` (drained as they come).
    fn thrust_for(&self, d: Duration) -> Vec<ThrustCommand> {
        let mut out = Vec::new();
        let end = Instant::now() + d;
        loop {
            while let Some(c) = self.thrust.recv().unwrap() {
                out.push(c);
            }
            if Instant::now() >= end {
                return out;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    }

    /// The journal entry of the stop request.
    fn stop_entry(&self) -> InputMsg {
        let end = Instant::now() + Duration::from_secs(5);
        while Instant::now() < end {
            while let Some(m) = self.input.recv().unwrap() {
                if m.kind() == Ok(InputKind::Request) && m.code == RequestKind::Stop.as_u32() {
                    return m;
                }
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        panic!("no journal entry for the stop request");
    }
}

/// Stops the daemon, which was just seen in state `from`, and checks the commands around the
/// stop: the answer to the last sample before it drove the thrusters, the answer to the next
/// one and every later one are neutral.
fn stop_from(op: &Operator, watch: &Watch, from: DaemonState) {
    // Only recent commands in the inbox (its 128 hold 0.6 s at 200 Hz).
    let mut seen = watch.thrust_for(Duration::ZERO);
    let r = op.request(RequestKind::Stop);
    assert_eq!(r.code(), Ok(ResponseCode::Ok), "{from:?}: {r:?}");
    assert!(r.text().contains("emergency stop"), "{r:?}");
    let entry = watch.stop_entry();
    assert_eq!(entry.refused, 0);
    seen.extend(watch.thrust_for(Duration::from_millis(500)));
    let last_before = seen
        .iter()
        .find(|c| c.imu_seq == entry.imu_seq)
        .unwrap_or_else(|| panic!("{from:?}: no command for sample {}", entry.imu_seq));
    // Open-loop pulses and identification under control send Estimating commands, a hold
    // Controlling: the state at the stop, as the thrusters saw it.
    let driving = match from {
        DaemonState::Active => ThrustMode::Controlling,
        _ => ThrustMode::Estimating,
    };
    assert_eq!(last_before.mode(), Ok(driving), "{from:?}: {last_before:?}");
    assert!(
        last_before.thrusters().iter().any(|v| *v != 0.0),
        "{from:?}: the thrusters were not driven at the stop: {last_before:?}"
    );
    let after: Vec<&ThrustCommand> = seen.iter().filter(|c| c.imu_seq > entry.imu_seq).collect();
    let first = after
        .iter()
        .min_by_key(|c| c.imu_seq)
        .unwrap_or_else(|| panic!("{from:?}: no command after the stop"));
    // One control period: the answer to the next sample.
    assert_eq!(first.imu_seq, entry.imu_seq + 1, "{from:?}");
    assert!(
        after.len() >= 50,
        "{from:?}: {} commands in 0.5 s",
        after.len()
    );
    for c in &after {
        assert_eq!(c.mode(), Ok(ThrustMode::Neutral), "{from:?}: {c:?}");
        assert!(
            c.thrusters().iter().all(|v| *v == 0.0),
            "{from:?}: sample {}: {:?}",
            c.imu_seq,
            c.thrusters()
        );
    }
    let idle = op
        .wait_status(Duration::from_secs(2), |s| state(s) == DaemonState::Idle)
        .expect("idle after the stop");
    assert!(idle.text().contains("emergency stop"), "{idle:?}");
}

#[test]
fn the_emergency_stop_is_neutral_from_the_next_sample_in_pulse_active_and_identify() {
    let world = World::new("estop");
    let op = Operator::new(&world);
    let watch = Watch {
        thrust: Inbox::create_with_buffer(world.node(), world.ipc(), 128).unwrap(),
        input: Inbox::create(world.node(), world.ipc()).unwrap(),
    };
    let mut daemon = world.daemon(&["--thrusters", "5"]);
    let mut sim = world.sim(
        "amour5",
        &["--realtime", "--noise", "realistic", "--duration", "300"],
    );
    op.wait_status(LONG, |s| s.samples > 50)
        .unwrap_or_else(|| panic!("no samples\n{}", daemon.log_text()));

    // Pulse: an open-loop estimation from rest.
    assert!(op.request(RequestKind::Estimate).is_ok());
    op.wait_status(LONG, |s| state(s) == DaemonState::Pulse)
        .unwrap_or_else(|| panic!("no pulse\n{}", daemon.log_text()));
    stop_from(&op, &watch, DaemonState::Pulse);

    // Active: estimate to the end, then the daemon holds with the new model. The vehicle
    // still swings from the stopped pulse; the noise rest waits for that
    // (`machine.max_rest_swing_radps`; before it, CI saw all three estimates here refused as
    // unexplained rotation: docs/reliability.md, "An estimate right after the thrusters
    // stopped"). A refusal is still the daemon's job, not this test's subject, so the estimate
    // is asked again, at most three times.
    let mut tries = 0;
    let active = loop {
        tries += 1;
        assert!(op.request(RequestKind::Estimate).is_ok());
        op.wait_status(LONG, |s| state(s) != DaemonState::Idle)
            .unwrap_or_else(|| panic!("not estimating\n{}", daemon.log_text()));
        let ended = op
            .wait_status(LONG, |s| {
                matches!(state(s), DaemonState::Active | DaemonState::Idle)
            })
            .unwrap_or_else(|| panic!("no model\n{}", daemon.log_text()));
        if state(&ended) == DaemonState::Active || tries == 3 {
            break ended;
        }
    };
    assert_eq!(
        state(&active),
        DaemonState::Active,
        "no model in {tries} estimates\n{}",
        daemon.log_text()
    );
    std::thread::sleep(Duration::from_millis(500));
    op.wait_status(LONG, |s| state(s) == DaemonState::Active)
        .expect("still holding");
    stop_from(&op, &watch, DaemonState::Active);

    // Identify: hold, then estimate under control.
    assert!(op.request(RequestKind::Hold).is_ok());
    std::thread::sleep(Duration::from_millis(1500));
    assert!(op.request(RequestKind::Estimate).is_ok());
    op.wait_status(LONG, |s| state(s) == DaemonState::Identify)
        .unwrap_or_else(|| panic!("no identification\n{}", daemon.log_text()));
    std::thread::sleep(Duration::from_millis(1200));
    op.wait_status(LONG, |s| state(s) == DaemonState::Identify)
        .expect("still identifying");
    stop_from(&op, &watch, DaemonState::Identify);

    // In any state: idle and fault included, answered OK.
    let r = op.request(RequestKind::Stop);
    assert_eq!(r.code(), Ok(ResponseCode::Ok), "{r:?}");

    sim.signal("INT");
    let _ = sim.wait_timeout(Duration::from_secs(10));
    assert!(daemon.stop().success(), "{}", daemon.log_text());
    drop(watch);
    drop(op);
    drop(sim);
    drop(daemon);
    world.assert_nothing_left();
}
