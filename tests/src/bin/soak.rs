//! Endurance (soak) run: thrusterd and thruster-sim as real processes, the simulator in real
//! time at 1 kHz, for many minutes of wall time; the daemon estimates, then holds attitude
//! through periodic setpoint changes and re-estimates (each one a model hot swap).
//!
//! Per minute it reports samples published / answered / unanswered (simulator side), accepted /
//! rejected (the daemon's status counters) and the samples lost without being counted, the
//! sample -> thrust latency seen by the simulator (p50 / p99 / p99.9 / max), and the RSS of
//! both processes, and over the run the simulator's pacing and the daemon's model-mismatch
//! reports. Exit status 1 when a sample was lost uncounted, memory grew beyond the limit, the
//! pacing p99 passed one period, the daemon reported a model mismatch (the vehicle never
//! changes) or a process died; 130 when interrupted (the table so far is still printed).
//!
//! Run (see docs/reliability.md):
//!   cargo build --release -p thrusterd -p thruster-sim --bins
//!   cargo run --release -p system-tests --bin soak -- --minutes 10 --out out/soak

use std::fs::File;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::Parser;
use system_tests::soak::{
    baseline_index, memory_growth, parse_proc_stat_cpu_ticks, parse_proc_status, spread,
    DaemonCounts, Growth, GrowthLimit, Memory, MinuteRow, Snapshot,
};
use system_tests::{state, Operator, Proc, World};
use thruster_driver_kit::Shutdown;
use thruster_protocol::services::Port;
use thruster_protocol::{DaemonState, RequestKind, Setpoint, StatusMsg};
use thruster_sim::link_stats::{LatencyHistogram, StatsLine};

#[derive(Parser)]
#[command(
    name = "soak",
    about = "Endurance run of thrusterd + thruster-sim in real time"
)]
struct Args {
    /// Wall-clock minutes to run (after the simulator is up).
    #[arg(long, default_value_t = 10)]
    minutes: u32,
    /// Vehicle file name under config/vehicles (without .toml).
    #[arg(long, default_value = "amour5")]
    vehicle: String,
    /// Sensor noise preset of the simulator.
    #[arg(long, default_value = "paper")]
    noise: String,
    /// IMU rate, Hz.
    #[arg(long, default_value_t = 1000.0)]
    rate: f64,
    /// Daemon low-latency polling, us (0 = event mode, the shipped default).
    #[arg(long, default_value_t = 0)]
    spin_us: u64,
    /// Toggle the pitch setpoint between 0 and `--pitch-deg` this often, s (0 = never).
    #[arg(long, default_value_t = 20)]
    setpoint_every_s: u64,
    /// Pitch of the alternate setpoint, degrees.
    #[arg(long, default_value_t = 10.0)]
    pitch_deg: f64,
    /// Request a re-estimate (a model hot swap) this often, minutes (0 = only the first).
    #[arg(long, default_value_t = 3)]
    reestimate_every_min: u32,
    /// Memory growth allowed after the baseline minute, KiB ...
    #[arg(long, default_value_t = 2048)]
    max_growth_kib: u64,
    /// ... or this fraction of the baseline RSS, whichever is larger.
    #[arg(long, default_value_t = 0.10)]
    max_growth_rel: f64,
    /// Write minutes.csv, summary.json, the stats lines and both logs here.
    #[arg(long)]
    out: Option<PathBuf>,
    /// A thrusterd configuration file for the daemon (e.g. `[refinement] change_test = true`).
    #[arg(long)]
    daemon_config: Option<PathBuf>,
}

