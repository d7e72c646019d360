//! Raw iceoryx2 round-trip latency of the protocol's hot path: the parent plays the
//! driver (sends an `ImuSample`), a child process plays the daemon (answers with a
//! `ThrustCommand`), the parent times the round trip.
//!
//! ```text
//! cargo run --release -p thruster-protocol --example pingpong [-- MODE [ITERATIONS]]
//! ```
//!
//! Modes (default: all three):
//! - `event`: sender publishes then notifies; the child blocks in a WaitSet, the parent
//!   blocks on its listener. What a daemon sleeping between samples sees.
//! - `poll`: publish only, both sides spin on `receive()`. The floor of iceoryx2 itself.
//! - `poll-notify`: both sides spin but senders still notify (the cost of the notify
//!   syscall when a spinning daemon talks to notifying drivers).
//!
//! Prints p50/p90/p99/max of the round trip in microseconds; one way is about half. The
//! namespace is unique and purged afterwards.

use std::process::{Command, ExitCode};
use std::time::{Duration, Instant};

use iceoryx2::prelude::CallbackProgression;
use thruster_protocol::services::{create_waitset, Inbox, IpcConfig, NamespaceGuard, Port};
use thruster_protocol::{ImuSample, ThrustCommand, ThrustMode};

const WARMUP: usize = 500;
const WAIT: Duration = Duration::from_secs(2);

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Mode {
    Event,
    Poll,
    PollNotify,
}

impl Mode {
    fn parse(s: &str) -> Option<Self> {
        match s {
            "event" => Some(Mode::Event),
            "poll" => Some(Mode::Poll),
            "poll-notify" => Some(Mode::PollNotify),
            _ => None,
        }
    }

    fn name(self) -> &'static str {
        match self {
            Mode::Event => "event",
            Mode::Poll => "poll",
            Mode::PollNotify => "poll-notify",
        }
    }

    fn notifies(self) -> bool {
        self != Mode::Poll
    }

    fn default_iterations(self) -> usize {
        match self {
            Mode::Event => 5_000,
            Mode::Poll | Mode::PollNotify => 20_000,
        }
    }
}

type AnyError = Box<dyn std::error::Error>;

fn send<T: thruster_protocol::services::TopicMessage>(
    port: &Port<T>,
    msg: &T,
    mode: Mode,
) -> Result<(), AnyError> {
    if mode.notifies() {
        port.send(msg)?;
    } else {
        // Publish without the notify syscall: the receiver spins anyway.
        port.publisher().send_copy(*msg)?;
    }
    Ok(())
}

/// Spins until a message arrives or `WAIT` passes.
fn spin_recv<T: thruster_protocol::services::TopicMessage>(
    inbox: &Inbox<T>,
) -> Result<T, AnyError> {
    let start = Instant::now();
    loop {
        if let Some(m) = inbox.recv()? {
            return Ok(m);
        }
        if start.elapsed() > WAIT {
            return Err("timed out spinning".into());
        }
        std::hint::spin_loop();
    }
}

/// Blocks on the listener until a message arrives or `WAIT` passes.
fn blocking_recv<T: thruster_protocol::services::TopicMessage>(
    inbox: &Inbox<T>,
) -> Result<T, AnyError> {
    let start = Instant::now();
    loop {
        if let Some(m) = inbox.recv()? {
            return Ok(m);
        }
        if start.elapsed() > WAIT {
            return Err("timed out waiting".into());
        }
        inbox.wait(WAIT)?;
    }
}

/// The "daemon": answers `total` samples, then exits (dropping everything cleanly).
fn child(ns: &str, mode: Mode, total: usize) -> Result<(), AnyError> {
    let ipc = IpcConfig::new(ns)?;
    let node = ipc.create_node("pingpong-daemon")?;
    let imu_in = Inbox::<ImuSample>::create(&node, &ipc)?;
    let thrust_out = Port::<ThrustCommand>::create(&node, &ipc)?;

    // Handshake: say hello until the parent's subscriber is connected.
    let hello = ThrustCommand::neutral(0, 0, 0, 0);
    let start = Instant::now();
    while thrust_out.send(&hello)? == 0 {
        if start.elapsed() > WAIT {
            return Err("parent never connected".into());
        }
        std::thread::sleep(Duration::from_millis(1));
    }

    let waitset = create_waitset()?;
    let guard = waitset.attach_notification(imu_in.listener())?;
    let mut answered = 0;
    let reply = |s: ImuSample| -> Result<(), AnyError> {
        let mut cmd = ThrustCommand::neutral(s.seq, s.seq, s.t_ns, 8);
        cmd.set_mode(ThrustMode::Controlling);
        cmd.thrusters_mut().fill(0.1);
        send(&thrust_out, &cmd, mode)
    };
    while answered < total {
        match mode {
            Mode::Event => {
                let mut result: Result<(), AnyError> = Ok(());
                waitset.wait_and_process_once_with_timeout(
                    |id| {
                        if id.has_event_from(&guard) {
                            result = (|| -> Result<(), AnyError> {
                                imu_in.drain_events()?;
                                while let Some(s) = imu_in.recv()? {
                                    reply(s)?;
                                    answered += 1;
                                }
                                Ok(())
                            })();
                        }
                        CallbackProgression::Continue
                    },
                    WAIT,
                )?;
                result?;
            }
            Mode::Poll | Mode::PollNotify => {
                let s = spin_recv(&imu_in)?;
                reply(s)?;
                answered += 1;
            }
        }
    }
    Ok(())
}

