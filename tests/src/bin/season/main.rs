//! A season-long soak in accelerated time (issue 25, item 4): thrusterd and thruster-sim as
//! real processes over iceoryx2, the simulator in lockstep (no faster than `--pace` times
//! real time), for many vehicle-hours, with what a pool day brings: an estimate every 20
//! vehicle-minutes, a reconfiguration every vehicle-hour (the simulator's scenario rotates a
//! thruster and announces it), a fresh operator client asking for the status every
//! vehicle-second, `thrusterctl watch` clients coming and going (SIGTERM, every third SIGKILL)
//! and a recorder rotating files once an hour.
//!
//! Every operator action is scheduled on the vehicle time the daemon's status carries, never
//! on the wall clock. At the start, every vehicle-hour and the end it reports IMU samples lost,
//! commands late, RSS and open descriptors of both processes, and the files and bytes of the
//! namespace in /dev/shm and under the ipc root; the verdict (tests/src/season.rs) names what
//! grew. Exit status 1 on a failed verdict or a process that died, 130 when interrupted.
//!
//! Run (see docs/reliability.md, "Season soak"):
//!   cargo build -p thrusterd -p thrusterctl -p thruster-sim -p system-tests --bins
//!   target/debug/season --hours 8 --out out/season

mod clients;
mod polls;
mod probe;
mod stall;

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::Parser;
use system_tests::season::{
    row_text, scenario_toml, verdict, Ending, Lag, Limits, Link, Plan, Row, Ticker, HEADER,
    NS_PER_S,
};
use system_tests::soak::DaemonCounts;
use system_tests::{bin, state, Proc, World, BIN_DIR_ENV};
use thruster_driver_kit::Shutdown;
use thruster_protocol::services::{cleanup_dead_nodes, namespace_files, tidy_residue, Inbox};
use thruster_protocol::{DriverStatusMsg, StatusMsg};

use clients::{end_recording, end_watch, Recording, Watch, MIN_LIFE};
use polls::{ctl_quiet, estimate, Inflight, Pollers};
use probe::{census, file_names, load1, proc_figures};
use stall::StallWatch;

#[derive(Parser)]
#[command(
    name = "season",
    about = "A season-long soak of thrusterd + thruster-sim in accelerated (lockstep) time"
)]
struct Args {
    /// Vehicle-hours to run.
    #[arg(long, default_value_t = 8.0)]
    hours: f64,
    /// Multiply every interval but the poll's (checkpoint, estimate, reconfiguration, watch,
    /// recording) by this: a short run with `--hours 0.25 --scale 0.0625` has the day's
    /// rhythm 16 times faster.
    #[arg(long, default_value_t = 1.0)]
    scale: f64,
    /// The simulator runs no faster than this many times real time (`thruster-sim --pace`),
    /// so the operator's once-a-vehicle-second poll keeps up.
    #[arg(long, default_value_t = 20.0)]
    pace: f64,
    /// Every this many polls is a real `thrusterctl status --json` process; the others are
    /// fresh clients in this process (a new iceoryx2 node + control client + status inbox,
    /// what such a process does). 1 = every poll a process.
    #[arg(long, default_value_t = 10)]
    process_every: u64,
    /// At most this many poll processes at once (more are done in process and counted so).
    #[arg(long, default_value_t = 2)]
    max_inflight: usize,
    /// Threads doing the in-process polls.
    #[arg(long, default_value_t = 2)]
    poll_threads: usize,
    /// Vehicle file name under config/vehicles (without .toml); needs a thruster named
    /// `--thruster`.
    #[arg(long, default_value = "amour5")]
    vehicle: String,
    /// Thruster the reconfigurations rotate (+-45 degrees about x, alternating).
    #[arg(long, default_value = "T")]
    thruster: String,
    /// Sensor noise preset of the simulator.
    #[arg(long, default_value = "realistic")]
    noise: String,
    /// Seed of the simulator's noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// IMU rate, Hz.
    #[arg(long, default_value_t = 200.0)]
    rate: f64,
    /// Recorder rotation size, MiB (`thrusterctl record --max-mb`).
    #[arg(long, default_value_t = 4.0)]
    record_max_mb: f64,
    /// RSS may grow this much after the first checkpoint, KiB ...
    #[arg(long, default_value_t = 2048)]
    rss_abs_kib: u64,
    /// ... or this share of it, whichever is larger.
    #[arg(long, default_value_t = 0.10)]
    rss_rel: f64,
    /// Open descriptors at the end (no client left) may exceed the start's by this many.
    #[arg(long, default_value_t = 8)]
    fd_slack: u64,
    /// Write summary.json, table.md and the processes' logs here.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Run nothing: judge the rows of an earlier run's summary.json with the current rules
    /// and the limits given here, print the verdict (exit status as a run's).
    #[arg(long, value_name = "SUMMARY_JSON")]
    rejudge: Option<PathBuf>,
}