fn main() -> ExitCode {
    let args = Args::parse();
    match run(&args) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("soak: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// The simulator's stats file, read incrementally (whole lines only).
struct StatsReader {
    file: Option<File>,
    path: PathBuf,
    pending: String,
    last: Option<StatsLine>,
    /// The simulator's pacing (sample published after its due instant) over the whole run.
    pacing: LatencyHistogram,
}

impl StatsReader {
    fn new(path: &Path) -> Self {
        StatsReader {
            file: None,
            path: path.to_path_buf(),
            pending: String::new(),
            last: None,
            pacing: LatencyHistogram::default(),
        }
    }

    /// New complete lines since the last call; their latency merged into `into`.
    fn poll(&mut self, into: &mut LatencyHistogram) -> Result<()> {
        if self.file.is_none() {
            match File::open(&self.path) {
                Ok(f) => self.file = Some(f),
                Err(_) => return Ok(()),
            }
        }
        let f = self.file.as_mut().unwrap();
        let mut chunk = String::new();
        f.read_to_string(&mut chunk)?;
        self.pending.push_str(&chunk);
        while let Some(end) = self.pending.find('\n') {
            let line: String = self.pending.drain(..=end).collect();
            let parsed: StatsLine = serde_json::from_str(line.trim())
                .with_context(|| format!("bad stats line: {line}"))?;
            into.merge(&parsed.latency);
            self.pacing.merge(&parsed.pacing);
            self.last = Some(parsed);
        }
        // The next call reads on from here: read_to_string leaves the cursor at the end.
        Ok(())
    }
}

/// Memory and CPU ticks of a process now.
fn proc_figures(pid: u32) -> (Memory, u64) {
    let mem = std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|t| parse_proc_status(&t))
        .unwrap_or_default();
    let cpu = std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .ok()
        .and_then(|t| parse_proc_stat_cpu_ticks(&t))
        .unwrap_or(0);
    (mem, cpu)
}

fn clock_ticks_per_s() -> f64 {
    std::process::Command::new("getconf")
        .arg("CLK_TCK")
        .output()
        .ok()
        .and_then(|o| String::from_utf8(o.stdout).ok())
        .and_then(|s| s.trim().parse().ok())
        .unwrap_or(100.0)
}

fn load1() -> f64 {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|s| s.split_whitespace().next().and_then(|v| v.parse().ok()))
        .unwrap_or(f64::NAN)
}

fn setpoint(seq: u64, pitch_deg: f64) -> Setpoint {
    let half = pitch_deg.to_radians() / 2.0;
    Setpoint {
        seq,
        attitude: [half.cos(), 0.0, half.sin(), 0.0],
        ..Setpoint::default()
    }
}

/// "p50 .. us, p99 .. us, p99.9 .. us, max .. us (N `what`)" of a histogram.
fn quantiles_text(h: &LatencyHistogram, what: &str) -> String {
    format!(
        "p50 {} us, p99 {} us, p99.9 {} us, max {} us ({} {what})",
        fmt_us(h.quantile_us(0.5)),
        fmt_us(h.quantile_us(0.99)),
        fmt_us(h.quantile_us(0.999)),
        fmt_us(h.max_us()),
        h.count()
    )
}

/// The same figures for summary.json.
fn quantiles_json(h: &LatencyHistogram) -> serde_json::Value {
    serde_json::json!({
        "p50": h.quantile_us(0.5),
        "p99": h.quantile_us(0.99),
        "p999": h.quantile_us(0.999),
        "max": h.max_us(),
        "count": h.count(),
    })
}

fn fmt_us(v: Option<f64>) -> String {
    v.map_or("-".into(), |v| format!("{v:.0}"))
}

const HEADER: &str = "| min | state | model | published | answered | unanswered | daemon accepted | daemon rejected | uncounted | p50 us | p99 us | p99.9 us | max us | daemon RSS / HWM MiB | sim RSS MiB | daemon CPU % | sim CPU % | load1 |";