/// The "driver": sends samples one at a time and times each answer.
fn run(ipc: &IpcConfig, mode: Mode, iterations: usize) -> Result<Vec<f64>, AnyError> {
    let node = ipc.create_node("pingpong-driver")?;
    let imu_out = Port::<ImuSample>::create(&node, ipc)?;
    let thrust_in = Inbox::<ThrustCommand>::create(&node, ipc)?;
    let total = iterations + WARMUP;
    let mut child = Command::new(std::env::current_exe()?)
        .args(["child", ipc.namespace(), mode.name(), &total.to_string()])
        .spawn()?;

    let result = (|| -> Result<Vec<f64>, AnyError> {
        let hello = blocking_recv(&thrust_in)?;
        if hello.seq != 0 {
            return Err("expected hello".into());
        }
        // Drop extra hellos the child sent before it saw us.
        while thrust_in.recv()?.is_some() {}
        thrust_in.drain_events()?;

        let mut rtt_us = Vec::with_capacity(iterations);
        for seq in 1..=total as u64 {
            let sample = ImuSample {
                seq,
                t_ns: seq * 2_500_000,
                accel: [0.0, 0.0, -9.81],
                ..Default::default()
            };
            let t0 = Instant::now();
            send(&imu_out, &sample, mode)?;
            let cmd = match mode {
                Mode::Event => blocking_recv(&thrust_in)?,
                Mode::Poll | Mode::PollNotify => spin_recv(&thrust_in)?,
            };
            let dt = t0.elapsed();
            if cmd.imu_seq != seq {
                return Err(format!("answer to {} while waiting for {seq}", cmd.imu_seq).into());
            }
            if seq as usize > WARMUP {
                rtt_us.push(dt.as_secs_f64() * 1e6);
            }
        }
        Ok(rtt_us)
    })();

    if result.is_err() {
        let _ = child.kill();
    }
    // Always reap the child: an unreaped zombie still counts as a live node.
    let status = child.wait()?;
    let rtt = result?;
    if !status.success() {
        return Err(format!("child failed: {status}").into());
    }
    Ok(rtt)
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    let idx = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted[idx]
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().collect();
    if args.get(1).map(String::as_str) == Some("child") {
        let (Some(ns), Some(mode), Some(total)) = (
            args.get(2),
            args.get(3).and_then(|m| Mode::parse(m)),
            args.get(4).and_then(|n| n.parse().ok()),
        ) else {
            eprintln!("usage: pingpong child NAMESPACE MODE TOTAL");
            return ExitCode::FAILURE;
        };
        return match child(ns, mode, total) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("child: {e}");
                ExitCode::FAILURE
            }
        };
    }

    let modes: Vec<Mode> = match args.get(1) {
        None => vec![Mode::Event, Mode::Poll, Mode::PollNotify],
        Some(m) => match Mode::parse(m) {
            Some(m) => vec![m],
            None => {
                eprintln!("usage: pingpong [event|poll|poll-notify] [ITERATIONS]");
                return ExitCode::FAILURE;
            }
        },
    };
    let iterations: Option<usize> = args.get(2).and_then(|n| n.parse().ok());

    let ipc = match NamespaceGuard::unique_for_test("pp") {
        Ok(g) => g,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::FAILURE;
        }
    };
    println!(
        "ImuSample {} B -> ThrustCommand {} B, namespace {}",
        std::mem::size_of::<ImuSample>(),
        std::mem::size_of::<ThrustCommand>(),
        ipc.namespace()
    );
    println!(
        "{:<12} {:>7} {:>9} {:>9} {:>9} {:>9}   (round trip, us)",
        "mode", "n", "p50", "p90", "p99", "max"
    );
    for mode in modes {
        let n = iterations.unwrap_or(mode.default_iterations());
        match run(&ipc, mode, n) {
            Ok(mut rtt) => {
                rtt.sort_by(f64::total_cmp);
                println!(
                    "{:<12} {:>7} {:>9.1} {:>9.1} {:>9.1} {:>9.1}",
                    mode.name(),
                    rtt.len(),
                    percentile(&rtt, 0.5),
                    percentile(&rtt, 0.9),
                    percentile(&rtt, 0.99),
                    rtt[rtt.len() - 1]
                );
            }
            Err(e) => {
                eprintln!("{}: {e}", mode.name());
                return ExitCode::FAILURE;
            }
        }
    }
    ExitCode::SUCCESS
}
