//! IMU sample -> thrust command latency through the real daemon, beside a raw iceoryx2
//! ping-pong of the same payloads (`thruster-sim respond`, which only validates and answers),
//! measured in the same run, in event mode and in low-latency (spin) mode; the daemon with
//! telemetry off, at its default (every 10th sample) and on every sample, each with a reader
//! subscribed to it (so every message is delivered and its listener woken).
//!
//! Then at 1 kHz (one sample per millisecond, the rate of a fast vehicle IMU), event mode,
//! telemetry at its default: the daemon alone, and with `thruster-bridge` attached (recording
//! to MCAP and serving the live view, one Foxglove client subscribed to every channel), runs
//! alternated; with the bridge's CPU over the run from /proc.
//!
//! Then the control thread under the daemon's long computations: IMU -> thrust at 200 Hz and
//! 1 kHz, 8 and 16 declared thrusters, while holding attitude (idle control), during an
//! open-loop estimation (a solve after every pulse) and during a closed-loop identification
//! (a solve every second of dither); p50 / p99 / p99.9 / max. Two schedulings: normal
//! (low-latency mode, the control thread spinning) and real-time (event mode, the control
//! thread at SCHED_FIFO 50 by `--realtime-priority`, the bench's driver thread at FIFO 60, as a
//! real driver's would be; needs root or CAP_SYS_NICE, else the rows say refused). Alone:
//! `BENCH_SOLVES_ONLY=1`; beside another build's daemon: `BENCH_BASELINE_THRUSTERD=PATH`
//! (each setting on it first, then on this build; with `BENCH_FIFO_ONLY=1` too the baseline
//! must know `--realtime-priority`, issue 25 on).
//!
//! Run: cargo bench -p system-tests --bench latency [-- ROUND_TRIPS]

use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

use system_tests::{state, Operator, Proc, World};
use thruster_protocol::services::{Inbox, Port};
use thruster_protocol::{DaemonState, ImuSample, RequestKind, TelemetryMsg, ThrustCommand};

const WARMUP: usize = 2_000;

struct Stats {
    p50: f64,
    p99: f64,
    p999: f64,
    mean: f64,
    max: f64,
}

fn stats(mut us: Vec<f64>) -> Stats {
    us.sort_by(|a, b| a.total_cmp(b));
    let q = |p: f64| us[((us.len() as f64 - 1.0) * p).round() as usize];
    Stats {
        p50: q(0.5),
        p99: q(0.99),
        p999: q(0.999),
        mean: us.iter().sum::<f64>() / us.len() as f64,
        max: us[us.len() - 1],
    }
}

/// Vehicle time between samples, ns (the sample's `t_ns` follows its `seq`): 1 kHz unless the
/// solve section sets another rate.
/// The latest the bench's thread woke after a paced sample's due time, since the last reset.
static WAKE_LATE_MAX_NS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

static SAMPLE_PERIOD_NS: std::sync::atomic::AtomicU64 =
    std::sync::atomic::AtomicU64::new(1_000_000);

fn sample(seq: u64) -> ImuSample {
    // A little deterministic noise (a hash of seq): an estimation measures the noise at rest
    // first, and a perfectly still gyro would make it zero.
    let h = |k: u64| {
        let x = seq
            .wrapping_mul(0x9E37_79B9_7F4A_7C15)
            .wrapping_add(k.wrapping_mul(0xBF58_476D_1CE4_E5B9));
        ((x >> 40) as f64 / (1u64 << 24) as f64) - 0.5
    };
    let period = SAMPLE_PERIOD_NS.load(std::sync::atomic::Ordering::Relaxed);
    ImuSample {
        seq,
        t_ns: 1_000_000_000 + seq * period,
        gyro: [
            0.001 + 0.01 * h(1),
            -0.002 + 0.01 * h(2),
            0.0005 + 0.01 * h(3),
        ],
        accel: [0.05 * h(4), 0.05 * h(5), -9.80665 + 0.05 * h(6)],
        mag: [20.0, 0.0, 45.0],
        depth: 5.0 + 0.001 * h(7),
        flags: ImuSample::HAS_MAG | ImuSample::HAS_DEPTH,
    }
}