fn main() -> ExitCode {
    let args = Args::parse();
    match run(&args) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("season: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// Copies the binaries to `dir` and makes [`bin`] use them: other builds in the shared target
/// folder must not swap them during a run of an hour.
fn pin_binaries(dir: &Path) -> Result<()> {
    if std::env::var_os(BIN_DIR_ENV).is_some() {
        return Ok(());
    }
    std::fs::create_dir_all(dir)?;
    for name in ["thrusterd", "thrusterctl", "thruster-sim"] {
        std::fs::copy(bin(name), dir.join(name))
            .with_context(|| format!("copying {}", bin(name).display()))?;
    }
    // Single-threaded here: nothing else reads the environment yet.
    std::env::set_var(BIN_DIR_ENV, dir);
    Ok(())
}

/// Counters for the report that the loop keeps.
#[derive(Default)]
struct Tally {
    polls_process: u64,
    polls_inproc: u64,
    polls_failed: u64,
    watches_started: u64,
    estimates: u64,
    estimates_refused: u64,
    recordings: u64,
    recorded_files: u64,
    recorded_bytes: u64,
    watch_failures: Vec<String>,
    recorder_failures: Vec<String>,
    poll_errors: Vec<String>,
    /// Wall time spent in in-process polls.
    inproc_wall: Duration,
    /// In-process polls: from the due vehicle time to the vehicle time of the status that
    /// answered (the served poll, not only its dispatch).
    served_lag: Lag,
}

fn limits(args: &Args) -> Limits {
    Limits {
        rss_abs_kib: args.rss_abs_kib,
        rss_rel: args.rss_rel,
        fd_slack: args.fd_slack,
        ..Limits::default()
    }
}

fn rejudge(path: &Path, limits: &Limits) -> Result<ExitCode> {
    let summary: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?,
    )?;
    let rows: Vec<Row> = serde_json::from_value(summary["rows"].clone()).context("rows")?;
    println!("{HEADER}");
    for r in &rows {
        println!("{}", row_text(r));
    }
    let findings = verdict(&rows, limits);
    if findings.is_empty() {
        println!("verdict of the rows: PASS");
        Ok(ExitCode::SUCCESS)
    } else {
        println!("verdict of the rows: FAIL");
        for f in &findings {
            println!("  - {}: {}", f.what, f.detail);
        }
        Ok(ExitCode::FAILURE)
    }
}

fn run(args: &Args) -> Result<ExitCode> {
    if let Some(path) = &args.rejudge {
        return rejudge(path, &limits(args));
    }
    let plan = Plan::pool_day(args.hours).scaled(args.scale);
    plan.validate().map_err(anyhow::Error::msg)?;
    anyhow::ensure!(
        args.process_every >= 1,
        "--process-every must be at least 1"
    );
    let stop = Shutdown::on_signals().context("installing the signal handler")?;
    let mut world = World::new("season");
    pin_binaries(&world.path("bin"))?;
    for name in ["thrusterd", "thrusterctl", "thruster-sim"] {
        println!("using {}", bin(name).display());
    }
    let ns = world.namespace();
    let ipc = world.ipc().clone();
    let period_ns = (1e9 / args.rate).round() as u64;
    let scenario = world.path("season.toml");
    std::fs::write(&scenario, scenario_toml(&plan, &args.thruster, 45.0))?;
    let recordings = world.path("rec");
    std::fs::create_dir_all(&recordings)?;

    let mut daemon = world.daemon(&["--thrusters", "5", "--lockstep"]);
    let pace = args.pace.to_string();
    let rate = args.rate.to_string();
    let seed = args.seed.to_string();
    let mut sim = world.sim(
        &args.vehicle,
        &[
            "--lockstep",
            "--pace",
            &pace,
            "--rate",
            &rate,
            "--noise",
            &args.noise,
            "--seed",
            &seed,
            "--scenario",
            scenario.to_str().context("temp path not UTF-8")?,
        ],
    );
    // The soak's own subscribers live from the start row to the end row, so they are part of
    // both baselines alike.
    let status_in: Inbox<StatusMsg> = Inbox::create(world.node(), world.ipc())?;
    let driver_in: Inbox<DriverStatusMsg> =
        Inbox::create_with_buffer(world.node(), world.ipc(), 1)?;
    let mut status: Option<StatusMsg> = None;
    let mut driver: Option<DriverStatusMsg> = None;
    let refresh =
        |status: &mut Option<StatusMsg>, driver: &mut Option<DriverStatusMsg>| -> Result<()> {
            while let Some(s) = status_in.recv()? {
                *status = Some(s);
            }
            while let Some(d) = driver_in.recv()? {
                *driver = Some(d);
            }
            Ok(())
        };

    // Up: the daemon counts samples and the simulator reports.
    let up_by = Instant::now() + Duration::from_secs(60);
    while status.as_ref().is_none_or(|s| s.samples == 0) || driver.is_none() {
        if Instant::now() > up_by || stop.requested() || !daemon.is_running() || !sim.is_running() {
            bail!(
                "the daemon never saw a sample\n--- daemon\n{}\n--- sim\n{}",
                daemon.log_text(),
                sim.log_text()
            );
        }
        std::thread::sleep(Duration::from_millis(10));
        refresh(&mut status, &mut driver)?;
    }
    println!(
        "season: {:.2} vehicle-h of {} in lockstep (pace <= {}x), {} Hz, noise {} seed {}; every {} vehicle s a poll (every {}th a process), an estimate every {} s, a reconfiguration every {} s, a watch every {} s living {} s, a {} s recording {} s into each {} s checkpoint interval; namespace {}; {} cores, load1 {:.2}",
        args.hours, args.vehicle, args.pace, args.rate, args.noise, args.seed, plan.poll_s,
        args.process_every, plan.estimate_s, plan.reconfig_s, plan.watch_every_s,
        plan.watch_life_s, plan.record_for_s, plan.record_at_s, plan.checkpoint_s, ns,
        std::thread::available_parallelism().map_or(0, |n| n.get()),
        load1()
    );
    println!("{HEADER}");
    println!("|{}", "---|".repeat(HEADER.matches('|').count() - 1));

    let wall0 = Instant::now();
    let mut tally = Tally::default();
    let mut rows: Vec<Row> = Vec::new();
    let take_row = |label: &str,
                    status: &StatusMsg,
                    driver: &DriverStatusMsg,
                    tally: &Tally,
                    watches_alive: u64,
                    reconfigs: u64,
                    daemon_pid: u32,
                    sim_pid: u32|
     -> Result<Row> {
        let d = DaemonCounts::of(status, period_ns);
        Ok(Row {
            label: label.into(),
            vehicle_s: status.vehicle_time_ns as f64 / NS_PER_S as f64,
            wall_s: wall0.elapsed().as_secs_f64(),
            state: state(status).name().to_string(),
            model_version: status.model_version,
            link: Link {
                published: d.last_seq,
                accepted: d.accepted,
                missed: status.samples_missed,
                rejected: d.rejected,
                uncounted: d.uncounted(),
                commands_applied: driver.commands_accepted,
                commands_rejected: driver.commands_rejected,
                unanswered: driver.watchdog_expiries,
            },
            daemon: proc_figures(daemon_pid),
            sim: proc_figures(sim_pid),
            files: census(&ipc)?,
            polls_process: tally.polls_process,
            polls_inproc: tally.polls_inproc,
            polls_failed: tally.polls_failed,
            watches_started: tally.watches_started,
            watches_alive,
            estimates: tally.estimates,
            estimates_refused: tally.estimates_refused,
            reconfigs,
            recordings: tally.recordings,
            recorded_files: tally.recorded_files,
        })
    };
    let start = take_row(
        "start",
        status.as_ref().unwrap(),
        driver.as_ref().unwrap(),
        &tally,
        0,
        0,
        daemon.pid(),
        sim.pid(),
    )?;
    println!("{}", row_text(&start));
    rows.push(start);
    let files_at_start = file_names(&ipc);

    let end_ns = plan.end_ns();
    let mut polls = Ticker::new(plan.poll_s, plan.poll_s, plan.duration_s);
    // The first estimate at once (the daemon starts idle), then every interval at half an
    // interval's offset: 10, 30, 50 min of every hour, never on a reconfiguration.
    let mut estimates_offset = Ticker::new(plan.estimate_s / 2.0, plan.estimate_s, plan.duration_s);
    let mut reconfigs = Ticker::new(plan.reconfig_s, plan.reconfig_s, plan.duration_s);
    let mut watch_starts = Ticker::new(
        plan.watch_every_s / 2.0,
        plan.watch_every_s,
        plan.duration_s,
    );
    let mut record_starts = Ticker::new(plan.record_at_s, plan.checkpoint_s, plan.duration_s);
    let mut checkpoints = Ticker::new(plan.checkpoint_s, plan.checkpoint_s, plan.duration_s);
    let mut poll_lag = Lag::default();
    let mut action_lag = Lag::default();
    let mut inflight = Inflight::default();
    let mut pollers = Pollers::new(&ipc, args.poll_threads);
    let mut watches: Vec<Watch> = Vec::new();
    let mut recording: Option<Recording> = None;
    let mut swaps = 0u64;
    let mut last_model = status.as_ref().map_or(0, |s| s.model_version);
    let mut died = None;
    let mut interrupted = false;
    let mut stall_watch = StallWatch::new(status.as_ref().map_or(0, |s| s.vehicle_time_ns));
    let mut stalled = None;
    tally.estimates += 1;
    if !estimate(&ns)? {
        tally.estimates_refused += 1;
    }

    loop {
        if stop.requested() {
            interrupted = true;
            break;
        }
        died = system_tests::first_exited(&mut [
            ("thrusterd", &mut daemon),
            ("thruster-sim", &mut sim),
        ]);
        if died.is_some() {
            break;
        }
        std::thread::sleep(Duration::from_millis(2));
        refresh(&mut status, &mut driver)?;
        let s = status.unwrap();
        let now = s.vehicle_time_ns;
        if let Some(why) = stall_watch.check(now) {
            let held = stall::describe(&[("thrusterd", daemon.pid()), ("thruster-sim", sim.pid())]);
            eprintln!("{why}\n{held}");
            if let Some(dir) = &args.out {
                let _ = std::fs::write(dir.join("stall.txt"), format!("{why}\n{held}"));
            }
            stalled = Some(why);
            break;
        }
        if s.model_version != last_model {
            last_model = s.model_version;
            swaps += 1;
        }

        // Poll processes that finished.
        inflight
            .0
            .retain_mut(|(child, since)| match child.try_wait() {
                Ok(Some(st)) => {
                    if !st.success() {
                        tally.polls_failed += 1;
                        tally.poll_errors.push(format!("thrusterctl status: {st}"));
                    }
                    false
                }
                Ok(None) if since.elapsed() > Duration::from_secs(30) => {
                    let _ = child.kill();
                    let _ = child.wait();
                    tally.polls_failed += 1;
                    tally
                        .poll_errors
                        .push("thrusterctl status hung 30 s".into());
                    false
                }
                Ok(None) => true,
                Err(_) => false,
            });

        while let Some((k, due)) = polls.due(now) {
            poll_lag.record(due, now);
            if k % args.process_every == 0 && inflight.0.len() < args.max_inflight {
                inflight
                    .0
                    .push((ctl_quiet(&ns, &["status", "--json"])?, Instant::now()));
                tally.polls_process += 1;
            } else {
                tally.polls_inproc += 1;
                pollers.submit(due);
            }
        }
        pollers.collect(&mut tally, false);
        while let Some((_, due)) = estimates_offset.due(now) {
            action_lag.record(due, now);
            tally.estimates += 1;
            if !estimate(&ns)? {
                tally.estimates_refused += 1;
            }
        }
        // The simulator applies the reconfigurations itself (its scenario): counted here.
        while reconfigs.due(now).is_some() {}
        while let Some((k, due)) = watch_starts.due(now) {
            action_lag.record(due, now);
            tally.watches_started += 1;
            watches.push(Watch {
                proc: Proc::spawn(
                    "thrusterctl",
                    &["--namespace", &ns, "watch", "--json"],
                    world.dir.path(),
                ),
                stop_ns: due + system_tests::season::secs_ns(plan.watch_life_s),
                ending: Ending::of_watch(k),
                started: Instant::now(),
            });
        }
        let mut i = 0;
        while i < watches.len() {
            if watches[i].stop_ns <= now && watches[i].started.elapsed() >= MIN_LIFE {
                let w = watches.swap_remove(i);
                end_watch(w, &mut tally);
            } else {
                i += 1;
            }
        }
        while let Some((k, due)) = record_starts.due(now) {
            action_lag.record(due, now);
            let stem = recordings.join(format!("rec{k}"));
            let out = stem.with_extension("mcap");
            let mb = args.record_max_mb.to_string();
            recording = Some(Recording {
                proc: Proc::spawn(
                    "thrusterctl",
                    &[
                        "--namespace",
                        &ns,
                        "record",
                        "--out",
                        out.to_str().unwrap(),
                        "--max-mb",
                        &mb,
                    ],
                    world.dir.path(),
                ),
                stop_ns: due + system_tests::season::secs_ns(plan.record_for_s),
                stem,
                started: Instant::now(),
            });
            tally.recordings += 1;
        }
        if recording
            .as_ref()
            .is_some_and(|r| r.stop_ns <= now && r.started.elapsed() >= MIN_LIFE)
        {
            end_recording(recording.take().unwrap(), &recordings, &mut tally);
        }
        while let Some((k, _)) = checkpoints.due(now) {
            let row = take_row(
                &format!("h{}", k + 1),
                &s,
                driver.as_ref().unwrap(),
                &tally,
                watches.len() as u64,
                reconfigs.count(),
                daemon.pid(),
                sim.pid(),
            )?;
            println!("{}", row_text(&row));
            rows.push(row);
        }
        if now >= end_ns {
            break;
        }
    }
    if stop.requested() {
        interrupted = true;
        died = None;
    }

    // The last clients leave: watches as planned, the recorder, the poll processes.
    for w in watches.drain(..) {
        end_watch(w, &mut tally);
    }
    if let Some(r) = recording.take() {
        end_recording(r, &recordings, &mut tally);
    }
    pollers.collect(&mut tally, true);
    let max_queued = pollers.max_pending;
    pollers.join();
    for (mut child, _) in inflight.0.drain(..) {
        match child.wait() {
            Ok(st) if st.success() => {}
            other => {
                tally.polls_failed += 1;
                tally
                    .poll_errors
                    .push(format!("thrusterctl status: {other:?}"));
            }
        }
    }
    // A killed watch's node stays until someone cleans dead nodes (any thrusterctl call does
    // on joining): do what the next operator call would, then count.
    let before_cleanup = census(&ipc)?;
    let cleaned = cleanup_dead_nodes(&ipc)?;
    std::thread::sleep(Duration::from_millis(200));
    refresh(&mut status, &mut driver)?;
    let end = take_row(
        "end",
        status.as_ref().unwrap(),
        driver.as_ref().unwrap(),
        &tally,
        0,
        reconfigs.count(),
        daemon.pid(),
        sim.pid(),
    )?;
    println!("{}", row_text(&end));
    rows.push(end);
    let files_at_end = file_names(&ipc);
    let appeared: Vec<&String> = files_at_end.difference(&files_at_start).collect();
    let vanished: Vec<&String> = files_at_start.difference(&files_at_end).collect();
    let wall_s = wall0.elapsed().as_secs_f64();

    // Stop: the simulator first (its summary line names stale answers), then the daemon.
    let sim_exit = sim.stop();
    std::thread::sleep(Duration::from_millis(300));
    refresh(&mut status, &mut driver)?;
    let final_counts = DaemonCounts::of(status.as_ref().unwrap(), period_ns);
    let mut failures_extra: Vec<String> = Vec::new();
    let daemon_exit = daemon.stop();
    let sim_summary = sim
        .log_text()
        .lines()
        .rev()
        .find(|l| l.contains("thruster-sim stopped"))
        .map(str::to_string)
        .unwrap_or_default();
    let sim_samples = system_tests::season::field_u64(&sim_summary, "samples");
    let sim_stale = system_tests::season::field_u64(&sim_summary, "stale");
    // In lockstep the daemon publishes status with the samples, every 100 ms of vehicle time
    // (`runtime.status_period_ms`), and not while the simulator is silent: its last status
    // may be up to one period behind the simulator's last sample. The counters are checked at
    // that status (exact there), and it must be that recent.
    let uncounted_total = sim_samples.map(|_| final_counts.uncounted());
    let status_every = 100_000_000u64.div_ceil(period_ns.max(1));
    if let Some(behind) = sim_samples
        .map(|n| n.saturating_sub(final_counts.last_seq))
        .filter(|b| *b > status_every + 1)
    {
        failures_extra.push(format!(
            "the daemon's last status is {behind} samples behind the simulator's last (at most \
             {status_every} expected)"
        ));
    }
    drop(status_in);
    drop(driver_in);
    // What is left once every process has gone (the soak's own node too): nothing, if each
    // left cleanly (each removes the namespace's residue as the last one out).
    drop(world.node.take());
    let _ = tidy_residue(&ipc);
    let left_raw = namespace_files(&ipc)?.len();
    // Dead nodes (a client that died, e.g. SIGKILLed) are removed by the next node of the
    // namespace: what is left after that is what nobody would ever remove.
    let dead = cleanup_dead_nodes(&ipc)?;
    let _ = tidy_residue(&ipc);
    let left: Vec<PathBuf> = namespace_files(&ipc)?;

    let limits = limits(args);
    let findings = verdict(&rows, &limits);
    let mut failures: Vec<String> = findings
        .iter()
        .map(|f| format!("{}: {}", f.what, f.detail))
        .collect();
    failures.append(&mut failures_extra);
    if let Some(who) = died {
        failures.push(format!("{who} died during the run"));
    }
    failures.extend(stalled);
    if uncounted_total.is_some_and(|n| n > 0) {
        failures.push(format!(
            "{} IMU samples published but neither accepted nor rejected by the daemon",
            uncounted_total.unwrap()
        ));
    }
    if sim_stale.is_some_and(|n| n > 0) {
        failures.push(format!("{} late (stale) answers", sim_stale.unwrap()));
    }
    failures.extend(tally.watch_failures.iter().cloned());
    failures.extend(tally.recorder_failures.iter().cloned());
    if !sim_exit.success() || !daemon_exit.success() {
        failures.push(format!(
            "unclean exit: thruster-sim {sim_exit}, thrusterd {daemon_exit}"
        ));
    }
    if !left.is_empty() {
        failures.push(format!(
            "{} files left after every process exited: {:?}",
            left.len(),
            left.iter().take(5).collect::<Vec<_>>()
        ));
    }

    println!();
    println!(
        "wall {:.1} s for {:.1} vehicle s ({:.1}x); model swaps seen {swaps} (v{}), estimates {} ({} refused), reconfigurations {}",
        wall_s,
        rows.last().map_or(0.0, |r| r.vehicle_s),
        rows.last().map_or(0.0, |r| r.vehicle_s) / wall_s.max(1e-9),
        last_model,
        tally.estimates,
        tally.estimates_refused,
        reconfigs.count()
    );
    println!(
        "polls: {} processes + {} in process, {} failed; lag behind schedule mean {:.3} s, max {:.3} s (vehicle); other actions' lag max {:.3} s",
        tally.polls_process,
        tally.polls_inproc,
        tally.polls_failed,
        poll_lag.mean_s(),
        poll_lag.max_s,
        action_lag.max_s
    );
    println!(
        "in-process poll: {:.1} ms wall each (mean), at most {max_queued} queued or running; served {:.2} vehicle-s after its due second on average, at most {:.2} s",
        tally.inproc_wall.as_secs_f64() * 1e3 / tally.polls_inproc.max(1) as f64,
        tally.served_lag.mean_s(),
        tally.served_lag.max_s
    );
    for e in tally.poll_errors.iter().take(5) {
        println!("  poll error: {e}");
    }
    println!(
        "watches started {}; recordings {} ({} files, {:.1} MiB, deleted after counting)",
        tally.watches_started,
        tally.recordings,
        tally.recorded_files,
        tally.recorded_bytes as f64 / 1048576.0
    );
    println!(
        "before the end row's dead-node cleanup: {} /dev/shm files, {} root files ({:?})",
        before_cleanup.shm_files, before_cleanup.root_files, cleaned
    );
    println!(
        "files at the end not there at the start ({}): {:?}; gone since the start ({}): {:?}",
        appeared.len(),
        appeared.iter().take(10).collect::<Vec<_>>(),
        vanished.len(),
        vanished.iter().take(10).collect::<Vec<_>>()
    );
    println!("simulator: {sim_summary}");
    println!(
        "after every process exited: {left_raw} namespace files; after removing dead nodes ({dead:?}): {} left",
        left.len()
    );

    if let Some(dir) = &args.out {
        std::fs::create_dir_all(dir)?;
        let mut table = format!(
            "{HEADER}\n|{}\n",
            "---|".repeat(HEADER.matches('|').count() - 1)
        );
        for r in &rows {
            table += &row_text(r);
            table.push('\n');
        }
        std::fs::write(dir.join("table.md"), table)?;
        std::fs::write(
            dir.join("summary.json"),
            serde_json::to_string_pretty(&serde_json::json!({
                "args": {
                    "hours": args.hours, "scale": args.scale, "pace": args.pace,
                    "process_every": args.process_every, "vehicle": args.vehicle,
                    "noise": args.noise, "seed": args.seed, "rate": args.rate,
                },
                "plan": plan,
                "limits": limits,
                "rows": rows,
                "wall_s": wall_s,
                "swaps": swaps,
                "poll_lag": poll_lag,
                "action_lag": action_lag,
                "poll_served_lag": tally.served_lag,
                "recorded_bytes": tally.recorded_bytes,
                "poll_errors": tally.poll_errors,
                "sim_summary": sim_summary,
                "left_after_exit": left,
                "files_appeared": appeared,
                "files_vanished": vanished,
                "interrupted": interrupted,
                "failures": failures,
            }))?,
        )?;
        let _ = std::fs::copy(&daemon.log, dir.join("thrusterd.log"));
        let _ = std::fs::copy(&sim.log, dir.join("thruster-sim.log"));
        println!("written to {}", dir.display());
    }

    if failures.is_empty() {
        println!(
            "verdict: PASS{}",
            if interrupted {
                " (interrupted early)"
            } else {
                ""
            }
        );
    } else {
        println!("verdict: FAIL");
        for f in &failures {
            println!("  - {f}");
        }
    }
    Ok(if !failures.is_empty() {
        ExitCode::FAILURE
    } else if interrupted {
        ExitCode::from(130)
    } else {
        ExitCode::SUCCESS
    })
}
