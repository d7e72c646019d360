//! `thrusterctl study --out DIR`: every vehicle file x noise preset x estimation method x seed, the
//! machine driving the simulator's physics in one process (no IPC: faster than the processes,
//! the same pure core the daemon runs), scored against the simulator's truth. Writes
//! DIR/runs.csv (one row per run), DIR/trace.csv (the estimate's error after every pulse) and
//! one SVG per noise preset of the error against vehicle seconds, mean over vehicles and seeds.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::plot::{render, Grid, Panel, Series};
use anyhow::{bail, Context, Result};
use clap::Args;
use nalgebra::DMatrix;
use thruster_sim::{NoisePreset, SensorConfig, Simulator, Vehicle};
use thrusterd_core::estimator::{EstimatorConfig, Excitation, Method};
use thrusterd_core::machine::{Machine, MachineSetup, Request, State};

use crate::excursion::Excursion;
use crate::session::config_file;

const ALL_VEHICLES: [&str; 6] = [
    "amour5",
    "amour5_top45",
    "six_dof",
    "eight_vectored",
    "four_up",
    "aligned",
];

#[derive(Args, Debug)]
pub struct MethodsArgs {
    /// Output folder (created if missing). Required without a subcommand; an `Option` only
    /// because the subcommands (fig2, pulse-power, sweep) share the command line.
    #[arg(long, required = true)]
    pub out: Option<PathBuf>,
    /// Noise presets, comma separated (none, realistic, paper).
    #[arg(long, default_value = "none,realistic,paper", value_delimiter = ',')]
    pub noise: Vec<String>,
    /// Methods, comma separated (dynamic: the default settings; forward and paper: the static
    /// methods' tuned settings, paper with round-robin pulses).
    #[arg(long, default_value = "dynamic,forward,paper", value_delimiter = ',')]
    pub methods: Vec<String>,
    /// Seeds 1..=N of the sensor noise.
    #[arg(long, default_value_t = 5)]
    pub seeds: u64,
    /// Vehicle files under config/vehicles, comma separated (default: all six).
    #[arg(long, value_delimiter = ',')]
    pub vehicles: Vec<String>,
    /// Give the vehicle a DVL (5 Hz, 0.01 m/s) whose velocity the estimation's navigation uses.
    #[arg(long)]
    pub dvl: bool,
}

/// (vehicle s since the request, err_rot, err_acc) after every pulse of one run.
pub type Trace = Vec<(f64, f64, f64)>;

/// Every run's trace of one (noise, method) pair.
struct Curve<'a> {
    noise: &'a str,
    method: &'a str,
    traces: Vec<Trace>,
}

/// One estimation, scored.
#[derive(Debug, Clone)]
pub struct Outcome {
    pub err_rot: f64,
    pub err_acc: f64,
    /// Vehicle seconds from the request to the model (the 1 s noise measurement included).
    pub seconds: f64,
    pub pulses: usize,
    /// Largest true tilt and heading change during the estimation, deg.
    pub tilt_deg: f64,
    pub heading_deg: f64,
    pub bound_rot: f64,
    pub bound_acc: f64,
    /// The error after every pulse.
    pub trace: Trace,
}

fn preset(noise: &str) -> Result<NoisePreset> {
    Ok(match noise {
        "none" => NoisePreset::None,
        "realistic" => NoisePreset::Realistic,
        "paper" => NoisePreset::Paper,
        other => bail!("--noise must be none, realistic or paper, got {other:?}"),
    })
}

fn estimator(method: &str) -> Result<EstimatorConfig> {
    Ok(match method {
        "dynamic" => EstimatorConfig::dynamic(),
        "forward" => EstimatorConfig::forward(),
        "paper" => EstimatorConfig {
            method: Method::Paper,
            excitation: Excitation::RoundRobin,
            ..EstimatorConfig::forward()
        },
        other => bail!("--methods must be dynamic, forward or paper, got {other:?}"),
    })
}

/// Symmetric truth (the mean of forward and reverse gain) and the relative error of rows
/// `first..first + 3`.
fn rel_err(est: &DMatrix<f64>, truth: &DMatrix<f64>, first: usize) -> f64 {
    let t = truth.rows(first, 3);
    (est.rows(first, 3) - t).norm() / t.norm().max(f64::MIN_POSITIVE)
}

