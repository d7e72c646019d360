//! `thrusterctl demo`: the whole system on one machine. thrusterd and thruster-sim start as
//! separate processes on a private iceoryx2 namespace; the daemon learns the simulated
//! vehicle's thrusters, then holds attitude through a pitch step; the demo prints the learned
//! model beside the simulator's truth, the time it took and the attitude error, and leaves no
//! process or shared-memory file behind.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use nalgebra::{Quaternion, UnitQuaternion};
use thruster_protocol::services::{
    namespace_files, purge_namespace, ControlClient, Inbox, IpcConfig, Port,
};
use thruster_protocol::{
    ControlRequest, DaemonState, ModelMsg, RequestKind, Setpoint, StatusMsg, TruthMsg,
    VehicleStateMsg,
};

const DOFS: [&str; 6] = ["roll", "pitch", "yaw", "surge", "sway", "heave"];

#[derive(Args, Debug)]
pub struct DemoArgs {
    /// Vehicle file for the simulator (default: config/vehicles/amour5.toml, AMOUR's
    /// 5-thruster default).
    #[arg(long)]
    pub vehicle: Option<PathBuf>,
    /// Run the simulator against the wall clock instead of in lockstep (as fast as possible).
    #[arg(long)]
    pub realtime: bool,
    /// Seed of the simulator's sensor noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Sensor noise preset: paper (0.25 rad/s, 0.05 g), realistic or none.
    #[arg(long, default_value = "paper")]
    pub noise: String,
    /// Vehicle seconds of attitude hold after the estimation (half level, half a 15 degree
    /// pitch step).
    #[arg(long, default_value_t = 10.0)]
    pub hold_s: f64,
    /// Print one JSON summary instead of the report.
    #[arg(long)]
    pub json: bool,
    /// thrusterd configuration file for the demo's daemon (controller gains, estimator, ...);
    /// its namespace, state directory and thruster count are the demo's own.
    #[arg(long)]
    pub daemon_config: Option<PathBuf>,
}

/// A child process killed and reaped on drop, whatever happens.
struct ChildProc {
    name: &'static str,
    child: Option<Child>,
    log: PathBuf,
}

impl ChildProc {
    fn spawn(name: &'static str, exe: &Path, args: &[&str], dir: &Path) -> Result<ChildProc> {
        let log = dir.join(format!("{name}.log"));
        let out = std::fs::File::create(&log)?;
        let child = Command::new(exe)
            .args(args)
            .stdin(Stdio::null())
            .stdout(out.try_clone()?)
            .stderr(out)
            .spawn()
            .with_context(|| format!("starting {}", exe.display()))?;
        Ok(ChildProc {
            name,
            child: Some(child),
            log,
        })
    }