/// One round trip per sample, busy-polling for the answer, one sample per `period` (None: back
/// to back). Microseconds.
fn round_trips(
    imu: &Port<ImuSample>,
    thrust: &Inbox<ThrustCommand>,
    seq: &mut u64,
    count: usize,
    period: Option<Duration>,
) -> Vec<f64> {
    let mut out = Vec::with_capacity(count);
    let t0 = Instant::now();
    for i in 0..count {
        if let Some(p) = period {
            // Sleep to the next tick (sleeping, not spinning: a spinning sender would take a
            // core from the processes measured).
            let due = t0 + p * i as u32;
            let now = Instant::now();
            if due > now {
                std::thread::sleep(due - now);
                // How late the bench's own thread woke: the machine's floor for any thread's
                // answer (what cyclictest measures), in the same run as the daemon's figures.
                let late = Instant::now().saturating_duration_since(due).as_nanos() as u64;
                WAKE_LATE_MAX_NS.fetch_max(late, std::sync::atomic::Ordering::Relaxed);
            }
        }
        *seq += 1;
        let start = Instant::now();
        imu.send(&sample(*seq)).unwrap();
        loop {
            if let Some(c) = thrust.recv().unwrap() {
                if c.imu_seq == *seq {
                    break;
                }
            }
            assert!(
                start.elapsed() < Duration::from_secs(5),
                "no answer to sample {seq}"
            );
            std::hint::spin_loop();
        }
        out.push(start.elapsed().as_secs_f64() * 1e6);
    }
    out
}

/// Ping-pong `n` samples after a handshake, `setup` and a warm-up.
fn ping_pong(world: &World, n: usize, setup: impl FnOnce()) -> Vec<f64> {
    ping_pong_at(world, n, None, WARMUP, setup)
}

/// The IMU port and thrust inbox on `world`, once the peer answers at all; the last sequence
/// number sent.
fn handshake(world: &World) -> (Port<ImuSample>, Inbox<ThrustCommand>, u64) {
    let imu: Port<ImuSample> = Port::create(world.node(), world.ipc()).unwrap();
    let thrust: Inbox<ThrustCommand> = Inbox::create(world.node(), world.ipc()).unwrap();
    let mut seq = 0u64;
    let start = Instant::now();
    loop {
        seq += 1;
        imu.send(&sample(seq)).unwrap();
        std::thread::sleep(Duration::from_millis(5));
        if thrust.recv().unwrap().is_some() {
            while thrust.recv().unwrap().is_some() {}
            return (imu, thrust, seq);
        }
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "peer never answered"
        );
    }
}

/// As [`ping_pong`], one sample per `period`, with `warmup` samples first.
fn ping_pong_at(
    world: &World,
    n: usize,
    period: Option<Duration>,
    warmup: usize,
    setup: impl FnOnce(),
) -> Vec<f64> {
    let (imu, thrust, mut seq) = handshake(world);
    setup();
    round_trips(&imu, &thrust, &mut seq, warmup, period);
    round_trips(&imu, &thrust, &mut seq, n, period)
}

fn daemon_config(world: &World, telemetry_every_n: u32) -> std::path::PathBuf {
    daemon_config_with(world, telemetry_every_n, 8, "")
}