/// One estimation of `vehicle` (a loaded file) at `noise` with `cfg`, seed `seed`.
pub fn run_one(
    vehicle: Vehicle,
    noise: NoisePreset,
    cfg: EstimatorConfig,
    seed: u64,
    dvl: bool,
) -> Result<Outcome> {
    let n = vehicle.thrusters.len();
    let sensors = SensorConfig {
        rate_hz: 200.0,
        noise,
        dvl: dvl.then(thruster_sim::DvlConfig::default),
        ..SensorConfig::default()
    };
    let mut sim = Simulator::new(vehicle, sensors, seed)?;
    let mut setup = MachineSetup {
        thrusters: n,
        estimator: cfg,
        ..MachineSetup::default()
    };
    // No driver in between: the machine compensates the T200 deadband itself.
    setup.machine.deadband = 0.05;
    let mut machine = Machine::new(setup);
    let (fwd, rev) = sim.truth();
    let truth = (fwd + rev) * 0.5;
    let tick = |machine: &mut Machine, sim: &mut Simulator| -> Result<()> {
        let r = sim.advance_and_sample();
        // As the driver does: the DVL's measurement just before the IMU sample.
        if let Some(v) = sim.dvl_measurement() {
            machine.on_dvl(v.into());
        }
        let cmd = machine.on_imu(&r);
        sim.set_commands(&cmd.thrust[..cmd.count])?;
        Ok(())
    };
    while sim.time_s() < 1.0 {
        tick(&mut machine, &mut sim)?;
    }
    machine
        .on_request(Request::Estimate)
        .map_err(|e| anyhow::anyhow!("estimate refused: {}", e.0))?;
    let start = sim.time_s();
    let mut excursion = Excursion::default();
    excursion.push_attitude(&sim.attitude());
    let mut trace = Vec::new();
    let mut seen_pulses = 0;
    loop {
        tick(&mut machine, &mut sim)?;
        excursion.push_attitude(&sim.attitude());
        if let Some(e) = machine.last_estimate() {
            if e.pulses != seen_pulses && e.excited {
                seen_pulses = e.pulses;
                trace.push((
                    sim.time_s() - start,
                    rel_err(&e.effectiveness, &truth, 0),
                    rel_err(&e.effectiveness, &truth, 3),
                ));
            }
        }
        if matches!(machine.state(), State::Active | State::Idle) {
            break;
        }
        if sim.time_s() - start > 120.0 {
            bail!("no model within 120 vehicle seconds");
        }
    }
    let model = machine.model().context("the estimation made no model")?;
    let est = machine.last_estimate().context("no estimate")?;
    Ok(Outcome {
        err_rot: rel_err(&model.effectiveness, &truth, 0),
        err_acc: rel_err(&model.effectiveness, &truth, 3),
        seconds: sim.time_s() - start,
        pulses: est.pulses,
        tilt_deg: excursion.max_tilt_deg,
        heading_deg: excursion.max_heading_deg,
        bound_rot: est.rel_err_rot,
        bound_acc: est.rel_err_acc,
        trace,
    })
}

pub fn run(args: MethodsArgs) -> Result<()> {
    let out = args
        .out
        .clone()
        .context("the methods study needs --out DIR")?;
    let vehicles: Vec<String> = if args.vehicles.is_empty() {
        ALL_VEHICLES.iter().map(|s| s.to_string()).collect()
    } else {
        args.vehicles.clone()
    };
    let noises = args
        .noise
        .iter()
        .map(|n| preset(n).map(|p| (n.as_str(), p)))
        .collect::<Result<Vec<_>>>()?;
    let methods = args
        .methods
        .iter()
        .map(|m| estimator(m).map(|c| (m.as_str(), c)))
        .collect::<Result<Vec<_>>>()?;
    if args.seeds == 0 {
        bail!("--seeds must be at least 1");
    }
    let loaded = vehicles
        .iter()
        .map(|v| {
            let file = config_file(&format!("vehicles/{v}.toml"));
            Vehicle::load(&file)
                .with_context(|| format!("vehicle {v} ({})", file.display()))
                .map(|x| (v.as_str(), x))
        })
        .collect::<Result<Vec<_>>>()?;
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;

    let mut runs = String::from(
        "vehicle,noise,method,seed,err_rot,err_acc,seconds,pulses,tilt_deg,heading_deg,bound_rot,bound_acc\n",
    );
    let mut traces = String::from("vehicle,noise,method,seed,seconds,err_rot,err_acc\n");
    // (noise, method) -> every trace, for the figures.
    let mut curves: Vec<Curve> = Vec::new();
    for (noise, p) in &noises {
        for (method, cfg) in &methods {
            let mut all = Vec::new();
            let mut mean = [0.0; 4];
            let mut count = 0.0;
            for (name, vehicle) in &loaded {
                for seed in 1..=args.seeds {
                    let o = run_one(vehicle.clone(), *p, cfg.clone(), seed, args.dvl)
                        .with_context(|| format!("{name} {noise} {method} seed {seed}"))?;
                    let _ = writeln!(
                        runs,
                        "{name},{noise},{method},{seed},{:.5},{:.5},{:.3},{},{:.2},{:.2},{:.5},{:.5}",
                        o.err_rot,
                        o.err_acc,
                        o.seconds,
                        o.pulses,
                        o.tilt_deg,
                        o.heading_deg,
                        o.bound_rot,
                        o.bound_acc
                    );
                    for (t, r, a) in &o.trace {
                        let _ = writeln!(
                            traces,
                            "{name},{noise},{method},{seed},{t:.3},{r:.5},{a:.5}"
                        );
                    }
                    mean[0] += o.err_rot;
                    mean[1] += o.err_acc;
                    mean[2] += o.seconds;
                    mean[3] = f64::max(mean[3], o.tilt_deg);
                    count += 1.0;
                    all.push(o.trace);
                }
            }
            println!(
                "{noise:9} {method:8} mean err_rot {:.4} err_acc {:.4} in {:.1} vehicle-s, largest tilt {:.0} deg ({} runs)",
                mean[0] / count,
                mean[1] / count,
                mean[2] / count,
                mean[3],
                count
            );
            curves.push(Curve {
                noise,
                method,
                traces: all,
            });
        }
    }
    write(&out.join("runs.csv"), &runs)?;
    write(&out.join("trace.csv"), &traces)?;
    for (noise, _) in &noises {
        let svg = figure(noise, &curves);
        write(&out.join(format!("error_vs_time_{noise}.svg")), &svg)?;
    }
    println!("wrote {}", out.display());
    Ok(())
}