    /// SIGTERM and wait (SIGKILL after 5 s); true when it exited cleanly.
    fn stop(&mut self) -> bool {
        let Some(mut child) = self.child.take() else {
            return true;
        };
        let _ = Command::new("kill")
            .args(["-TERM", &child.id().to_string()])
            .status();
        let start = Instant::now();
        while start.elapsed() < Duration::from_secs(5) {
            if let Ok(Some(status)) = child.try_wait() {
                return status.success();
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        let _ = child.kill();
        let _ = child.wait();
        false
    }

    fn alive(&mut self) -> bool {
        self.child
            .as_mut()
            .is_some_and(|c| matches!(c.try_wait(), Ok(None)))
    }

    /// The end of the process's log, for error messages.
    fn tail(&self) -> String {
        let text = std::fs::read_to_string(&self.log).unwrap_or_default();
        let lines: Vec<&str> = text.lines().collect();
        format!(
            "--- {} ({}) ---\n{}",
            self.name,
            self.log.display(),
            lines[lines.len().saturating_sub(15)..].join("\n")
        )
    }
}

impl Drop for ChildProc {
    fn drop(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// The daemon and simulator binaries next to this one; under `cargo run` they are built first
/// (cargo only builds the binary it runs).
fn sibling_binaries() -> Result<(PathBuf, PathBuf)> {
    let exe = std::env::current_exe()?;
    let dir = exe
        .parent()
        .context("thrusterctl has no folder")?
        .to_path_buf();
    if let (Ok(cargo), Ok(manifest)) = (std::env::var("CARGO"), std::env::var("CARGO_MANIFEST_DIR"))
    {
        let mut cmd = Command::new(cargo);
        cmd.args([
            "build",
            "-q",
            "-p",
            "thrusterd",
            "-p",
            "thruster-sim",
            "--bins",
        ]);
        if dir.ends_with("release") {
            cmd.arg("--release");
        }
        let status = cmd
            .current_dir(manifest)
            .status()
            .context("building thrusterd and thruster-sim")?;
        if !status.success() {
            bail!("building thrusterd and thruster-sim failed");
        }
    }
    let (d, s) = (dir.join("thrusterd"), dir.join("thruster-sim"));
    for p in [&d, &s] {
        if !p.exists() {
            bail!(
                "{} not found: build the workspace (cargo build --release)",
                p.display()
            );
        }
    }
    Ok((d, s))
}

fn default_vehicle() -> PathBuf {
    let candidates = [
        std::env::var("CARGO_MANIFEST_DIR")
            .map(|d| Path::new(&d).join("../config/vehicles/amour5.toml"))
            .ok(),
        Some(PathBuf::from("config/vehicles/amour5.toml")),
        Some(PathBuf::from("/etc/thrusterd/vehicles/amour5.toml")),
    ];
    candidates
        .into_iter()
        .flatten()
        .find(|p| p.exists())
        .unwrap_or_else(|| PathBuf::from("config/vehicles/amour5.toml"))
}

fn latest<T: thruster_protocol::services::TopicMessage>(inbox: &Inbox<T>) -> Result<Option<T>> {
    let mut last = None;
    while let Some(m) = inbox.recv()? {
        last = Some(m);
    }
    Ok(last)
}

fn quat(q: [f64; 4]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3]))
}

struct Summary {
    vehicle: String,
    vehicle_seconds: f64,
    wall_seconds: f64,
    pulses: u32,
    err_rot: f64,
    err_acc: f64,
    actuated: Vec<&'static str>,
    attitude_err_deg: Option<f64>,
    attitude_err_level_deg: Option<f64>,
    attitude_err_step_deg: Option<f64>,
    tilt_err_deg: Option<f64>,
    yaw_err_deg: Option<f64>,
    clean_exit: bool,
    leftovers: usize,
}

pub fn run(args: DemoArgs) -> Result<()> {
    let (daemon_exe, sim_exe) = sibling_binaries()?;
    let vehicle = args.vehicle.clone().unwrap_or_else(default_vehicle);
    if !vehicle.exists() {
        bail!("vehicle file {} not found", vehicle.display());
    }
    let ns = format!("demo-{}", std::process::id() % 1_000_000);
    let ipc = IpcConfig::new(&ns)?;
    let tmp = tempfile_dir()?;
    let state = tmp.join("state");
    let node = ipc.create_node("thrusterctl-demo")?;
    let status_in = Inbox::<StatusMsg>::create(&node, &ipc)?;
    let model_in = Inbox::<ModelMsg>::create(&node, &ipc)?;
    let truth_in = Inbox::<TruthMsg>::create(&node, &ipc)?;
    let vehicle_in = Inbox::<VehicleStateMsg>::create(&node, &ipc)?;
    let setpoint_out = Port::<Setpoint>::create(&node, &ipc)?;
    let client = ControlClient::create(&node, &ipc)?;

    // The daemon is told only how many thrusters there are, not where: it learns the rest.
    let count = thruster_count(&vehicle)?.to_string();
    let mut daemon_args = vec![
        "run",
        "--namespace",
        &ns,
        "--state-dir",
        state.to_str().unwrap_or("."),
        "--thrusters",
        &count,
    ];
    // In lockstep the simulator waits for every answer: the daemon's low-latency mode (poll
    // before blocking) saves a wake-up per sample.
    if !args.realtime {
        daemon_args.extend(["--spin-us", "500"]);
    }
    let cfg = args.daemon_config.as_ref().map(|p| p.display().to_string());
    if let Some(cfg) = cfg.as_deref() {
        daemon_args.extend(["--config", cfg]);
    }
    let mut daemon = ChildProc::spawn("thrusterd", &daemon_exe, &daemon_args, &tmp)?;
    let seed = args.seed.to_string();
    let mut sim_args = vec![
        "run",
        "--namespace",
        &ns,
        "--vehicle",
        vehicle.to_str().unwrap_or(""),
        "--noise",
        &args.noise,
        "--seed",
        &seed,
    ];
    sim_args.push(if args.realtime {
        "--realtime"
    } else {
        "--lockstep"
    });
    let mut sim = ChildProc::spawn("thruster-sim", &sim_exe, &sim_args, &tmp)?;

    let result = drive(
        &args,
        &client,
        &status_in,
        &model_in,
        &truth_in,
        &vehicle_in,
        &setpoint_out,
        &mut daemon,
        &mut sim,
        &vehicle,
    );
    let clean = daemon.stop() & sim.stop();
    drop((
        status_in,
        model_in,
        truth_in,
        vehicle_in,
        setpoint_out,
        client,
    ));
    drop(node);
    let _ = purge_namespace(&ipc);
    let leftovers = namespace_files(&ipc).map(|f| f.len()).unwrap_or(0);
    let _ = std::fs::remove_dir_all(&tmp);
    let mut summary = result?;
    summary.clean_exit = clean;
    summary.leftovers = leftovers;
    report(&args, &summary);
    if !clean || leftovers > 0 {
        bail!("shutdown was not clean (exit ok: {clean}, files left: {leftovers})");
    }
    Ok(())
}

/// Number of `[[thruster]]` tables in a vehicle file.
fn thruster_count(vehicle: &Path) -> Result<usize> {
    let text = std::fs::read_to_string(vehicle)
        .with_context(|| format!("reading {}", vehicle.display()))?;
    let value: toml::Value =
        toml::from_str(&text).with_context(|| format!("{}", vehicle.display()))?;
    let n = value
        .get("thruster")
        .and_then(|t| t.as_array())
        .map(|a| a.len())
        .unwrap_or(0);
    if !(1..=16).contains(&n) {
        bail!(
            "{}: {n} thrusters ([[thruster]] tables), expected 1..16",
            vehicle.display()
        );
    }
    Ok(n)
}

fn tempfile_dir() -> Result<PathBuf> {
    let dir = std::env::temp_dir().join(format!("thrusterd-demo-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    Ok(dir)
}

#[allow(clippy::too_many_arguments)]
fn drive(
    args: &DemoArgs,
    client: &ControlClient,
    status_in: &Inbox<StatusMsg>,
    model_in: &Inbox<ModelMsg>,
    truth_in: &Inbox<TruthMsg>,
    vehicle_in: &Inbox<VehicleStateMsg>,
    setpoint_out: &Port<Setpoint>,
    daemon: &mut ChildProc,
    sim: &mut ChildProc,
    vehicle: &Path,
) -> Result<Summary> {
    let wait = |what: &str,
                timeout: Duration,
                pred: &mut dyn FnMut(&StatusMsg) -> bool,
                d: &mut ChildProc,
                s: &mut ChildProc|
     -> Result<StatusMsg> {
        let start = Instant::now();
        loop {
            while let Some(st) = status_in.recv()? {
                if pred(&st) {
                    return Ok(st);
                }
            }
            if !d.alive() {
                bail!("thrusterd exited while waiting for {what}:\n{}", d.tail());
            }
            if !s.alive() {
                bail!(
                    "thruster-sim exited while waiting for {what}:\n{}",
                    s.tail()
                );
            }
            if start.elapsed() > timeout {
                bail!("timed out waiting for {what}\n{}\n{}", d.tail(), s.tail());
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    };
    // Both processes up; the daemon answering samples.
    let first = wait(
        "the first IMU samples",
        Duration::from_secs(30),
        &mut |s| s.samples > 20,
        daemon,
        sim,
    )?;
    let truth = {
        let start = Instant::now();
        // History 1: the simulator's truth reaches us on its next connection update.
        loop {
            if let Some(t) = latest(truth_in)? {
                break t;
            }
            if start.elapsed() > Duration::from_secs(10) {
                bail!("the simulator published no truth");
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    };
    let wall = Instant::now();
    let t0 = first.vehicle_time_ns;
    let r = client.call(
        ControlRequest::new(RequestKind::Estimate),
        Duration::from_secs(2),
    )?;
    if !r.is_ok() {
        bail!("estimate refused: {}", r.text());
    }
    let bar = if args.json {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(1)
    };
    bar.set_style(
        ProgressStyle::with_template("{spinner} estimating {bar:30} {pos}/{len} pulses  {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let done = wait(
        "the estimated model",
        Duration::from_secs(if args.realtime { 600 } else { 120 }),
        &mut |s| {
            bar.set_length(u64::from(s.pulses_planned.max(s.pulse).max(1)));
            bar.set_position(u64::from(s.pulse));
            let bound = if s.error_bound.is_finite() {
                format!("error bound {:.3}", s.error_bound)
            } else {
                String::new()
            };
            bar.set_message(format!(
                "{} {}",
                s.state().map(|x| x.name()).unwrap_or("?"),
                bound
            ));
            s.state() == Ok(DaemonState::Active) && s.model_version >= 1
        },
        daemon,
        sim,
    )?;
    bar.finish_and_clear();
    let wall_seconds = wall.elapsed().as_secs_f64();
    let vehicle_seconds = done.vehicle_time_ns.saturating_sub(t0) as f64 * 1e-9;
    let model = latest(model_in)?.context("no model published")?;
    let truth = latest(truth_in)?.unwrap_or(truth);
    let err_rot = truth.relative_error(&model, 0);
    let err_acc = truth.relative_error(&model, 3);
    let actuated: Vec<&'static str> = (0..6)
        .filter(|j| model.actuated & (1 << j) != 0)
        .map(|j| DOFS[j])
        .collect();
    if !args.json {
        print_model(
            &model,
            &truth,
            vehicle,
            err_rot,
            err_acc,
            vehicle_seconds,
            wall_seconds,
            done.pulse,
        );
    }

    // Hold: level first, then a 15 degree pitch step, scored against the simulator's truth.
    let mut tilt_yaw = None;
    let (level_err, step_err) = if args.hold_s > 0.0 {
        let _ = latest(vehicle_in)?;
        let start = latest_blocking(vehicle_in)?;
        let (_, _, yaw) = quat(start.attitude).euler_angles();
        let depth = start.position_ned[2];
        let half = args.hold_s / 2.0;
        let level = UnitQuaternion::from_euler_angles(0.0, 0.0, yaw);
        let pitched = UnitQuaternion::from_euler_angles(0.0, 15f64.to_radians(), yaw);
        let mut errs = Vec::new();
        for (target, settle) in [(level, 0.3 * half), (pitched, 0.3 * half)] {
            let q = target.into_inner();
            let sp = Setpoint {
                attitude: [q.w, q.i, q.j, q.k],
                depth,
                flags: Setpoint::HOLD_DEPTH,
                ..Setpoint::default()
            };
            setpoint_out.send(&sp)?;
            let t_start = latest_blocking(vehicle_in)?.t_ns;
            let (mut sum, mut count, mut tilt_sum, mut yaw_sum) = (0.0, 0u64, 0.0, 0.0);
            let timeout = Instant::now();
            loop {
                let Some(v) = vehicle_in.recv()? else {
                    if timeout.elapsed()
                        > Duration::from_secs(if args.realtime {
                            (half * 3.0) as u64 + 5
                        } else {
                            60
                        })
                    {
                        bail!("no vehicle state from the simulator");
                    }
                    std::thread::sleep(Duration::from_micros(200));
                    continue;
                };
                let t = v.t_ns.saturating_sub(t_start) as f64 * 1e-9;
                if t >= settle {
                    let q = quat(v.attitude);
                    sum += q.angle_to(&target).to_degrees();
                    // Tilt: angle between the body z axes; heading: yaw difference.
                    let z = nalgebra::Vector3::z();
                    tilt_sum += (q * z).angle(&(target * z)).to_degrees();
                    let dyaw = q.euler_angles().2 - target.euler_angles().2;
                    yaw_sum += dyaw.sin().atan2(dyaw.cos()).abs().to_degrees();
                    count += 1;
                }
                if t >= half {
                    break;
                }
            }
            let c = count.max(1) as f64;
            errs.push((sum / c, tilt_sum / c, yaw_sum / c));
        }
        tilt_yaw = Some((0.5 * (errs[0].1 + errs[1].1), 0.5 * (errs[0].2 + errs[1].2)));
        (Some(errs[0].0), Some(errs[1].0))
    } else {
        (None, None)
    };
    let attitude = match (level_err, step_err) {
        (Some(a), Some(b)) => Some(0.5 * (a + b)),
        _ => None,
    };
    Ok(Summary {
        vehicle: vehicle.display().to_string(),
        vehicle_seconds,
        wall_seconds,
        pulses: done.pulse,
        err_rot,
        err_acc,
        actuated,
        attitude_err_deg: attitude,
        attitude_err_level_deg: level_err,
        attitude_err_step_deg: step_err,
        tilt_err_deg: tilt_yaw.map(|t| t.0),
        yaw_err_deg: tilt_yaw.map(|t| t.1),
        clean_exit: false,
        leftovers: 0,
    })
}

fn latest_blocking(inbox: &Inbox<VehicleStateMsg>) -> Result<VehicleStateMsg> {
    let start = Instant::now();
    loop {
        if let Some(v) = latest(inbox)? {
            return Ok(v);
        }
        if start.elapsed() > Duration::from_secs(10) {
            bail!("the simulator publishes no vehicle state");
        }
        std::thread::sleep(Duration::from_micros(500));
    }
}

#[allow(clippy::too_many_arguments)]
fn print_model(
    m: &ModelMsg,
    t: &TruthMsg,
    vehicle: &Path,
    err_rot: f64,
    err_acc: f64,
    vehicle_s: f64,
    wall_s: f64,
    pulses: u32,
) {
    let n = m.count as usize;
    println!("vehicle {}: {n} thrusters", vehicle.display());
    println!(
        "learned in {vehicle_s:.1} vehicle seconds ({pulses} pulses), {wall_s:.2} s wall clock"
    );
    println!();
    println!("effectiveness per unit command (learned | truth), rad/s^2 and m/s^2");
    print!("{:>7}", "");
    for i in 0..n {
        print!(" {:>17}", format!("thruster {i}"));
    }
    println!();
    for (j, dof) in DOFS.iter().enumerate() {
        let mark = if m.actuated & (1 << j) != 0 { ' ' } else { '-' };
        print!("{dof:>6}{mark}");
        for i in 0..n {
            let truth = t.symmetric(j, i);
            print!(" {:>8.2}|{:<8.2}", m.effectiveness[j][i], truth);
        }
        println!();
    }
    println!(
        "('-': not actuated; truth = mean of forward and reverse gain, what a linear model learns)"
    );
    println!();
    println!(
        "relative error: rotation {:.1} %, acceleration {:.1} %",
        err_rot * 100.0,
        err_acc * 100.0
    );
}

fn report(args: &DemoArgs, s: &Summary) {
    if args.json {
        let obj = serde_json::json!({
            "vehicle": s.vehicle,
            "vehicle_seconds": s.vehicle_seconds,
            "wall_seconds": s.wall_seconds,
            "pulses": s.pulses,
            "err_rot": s.err_rot,
            "err_acc": s.err_acc,
            "actuated_dof": s.actuated,
            "attitude_err_deg": s.attitude_err_deg,
            "attitude_err_level_deg": s.attitude_err_level_deg,
            "attitude_err_pitch_step_deg": s.attitude_err_step_deg,
            "tilt_err_deg": s.tilt_err_deg,
            "yaw_err_deg": s.yaw_err_deg,
            "clean_exit": s.clean_exit,
            "files_left": s.leftovers,
        });
        println!("{obj}");
        return;
    }
    println!("actuated: {}", s.actuated.join(", "));
    if let (Some(a), Some(l), Some(p)) = (
        s.attitude_err_deg,
        s.attitude_err_level_deg,
        s.attitude_err_step_deg,
    ) {
        println!("attitude hold with the learned model, against the simulator's true attitude, after settling:");
        println!(
            "  mean angular error {a:.2} deg (level {l:.2} deg, 15 deg pitch step {p:.2} deg)"
        );
        if let (Some(t), Some(y)) = (s.tilt_err_deg, s.yaw_err_deg) {
            println!("  of which tilt (roll/pitch) {t:.2} deg, heading {y:.2} deg (the daemon's heading comes from the magnetometer)");
        }
    }
    println!(
        "shutdown: {} ({} files of the namespace left)",
        if s.clean_exit {
            "both processes exited cleanly"
        } else {
            "NOT clean"
        },
        s.leftovers
    );
}