/// `thrusters` declared thrusters (8, or 16: the eight again, farther out), telemetry every
/// `telemetry_every_n`-th sample, and `extra` TOML appended.
fn daemon_config_with(
    world: &World,
    telemetry_every_n: u32,
    thrusters: usize,
    extra: &str,
) -> std::path::PathBuf {
    // Eight declared thrusters (directions need not be unit: the daemon normalises them): the
    // daemon starts with a nominal model and can hold attitude.
    let mut text = String::from("[vehicle]\n");
    let eight = [
        ([0.15, -0.1, 0.0], [1.0, 1.0, 0.0]),
        ([0.15, 0.1, 0.0], [1.0, -1.0, 0.0]),
        ([-0.15, -0.1, 0.0], [1.0, -1.0, 0.0]),
        ([-0.15, 0.1, 0.0], [1.0, 1.0, 0.0]),
        ([0.12, -0.22, 0.0], [0.0, 0.0, 1.0]),
        ([0.12, 0.22, 0.0], [0.0, 0.0, -1.0]),
        ([-0.12, -0.22, 0.0], [0.0, 0.0, -1.0]),
        ([-0.12, 0.22, 0.0], [0.0, 0.0, 1.0]),
    ];
    for k in 0..thrusters {
        let (p, d) = eight[k % 8];
        let s = 1.0 + (k / 8) as f64 * 0.5;
        let p = [p[0] * s, p[1] * s, p[2] + 0.05 * (k / 8) as f64];
        text += &format!("[[vehicle.thruster]]\nposition_m = {p:?}\ndirection = {d:?}\n");
    }
    text += &format!("[telemetry]\nevery_n = {telemetry_every_n}\n");
    text += extra;
    let path = world.path("thrusterd.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// `thrusterd run` on `world` with telemetry every `every_n`-th sample.
fn start_daemon(world: &World, spin: &str, every_n: u32) -> Proc {
    let ns = world.namespace();
    let cfg = daemon_config(world, every_n);
    let state_dir = world.path("state");
    Proc::spawn(
        "thrusterd",
        &[
            "run",
            "--config",
            cfg.to_str().unwrap(),
            "--namespace",
            &ns,
            "--state-dir",
            state_dir.to_str().unwrap(),
            "--spin-us",
            spin,
        ],
        world.dir.path(),
    )
}

/// Hold attitude, so every sample runs the attitude filter and the controller.
fn hold(op: &Operator) {
    let r = op.request(RequestKind::Hold);
    assert!(r.is_ok(), "{}", r.text());
    op.wait_status(Duration::from_secs(10), |s| state(s) == DaemonState::Active)
        .expect("daemon active");
}

/// Round trips through `thrusterd run` holding attitude, telemetry every `every_n`-th sample
/// (0: off) with a reader attached.
fn through_daemon(n: usize, spin: &str, every_n: u32) -> Stats {
    let world = World::new("lat-d");
    let mut peer = start_daemon(&world, spin, every_n);
    let op = Operator::new(&world);
    // A reader as `thrusterctl watch --interval-ms 0` is, with the topic's full buffer: every
    // message is delivered and its listener notified. Read only after the run (reading here
    // would be measured); a full buffer drops its oldest, which costs the daemon the same.
    let telemetry: Inbox<TelemetryMsg> = Inbox::create(world.node(), world.ipc()).unwrap();
    let us = ping_pong(&world, n, || hold(&op));
    let got = telemetry.recv().unwrap().is_some();
    assert_eq!(
        got,
        every_n > 0,
        "telemetry every {every_n}: received {got}"
    );
    peer.stop();
    stats(us)
}

/// User + system CPU time of process `pid` so far, seconds (/proc/PID/stat fields 14 and 15).
fn cpu_s(pid: u32) -> f64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).expect("/proc/PID/stat");
    // The command name (field 2) is in parentheses and may hold spaces: split after it.
    let rest = &stat[stat.rfind(')').expect("stat has (comm)") + 2..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = fields[11].parse::<f64>().unwrap() + fields[12].parse::<f64>().unwrap();
    // SAFETY: sysconf only reads a constant.
    let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) } as f64;
    ticks / hz
}

/// The topside's Foxglove client (tests/node, `--watch`): subscribed to every channel for
/// `seconds`. Killed and reaped on drop.
struct Topside(Child);