fn write(path: &Path, text: &str) -> Result<()> {
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}

/// The mean error (over vehicles and seeds) against vehicle seconds, in 0.5 s bins, one
/// series per method; rotation and acceleration panels.
fn figure(noise: &str, curves: &[Curve]) -> String {
    const BIN: f64 = 0.5;
    const COLORS: [&str; 3] = ["#1b6ca8", "#d1495b", "#2e8b57"];
    let mut panels = vec![
        Panel {
            title: "rotation rows".into(),
            series: Vec::new(),
            y_range: Some((0.0, 0.5)),
            shade: Vec::new(),
        },
        Panel {
            title: "acceleration rows".into(),
            series: Vec::new(),
            y_range: Some((0.0, 0.5)),
            shade: Vec::new(),
        },
    ];
    let mut x_max: f64 = 1.0;
    for (k, Curve { method, traces, .. }) in curves.iter().filter(|c| c.noise == noise).enumerate()
    {
        let end = traces
            .iter()
            .flat_map(|t| t.iter().map(|p| p.0))
            .fold(0.0, f64::max);
        x_max = x_max.max(end);
        let bins = (end / BIN).ceil() as usize + 1;
        for (panel, col) in [(0usize, 1usize), (1, 2)] {
            let mut points = Vec::new();
            for b in 0..bins {
                let (lo, hi) = (b as f64 * BIN, (b + 1) as f64 * BIN);
                let vals: Vec<f64> = traces
                    .iter()
                    .flat_map(|t| t.iter().filter(|p| p.0 >= lo && p.0 < hi))
                    .map(|p| if col == 1 { p.1 } else { p.2 })
                    .filter(|v| v.is_finite())
                    .collect();
                if !vals.is_empty() {
                    points.push((
                        0.5 * (lo + hi),
                        vals.iter().sum::<f64>() / vals.len() as f64,
                    ));
                }
            }
            panels[panel].series.push(Series {
                label: method.to_string(),
                color: COLORS[k % COLORS.len()],
                dashed: false,
                points,
                band: None,
            });
        }
    }
    render(
        &Grid {
            title: format!("error against the truth while estimating, noise {noise}"),
            columns: 2,
            x_label: "vehicle seconds since the request".into(),
            y_label: "relative error".into(),
            x_max: x_max.ceil(),
            y_max: 0.5,
        },
        &panels,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The whole command on one vehicle, noise-free: the files are there, one row per run, the
    /// dynamic method within 2 % of the truth and the static forward model visibly biased
    /// (measured 0.015 and 0.18 on rotation).
    #[test]
    fn study_writes_its_tables_and_figures_and_separates_the_methods() {
        let dir = tempfile::tempdir().unwrap();
        run(MethodsArgs {
            out: Some(dir.path().to_path_buf()),
            noise: vec!["none".into()],
            methods: vec!["dynamic".into(), "forward".into()],
            seeds: 1,
            vehicles: vec!["amour5".into()],
            dvl: false,
        })
        .unwrap();
        let runs = std::fs::read_to_string(dir.path().join("runs.csv")).unwrap();
        let rows: Vec<Vec<&str>> = runs
            .lines()
            .skip(1)
            .map(|l| l.split(',').collect())
            .collect();
        assert_eq!(rows.len(), 2, "{runs}");
        let err = |m: &str| -> f64 { rows.iter().find(|r| r[2] == m).unwrap()[4].parse().unwrap() };
        assert!(err("dynamic") < 0.02, "{runs}");
        assert!(err("forward") > 0.1, "{runs}");
        let trace = std::fs::read_to_string(dir.path().join("trace.csv")).unwrap();
        assert!(trace.lines().count() > 10, "{trace}");
        let svg = std::fs::read_to_string(dir.path().join("error_vs_time_none.svg")).unwrap();
        assert!(svg.starts_with("<svg") && svg.contains("dynamic") && svg.contains("forward"));
    }

    #[test]
    fn unknown_names_are_refused_with_the_allowed_ones() {
        let dir = tempfile::tempdir().unwrap();
        let e = run(MethodsArgs {
            out: Some(dir.path().to_path_buf()),
            noise: vec!["loud".into()],
            methods: vec!["dynamic".into()],
            seeds: 1,
            vehicles: vec![],
            dvl: false,
        })
        .unwrap_err();
        assert!(e.to_string().contains("none, realistic or paper"), "{e}");
    }
}