fn row_text(r: &MinuteRow) -> String {
    let mib = |k: u64| k as f64 / 1024.0;
    format!(
        "| {} | {} | v{} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {:.2} / {:.2} | {:.2} | {:.1} | {:.1} | {:.2} |",
        r.minute,
        r.state,
        r.model_version,
        r.published,
        r.answered,
        r.unanswered,
        r.daemon_accepted,
        r.daemon_rejected,
        r.uncounted,
        fmt_us(r.p50_us),
        fmt_us(r.p99_us),
        fmt_us(r.p999_us),
        fmt_us(r.max_us),
        mib(r.daemon_mem.rss_kib),
        mib(r.daemon_mem.hwm_kib),
        mib(r.sim_mem.rss_kib),
        r.daemon_cpu_pct,
        r.sim_cpu_pct,
        r.load1
    )
}

fn latest_status(op: &Operator, latest: &mut Option<StatusMsg>) -> Result<()> {
    while let Some(s) = op.status.recv()? {
        *latest = Some(s);
    }
    Ok(())
}

fn run(args: &Args) -> Result<ExitCode> {
    anyhow::ensure!(args.minutes >= 1, "--minutes must be at least 1");
    let stop = Shutdown::on_signals().context("installing the signal handler")?;
    // The binaries are used as built (see the module docs: build them first). Not rebuilt
    // here: on a shared tree a rebuild can fail on others' half-done work, and the run should
    // measure exactly what was built for it.
    for name in ["thrusterd", "thruster-sim"] {
        println!("using {}", system_tests::bin(name).display());
    }
    let period_ns = (1e9 / args.rate).round() as u64;
    let ticks = clock_ticks_per_s();

    // Everything below lives in `world` (namespace purged and temp dir removed on drop) and
    // the two `Proc`s (killed and reaped on drop), however this function returns.
    let world = World::new("soak");
    let stats_path = world.path("sim-stats.jsonl");
    let rate = args.rate.to_string();
    let spin = args.spin_us.to_string();
    let mut daemon_args = vec!["--thrusters", "5", "--spin-us", &spin];
    if let Some(c) = &args.daemon_config {
        daemon_args.extend([
            "--config",
            c.to_str().context("--daemon-config: not UTF-8")?,
        ]);
    }
    let mut daemon = world.daemon(&daemon_args);
    let op = Operator::new(&world);
    let setpoints: Port<Setpoint> = Port::create(world.node(), world.ipc())?;
    let mut sim = world.sim(
        &args.vehicle,
        &[
            "--realtime",
            "--rate",
            &rate,
            "--noise",
            &args.noise,
            "--stats-file",
            stats_path.to_str().unwrap(),
        ],
    );

    // Up: the daemon has counted samples.
    let mut status = None;
    let up_by = Instant::now() + Duration::from_secs(30);
    while status.as_ref().is_none_or(|s: &StatusMsg| s.samples == 0) {
        if Instant::now() > up_by || stop.requested() {
            bail!(
                "the daemon never saw a sample\n--- daemon\n{}\n--- sim\n{}",
                daemon.log_text(),
                sim.log_text()
            );
        }
        std::thread::sleep(Duration::from_millis(20));
        latest_status(&op, &mut status)?;
    }
    let machine = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|t| {
            t.lines()
                .find(|l| l.starts_with("model name"))
                .map(|l| l.split(':').nth(1).unwrap_or("").trim().to_string())
        })
        .unwrap_or_default();
    println!(
        "soak: {} min, {} at {} Hz real time, noise {}, daemon spin {} us; machine: {} x {} (load1 at start {:.2})",
        args.minutes,
        args.vehicle,
        args.rate,
        args.noise,
        args.spin_us,
        std::thread::available_parallelism().map_or(0, |n| n.get()),
        machine,
        load1()
    );
    let r = op.request(RequestKind::Estimate);
    anyhow::ensure!(r.is_ok(), "estimate refused: {}", r.text());
    println!("estimate requested; then hold, pitch setpoint toggled every {} s, re-estimate every {} min", args.setpoint_every_s, args.reestimate_every_min);
    println!("{HEADER}");
    println!("|{}", "---|".repeat(HEADER.matches('|').count() - 1));

    let start = Instant::now();
    let mut stats = StatsReader::new(&stats_path);
    let mut window = LatencyHistogram::default();
    let mut total_latency = LatencyHistogram::default();
    stats.poll(&mut window)?;
    window = LatencyHistogram::default();
    let mut prev = Snapshot::new(
        stats.last.as_ref(),
        DaemonCounts::of(status.as_ref().unwrap(), period_ns),
    );
    let (mut prev_dcpu, mut prev_scpu) = (proc_figures(daemon.pid()).1, proc_figures(sim.pid()).1);
    let mut rows: Vec<MinuteRow> = Vec::new();
    let mut next_setpoint = Duration::from_secs(args.setpoint_every_s.max(1));
    let mut setpoint_seq = 0u64;
    let mut pitched = false;
    let mut estimates = 1u32;
    let mut swaps = 0u32;
    let mut last_model = status.as_ref().map_or(0, |s| s.model_version);
    let mut died = None;
    let mut interrupted = false;

    for minute in 1..=args.minutes {
        let end = start + Duration::from_secs(60 * u64::from(minute));
        while Instant::now() < end {
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
            std::thread::sleep(Duration::from_millis(100));
            latest_status(&op, &mut status)?;
            stats.poll(&mut window)?;
            let s = status.as_ref().unwrap();
            if s.model_version != last_model {
                last_model = s.model_version;
                swaps += 1;
            }
            let elapsed = start.elapsed();
            if args.setpoint_every_s > 0 && elapsed >= next_setpoint {
                next_setpoint += Duration::from_secs(args.setpoint_every_s);
                pitched = !pitched;
                setpoint_seq += 1;
                setpoints.send(&setpoint(
                    setpoint_seq,
                    if pitched { args.pitch_deg } else { 0.0 },
                ))?;
            }
            // Re-estimate on the schedule, only from Active (never on top of a running one).
            let due_estimates = if args.reestimate_every_min == 0 {
                1
            } else {
                1 + elapsed.as_secs() / (60 * u64::from(args.reestimate_every_min))
            };
            if u64::from(estimates) < due_estimates && state(s) == DaemonState::Active {
                let r = op.request(RequestKind::Estimate);
                if r.is_ok() {
                    estimates += 1;
                } else {
                    eprintln!("re-estimate refused: {}", r.text());
                }
            }
        }
        if interrupted || died.is_some() {
            break;
        }
        let s = status.as_ref().unwrap();
        let snap = Snapshot::new(stats.last.as_ref(), DaemonCounts::of(s, period_ns));
        let (dmem, dcpu) = proc_figures(daemon.pid());
        let (smem, scpu) = proc_figures(sim.pid());
        let mut row = MinuteRow {
            minute,
            state: state(s).name().to_string(),
            model_version: s.model_version,
            daemon_mem: dmem,
            sim_mem: smem,
            daemon_cpu_pct: (dcpu - prev_dcpu) as f64 / ticks / 60.0 * 100.0,
            sim_cpu_pct: (scpu - prev_scpu) as f64 / ticks / 60.0 * 100.0,
            load1: load1(),
            ..MinuteRow::default()
        };
        snap.fill(&prev, &window, &mut row);
        println!("{}", row_text(&row));
        std::io::stdout().flush()?;
        total_latency.merge(&window);
        window = LatencyHistogram::default();
        prev = snap;
        (prev_dcpu, prev_scpu) = (dcpu, scpu);
        rows.push(row);
    }

    // A Ctrl-C at a terminal reaches the children too (same process group): they may exit
    // before this loop saw the flag, which is not a death.
    if stop.requested() {
        interrupted = true;
        died = None;
    }
    // The answers of a partial last minute still count in the run's percentiles.
    total_latency.merge(&window);

    // Orderly end: the simulator first (it writes its final stats line), then let the daemon
    // drain and publish its counters once more, then the daemon.
    let sim_exit = sim.stop();
    std::thread::sleep(Duration::from_millis(500));
    latest_status(&op, &mut status)?;
    stats.poll(&mut total_latency)?;
    let final_daemon = DaemonCounts::of(status.as_ref().unwrap(), period_ns);
    let daemon_exit = daemon.stop();
    // The vehicle never changes in a soak: every mismatch verdict (a re-estimation the
    // operator did not ask for) is a false alarm.
    let false_alarms = daemon
        .log_text()
        .lines()
        .filter(|l| l.contains("WARN") && l.contains("model mismatch on thruster"))
        .count();
    let published = stats.last.as_ref().map_or(0, |l| l.published);
    let last = stats.last.clone();
    let uncounted_total = published.saturating_sub(final_daemon.accepted + final_daemon.rejected);

    // Memory verdicts.
    let limit = GrowthLimit {
        abs_kib: args.max_growth_kib,
        rel: args.max_growth_rel,
    };
    let base = baseline_index(rows.len());
    let growth = |f: fn(&MinuteRow) -> u64| -> Option<Growth> {
        memory_growth(&rows.iter().map(f).collect::<Vec<_>>(), base, limit)
    };
    let daemon_growth = growth(|r| r.daemon_mem.rss_kib);
    let sim_growth = growth(|r| r.sim_mem.rss_kib);

    println!();
    if let Some(l) = &last {
        println!(
            "totals: published {} (vehicle {:.1} s in {:.1} s wall), answered {}, unanswered {}, pending at stop {}; commands applied {}, stale {}, rejected {}",
            l.published, l.vehicle_s, l.wall_s, l.answered, l.unanswered, l.pending, l.applied, l.stale, l.rejected
        );
    }
    println!(
        "daemon: accepted {}, rejected {}, uncounted {} (published - accepted - rejected after the simulator stopped)",
        final_daemon.accepted, final_daemon.rejected, uncounted_total
    );
    println!(
        "estimates requested {estimates}, model swaps seen {swaps}, setpoints sent {setpoint_seq}, false alarms (mismatch verdicts on the unchanged vehicle) {false_alarms}"
    );
    println!(
        "latency over the run: {}; per-minute p50 {}, p99 {}",
        quantiles_text(&total_latency, "answers"),
        spread(rows.iter().map(|r| r.p50_us))
            .map_or("-".into(), |(a, b)| format!("{a:.0}-{b:.0} us")),
        spread(rows.iter().map(|r| r.p99_us))
            .map_or("-".into(), |(a, b)| format!("{a:.0}-{b:.0} us")),
    );
    let pacing = &stats.pacing;
    println!(
        "simulator pacing (sample published after its due instant): {}",
        quantiles_text(pacing, "samples")
    );
    for (name, g) in [("daemon", &daemon_growth), ("sim", &sim_growth)] {
        match g {
            Some(g) => println!(
                "{name} RSS: baseline (minute {}) {} KiB, peak after {} KiB, last {} KiB, slope {:+.1} KiB/min, allowed +{} KiB: {}",
                base + 1,
                g.baseline_kib,
                g.peak_after_kib,
                g.last_kib,
                g.slope_kib_per_min,
                g.allowed_kib,
                if g.exceeded { "GREW" } else { "flat" }
            ),
            None => println!("{name} RSS: too few minutes for a verdict"),
        }
    }

    let mut failures = Vec::new();
    if let Some(who) = died {
        failures.push(format!("{who} died during the run"));
    }
    // A simulator that publishes a period late is not real time: its samples come in bursts
    // and the daemon's commands act late (7 of 8 never did, with 8 ms bursts at 1 kHz).
    let period_us = period_ns as f64 / 1e3;
    if pacing.quantile_us(0.99).is_some_and(|p| p > period_us) {
        failures.push(format!(
            "the simulator's pacing p99 is above one period ({period_us:.0} us)"
        ));
    }
    if false_alarms > 0 {
        failures.push(format!(
            "{false_alarms} model-mismatch verdicts on an unchanged vehicle"
        ));
    }
    if uncounted_total > 0 {
        failures.push(format!(
            "{uncounted_total} samples lost without being counted"
        ));
    }
    for (name, g) in [("daemon", &daemon_growth), ("sim", &sim_growth)] {
        if g.as_ref().is_some_and(|g| g.exceeded) {
            failures.push(format!("{name} memory grew beyond the limit"));
        }
    }
    if !sim_exit.success() || !daemon_exit.success() {
        failures.push(format!(
            "unclean exit: thruster-sim {sim_exit}, thrusterd {daemon_exit}"
        ));
    }

    if let Some(dir) = &args.out {
        write_out(
            dir,
            &rows,
            &stats_path,
            &daemon,
            &sim,
            &serde_json::json!({
                "minutes": args.minutes,
                "vehicle": args.vehicle,
                "rate_hz": args.rate,
                "noise": args.noise,
                "spin_us": args.spin_us,
                "machine": machine,
                "cores": std::thread::available_parallelism().map_or(0, |n| n.get()),
                "final": last,
                "daemon_final": final_daemon,
                "uncounted_total": uncounted_total,
                "estimates": estimates,
                "swaps": swaps,
                "false_alarms": false_alarms,
                "latency_total_us": quantiles_json(&total_latency),
                "pacing_us": quantiles_json(&stats.pacing),
                "growth_limit": limit,
                "daemon_growth": daemon_growth,
                "sim_growth": sim_growth,
                "interrupted": interrupted,
                "failures": failures,
            }),
        )?;
        println!("written to {}", dir.display());
    }
    // `world` purges the namespace and removes its temp folder when it drops, after `op` and
    // `setpoints` (declared later, dropped first); both processes have exited by now.

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
        println!("verdict: FAIL: {}", failures.join("; "));
    }
    Ok(if !failures.is_empty() {
        ExitCode::FAILURE
    } else if interrupted {
        ExitCode::from(130)
    } else {
        ExitCode::SUCCESS
    })
}