impl Drop for Topside {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// `thruster-bridge` recording to `out` and serving one topside client, attached to `world`.
struct Attached {
    bridge: Proc,
    topside: Topside,
}

fn attach(world: &World, out: &std::path::Path, seconds: u64) -> Attached {
    let (bridge, port) = world.live_bridge(out);
    let client = system_tests::node::script("bridge_client.js")
        .arg(format!("ws://127.0.0.1:{port}"))
        .arg(seconds.to_string())
        .arg("--watch")
        .stdout(Stdio::null())
        .spawn()
        .expect("node runs the topside client");
    Attached {
        bridge,
        topside: Topside(client),
    }
}

/// Stops the client and the bridge; the bridge's summary line.
fn detach(a: Attached) -> String {
    let Attached {
        mut bridge,
        topside,
    } = a;
    drop(topside);
    bridge.signal("INT");
    bridge.wait_timeout(Duration::from_secs(30));
    let log = bridge.log_text();
    log.lines()
        .rev()
        .find(|l| l.contains("; lost "))
        .unwrap_or("(no summary)")
        .to_string()
}

/// The 1 kHz comparison, alone and with the bridge alternated against one running daemon
/// (event mode, telemetry every 10th sample, a model in force, holding). One daemon process
/// for all rounds: separate daemons per run differed by 2x in their median alone (32 vs 68
/// us), with where the scheduler placed them, more than the bridge's effect.
fn bridge_section(n: usize) {
    let n = n.min(10_000);
    // Rounds: BENCH_ROUNDS (default 5). Two rounds disagreed by more than the effect measured
    // (p50 ratio 1.02 in one, 1.47 in the next) on the 2-core VM.
    let rounds: usize = std::env::var("BENCH_ROUNDS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(5);
    let period = Some(Duration::from_millis(1));
    println!();
    println!(
        "IMU -> thrust at 1 kHz (event mode, telemetry every 10th, holding), {n} samples per run \
         after 1000 warm-up, {rounds} rounds, alone and with the bridge alternated on one \
         daemon, microseconds"
    );
    println!("| run | daemon | p50 | p99 | p99.9 | mean | bridge CPU (% of one core) |");
    println!("|---|---|---|---|---|---|---|");
    // The platform's own floor at this pace: the same paced round trips to a bare iceoryx2
    // echo (`thruster-sim respond`). Paced, each side sleeps between samples, and waking a
    // sleeping vCPU is what the tail of this row measures.
    let raw = {
        let world = World::new("lat-rp");
        let mut peer = Proc::spawn(
            "thruster-sim",
            &[
                "respond",
                "--namespace",
                &world.namespace(),
                "--count",
                "8",
                "--spin-us",
                "0",
            ],
            world.dir.path(),
        );
        let us = ping_pong_at(&world, n, period, 1000, || {});
        peer.stop();
        stats(us)
    };
    println!(
        "| - | raw iceoryx2 echo (thruster-sim respond) | {:.1} | {:.1} | {:.1} | {:.1} | |",
        raw.p50, raw.p99, raw.p999, raw.mean
    );
    let world = World::new("lat-b");
    let mut daemon = start_daemon(&world, "0", 10);
    let op = Operator::new(&world);
    let (imu, thrust, mut seq) = handshake(&world);
    hold(&op);
    round_trips(&imu, &thrust, &mut seq, 1000, period);
    let mut ratios = Vec::new();
    let mut p99_ratios = Vec::new();
    for round in 1..=rounds {
        let alone = stats(round_trips(&imu, &thrust, &mut seq, n, period));
        println!(
            "| {round} | alone | {:.1} | {:.1} | {:.1} | {:.1} | |",
            alone.p50, alone.p99, alone.p999, alone.mean
        );
        let out = world.path(&format!("bench-{round}.mcap"));
        let attached = attach(&world, &out, (n as u64 + 1000) / 1000 + 60);
        // Warm-up with the bridge and its client connected.
        round_trips(&imu, &thrust, &mut seq, 1000, period);
        let (c0, t0) = (cpu_s(attached.bridge.pid()), Instant::now());
        let with = stats(round_trips(&imu, &thrust, &mut seq, n, period));
        let cpu = (cpu_s(attached.bridge.pid()) - c0) / t0.elapsed().as_secs_f64() * 100.0;
        let summary = detach(attached);
        println!(
            "| {round} | with thruster-bridge (MCAP + live view, 1 client) | {:.1} | {:.1} | {:.1} | {:.1} | {cpu:.1} |",
            with.p50, with.p99, with.p999, with.mean
        );
        println!("|   | bridge: {summary} | | | | | |");
        ratios.push(with.p50 / alone.p50);
        p99_ratios.push(with.p99 / alone.p99);
    }
    daemon.stop();
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let each = |v: &[f64]| {
        v.iter()
            .map(|r| format!("{r:.2}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    println!(
        "p50 with/alone per round: {}; median {:.3}. p99 with/alone per round: {}; median {:.3} \
         (target: p50 within 1.10)",
        each(&ratios),
        median(&mut ratios.clone()),
        each(&p99_ratios),
        median(&mut p99_ratios.clone()),
    );
}

/// The statistics of `phase`'s round trips, with the latest wake-up of the bench's own thread
/// in it (microseconds).
fn measured(phase: impl FnOnce() -> Vec<f64>) -> (Stats, f64) {
    WAKE_LATE_MAX_NS.store(0, std::sync::atomic::Ordering::Relaxed);
    let s = stats(phase());
    let late = WAKE_LATE_MAX_NS.load(std::sync::atomic::Ordering::Relaxed) as f64 / 1e3;
    (s, late)
}

/// How the control thread is scheduled in the solve section.
#[derive(Clone, Copy, PartialEq)]
enum Scheduling {
    /// SCHED_OTHER, low-latency mode spinning for two periods so it never blocks between
    /// samples (the figures before real-time scheduling).
    NormalSpinning,
    /// Event mode (blocks between samples), the control thread at SCHED_FIFO 50 and the
    /// bench's own driver thread at FIFO 60.
    Fifo,
}

impl Scheduling {
    fn label(self) -> &'static str {
        match self {
            Scheduling::NormalSpinning => "normal, spinning",
            Scheduling::Fifo => "FIFO 50, event",
        }
    }
}

/// IMU -> thrust while the daemon holds, estimates and identifies, at `rate_hz` with
/// `thrusters` declared thrusters, under `scheduling`; paced samples, each phase measured for
/// `seconds`.
fn solve_phases(
    daemon_bin: Option<&std::path::Path>,
    scheduling: Scheduling,
    rate_hz: u64,
    thrusters: usize,
    seconds: f64,
) -> Vec<(&'static str, (Stats, f64))> {
    let period_ns = 1_000_000_000 / rate_hz;
    SAMPLE_PERIOD_NS.store(period_ns, std::sync::atomic::Ordering::Relaxed);
    let period = Duration::from_nanos(period_ns);
    let count = (seconds * rate_hz as f64) as usize;
    let world = World::new("lat-s");
    // The IMU watchdog off the bench's way: between phases the bench sends nothing while it
    // talks to the daemon.
    let cfg = daemon_config_with(&world, 10, thrusters, "[runtime]\nimu_timeout_ms = 10000\n");
    let spin = match scheduling {
        Scheduling::NormalSpinning => (2 * period_ns / 1000).to_string(),
        Scheduling::Fifo => "0".to_string(),
    };
    let state_dir = world.path("state");
    let namespace = world.namespace();
    let mut args = vec![
        "run",
        "--config",
        cfg.to_str().unwrap(),
        "--namespace",
        &namespace,
        "--state-dir",
        state_dir.to_str().unwrap(),
        "--spin-us",
        &spin,
    ];
    if scheduling == Scheduling::Fifo {
        args.extend(["--realtime-priority", "50"]);
    }
    let mut daemon = match daemon_bin {
        Some(path) => Proc::spawn_path(path, "thrusterd", &args, &[], world.dir.path()),
        None => Proc::spawn("thrusterd", &args, world.dir.path()),
    };
    let op = Operator::new(&world);
    let (imu, thrust, mut seq) = handshake(&world);
    if scheduling == Scheduling::Fifo {
        let control = control_thread_scheduling(daemon.pid());
        assert_eq!(
            control,
            Some((libc::SCHED_FIFO, 50)),
            "the daemon's control thread is not at FIFO 50 (its threads: {:?})",
            thread_schedulings(daemon.pid())
        );
    }
    hold(&op);
    round_trips(&imu, &thrust, &mut seq, rate_hz as usize, Some(period));
    let mut out = Vec::new();
    let idle = measured(|| round_trips(&imu, &thrust, &mut seq, count, Some(period)));
    out.push(("holding (idle control)", idle));

    // Open loop: from Idle, the noise at rest (1 s, skipped), then pulses with a solve after
    // each (the synthetic vehicle never answers the thrust, so the run goes to its limit).
    let r = op.request(RequestKind::Idle);
    assert!(r.is_ok(), "{}", r.text());
    let r = op.request(RequestKind::Estimate);
    assert!(r.is_ok(), "{}", r.text());
    round_trips(
        &imu,
        &thrust,
        &mut seq,
        (1.2 * rate_hz as f64) as usize,
        Some(period),
    );
    let est = measured(|| round_trips(&imu, &thrust, &mut seq, count, Some(period)));
    out.push(("estimating (open loop)", est));
    // What the daemon was doing at the end of the phase (it must still be estimating).
    let after_estimation = op.request(RequestKind::Status).text().to_string();

    // Closed loop: holding, then an estimate request identifies under control, a solve every
    // second of dither (the first 0.5 s, the hold before the dither, skipped).
    let r = op.request(RequestKind::Hold);
    assert!(r.is_ok(), "{}", r.text());
    round_trips(&imu, &thrust, &mut seq, rate_hz as usize, Some(period));
    let r = op.request(RequestKind::Estimate);
    assert!(r.is_ok(), "{}", r.text());
    round_trips(&imu, &thrust, &mut seq, rate_hz as usize / 2, Some(period));
    let ident = measured(|| round_trips(&imu, &thrust, &mut seq, count, Some(period)));
    out.push(("identifying (closed loop)", ident));
    let after_identification = op.request(RequestKind::Status).text().to_string();
    println!(
        "    ({rate_hz} Hz, N = {thrusters}: after estimating \"{after_estimation}\"; after identifying \"{after_identification}\")"
    );
    daemon.stop();
    out
}

/// The solve section's table. With `BENCH_BASELINE_THRUSTERD=PATH` (another build's
/// binary, e.g. the commit before the solver thread), each setting runs on that daemon first and
/// then on this build's, back to back, so both see the same background load.
fn solve_section(seconds: f64) {
    let baseline = std::env::var_os("BENCH_BASELINE_THRUSTERD").map(std::path::PathBuf::from);
    println!();
    println!(
        "IMU -> thrust while holding, estimating and identifying (paced, \
         {seconds} s per phase), microseconds"
    );
    // The bench is the driver: at FIFO 60 (above the daemon's 50) its sleep to the next
    // sample and its wait for the answer are not stretched by the machine's other work. Reset
    // on fork: the processes it starts run normally until they raise themselves.
    let fifo = match thruster_driver_kit::realtime::make_this_thread_fifo(60) {
        Ok(()) => true,
        Err(e) => {
            println!("(real-time rows not measured: the bench's thread: {e})");
            false
        }
    };
    println!(
        "| daemon | scheduling | rate | N | phase | p50 | p99 | p99.9 | max | p99.9 / holding's | bench's latest wake-up |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    // A subset for a closer look: BENCH_RATES=1000, BENCH_NS=16, BENCH_FIFO_ONLY=1.
    let list = |var: &str, all: &[u64]| -> Vec<u64> {
        std::env::var(var)
            .ok()
            .map(|v| v.split(',').filter_map(|x| x.trim().parse().ok()).collect())
            .unwrap_or_else(|| all.to_vec())
    };
    let fifo_only = std::env::var_os("BENCH_FIFO_ONLY").is_some();
    for rate in list("BENCH_RATES", &[200, 1000]) {
        for n in list("BENCH_NS", &[8, 16]).into_iter().map(|n| n as usize) {
            let mut schedulings = Vec::new();
            if !fifo_only {
                schedulings.push(Scheduling::NormalSpinning);
            }
            if fifo {
                schedulings.push(Scheduling::Fifo);
            }
            // Each scheduling on the baseline first, then on this build, back to back.
            let mut runs = Vec::new();
            for scheduling in schedulings {
                if let Some(b) = &baseline {
                    runs.push(("baseline", Some(b.as_path()), scheduling));
                }
                runs.push(("this build", None, scheduling));
            }
            for (label, bin, scheduling) in runs {
                let phases = solve_phases(bin, scheduling, rate, n, seconds);
                let idle = phases[0].1 .0.p999;
                for (phase, (s, late)) in &phases {
                    println!(
                        "| {label} | {} | {rate} Hz | {n} | {phase} | {:.1} | {:.1} | {:.1} | {:.1} | {:.2} | {late:.1} |",
                        scheduling.label(),
                        s.p50,
                        s.p99,
                        s.p999,
                        s.max,
                        s.p999 / idle
                    );
                }
            }
        }
    }
    SAMPLE_PERIOD_NS.store(1_000_000, std::sync::atomic::Ordering::Relaxed);
}

/// Every thread of `pid`: (tid, policy, priority), from /proc/PID/task/TID/stat (fields 40
/// and 41: rt_priority, policy).
fn thread_schedulings(pid: u32) -> Vec<(u32, i32, i32)> {
    let mut out = Vec::new();
    let Ok(tasks) = std::fs::read_dir(format!("/proc/{pid}/task")) else {
        return out;
    };
    for t in tasks.flatten() {
        let Ok(stat) = std::fs::read_to_string(t.path().join("stat")) else {
            continue;
        };
        // The command name (field 2) may hold spaces: count fields after its ')'.
        let Some(rest) = stat.rsplit_once(')').map(|(_, r)| r) else {
            continue;
        };
        let f: Vec<&str> = rest.split_whitespace().collect();
        // rest starts at field 3, so field k is f[k - 3].
        if let (Some(prio), Some(policy)) = (f.get(37), f.get(38)) {
            let tid = t.file_name().to_string_lossy().parse().unwrap_or(0);
            out.push((
                tid,
                policy.parse().unwrap_or(-1),
                prio.parse().unwrap_or(-1),
            ));
        }
    }
    out
}

/// The one FIFO thread of `pid` (policy, priority), or None when it has none or several.
fn control_thread_scheduling(pid: u32) -> Option<(i32, i32)> {
    let fifo: Vec<_> = thread_schedulings(pid)
        .into_iter()
        .filter(|&(_, policy, _)| policy == libc::SCHED_FIFO)
        .collect();
    match fifo.as_slice() {
        [(_, policy, prio)] => Some((*policy, *prio)),
        _ => None,
    }
}

fn main() {
    // Never measure a binary left from an older build.
    system_tests::build_binaries();
    // Only the solve section: BENCH_SOLVES_ONLY=1 (BENCH_SOLVE_S: seconds per phase, 8).
    let solve_s: f64 = std::env::var("BENCH_SOLVE_S")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(8.0);
    if std::env::var_os("BENCH_SOLVES_ONLY").is_some() {
        solve_section(solve_s);
        return;
    }
    let n: usize = std::env::args()
        .skip(1)
        .find_map(|a| a.parse().ok())
        .unwrap_or(20_000);
    // Only the 1 kHz bridge comparison: BENCH_BRIDGE_ONLY=1.
    if std::env::var_os("BENCH_BRIDGE_ONLY").is_some() {
        bridge_section(n);
        return;
    }
    println!(
        "IMU sample -> thrust command round trip, {n} samples after {WARMUP} warm-up, microseconds"
    );
    println!("| mode | path | p50 | p99 | p99.9 | mean | p50 ratio daemon/raw |");
    println!("|---|---|---|---|---|---|---|");
    for (mode, spin) in [
        ("event (spin 0)", "0"),
        ("low-latency (spin 1000 us)", "1000"),
    ] {
        let raw = {
            let world = World::new("lat-raw");
            let ns = world.namespace();
            let mut peer = Proc::spawn(
                "thruster-sim",
                &[
                    "respond",
                    "--namespace",
                    &ns,
                    "--count",
                    "8",
                    "--spin-us",
                    spin,
                ],
                world.dir.path(),
            );
            let us = ping_pong(&world, n, || {});
            peer.stop();
            stats(us)
        };
        let mut rows = vec![("raw iceoryx2 ping-pong".to_string(), raw, None)];
        for (what, every_n) in [
            ("telemetry off", 0),
            ("telemetry every 10th, default", 10),
            ("telemetry every sample", 1),
        ] {
            let s = through_daemon(n, spin, every_n);
            let ratio = s.p50 / rows[0].1.p50;
            rows.push((
                format!("through thrusterd (controlling, {what})"),
                s,
                Some(ratio),
            ));
        }
        for (path, s, ratio) in &rows {
            let ratio = ratio.map_or_else(String::new, |r| format!("{r:.2}"));
            println!(
                "| {mode} | {path} | {:.1} | {:.1} | {:.1} | {:.1} | {ratio} |",
                s.p50, s.p99, s.p999, s.mean
            );
        }
    }
    bridge_section(n);
    solve_section(solve_s);
}