fn write_out(
    dir: &Path,
    rows: &[MinuteRow],
    stats: &Path,
    daemon: &Proc,
    sim: &Proc,
    summary: &serde_json::Value,
) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut csv = String::from("minute,state,model_version,published,answered,unanswered,daemon_accepted,daemon_rejected,uncounted,p50_us,p99_us,p999_us,max_us,daemon_rss_kib,daemon_hwm_kib,sim_rss_kib,sim_hwm_kib,daemon_cpu_pct,sim_cpu_pct,load1\n");
    let opt = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.1}"));
    for r in rows {
        csv += &format!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{:.1},{:.1},{:.2}\n",
            r.minute,
            r.state,
            r.model_version,
            r.published,
            r.answered,
            r.unanswered,
            r.daemon_accepted,
            r.daemon_rejected,
            r.uncounted,
            opt(r.p50_us),
            opt(r.p99_us),
            opt(r.p999_us),
            opt(r.max_us),
            r.daemon_mem.rss_kib,
            r.daemon_mem.hwm_kib,
            r.sim_mem.rss_kib,
            r.sim_mem.hwm_kib,
            r.daemon_cpu_pct,
            r.sim_cpu_pct,
            r.load1
        );
    }
    std::fs::write(dir.join("minutes.csv"), csv)?;
    std::fs::write(
        dir.join("summary.json"),
        serde_json::to_string_pretty(summary)?,
    )?;
    let _ = std::fs::copy(stats, dir.join("sim-stats.jsonl"));
    let _ = std::fs::copy(&daemon.log, dir.join("thrusterd.log"));
    let _ = std::fs::copy(&sim.log, dir.join("thruster-sim.log"));
    Ok(())
}
