//! Issue 29's open item: at the paper's gyro noise the learned thruster lag is biased short.
//! Which of the estimator's inputs does it? One estimation is run as usual while the
//! simulator's truth is recorded at every sample; the dynamic fit's log (what the fit saw
//! after the navigation) is then learned from again with one input at a time replaced by the
//! truth, the rest left as measured (docs/study.md, "Where the short lag comes from"). Found:
//! the terms' inputs, the navigated velocity and the measured rate (errors-in-variables).

use std::collections::HashMap;

use nalgebra::{DMatrix, Vector3};
use thruster_sim::{SensorConfig, Vehicle};
use thrusterd_core::estimator::dynamic::lag_search::{learn_common_lag_weighted, LagRange};
use thrusterd_core::estimator::dynamic::sample_log::Navigated;
use thrusterd_core::estimator::dynamic::spin_state::lags_for_fit;
use thrusterd_core::estimator::dynamic::DynamicRun;
use thrusterd_core::estimator::EstimatorConfig;

use crate::estimation::{estimate_observed, Ideal, Outcome};

mod nav_bootstrap;
mod output_scan;
mod rate_noise;
mod response;
mod tow_scan;
mod velocity_error;
use response::{print_leaky, print_simulated, print_smoothed};

/// The simulator's truth at one sample, in the log's terms.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Truth {
    pub(crate) rate: Vector3<f64>,
    pub(crate) velocity: Vector3<f64>,
    pub(crate) down: Vector3<f64>,
    /// Body acceleration (noise-free specific force plus gravity), m/s^2.
    pub(crate) motion: Vector3<f64>,
}

/// Which of the log's inputs are replaced by the truth.
#[derive(Debug, Clone, Copy, Default)]
pub struct Replace {
    /// The rotation rows' output (the gyro they are fitted to).
    pub target_gyro: bool,
    /// The rate the terms are built from (damping, |w|w, Coriolis).
    pub rate: bool,
    /// The attitude: the gravity direction in the terms and in the acceleration rows' output.
    pub down: bool,
    /// The body velocity in the terms.
    pub velocity: bool,
    /// The body velocity in the terms set to zero (the velocity terms left out).
    pub zero_velocity: bool,
    /// The body velocity in the terms moved by the navigation's error at the log's start, held
    /// fixed in the world: what the velocity would be had the run started from the vehicle's
    /// true velocity (a vehicle moving steadily through the water, which no IMU sees).
    pub world_offset: bool,
    /// The acceleration rows' output whole (noise-free specific force, true gravity).
    pub motion: bool,
    /// With `motion`: white noise of this standard deviation added to it (m/s^2, seeded): the
    /// accelerometer's noise without the navigation's errors.
    pub motion_noise: f64,
}

/// The variants a probe learns the lag on, by name.
pub const VARIANTS: [(&str, Replace); 9] = [
    ("as measured", NONE),
    (
        "target gyro true",
        Replace {
            target_gyro: true,
            ..NONE
        },
    ),
    ("term rate true", Replace { rate: true, ..NONE }),
    (
        "rotation inputs true",
        Replace {
            target_gyro: true,
            rate: true,
            ..NONE
        },
    ),
    ("attitude true", Replace { down: true, ..NONE }),
    (
        "velocity true",
        Replace {
            velocity: true,
            ..NONE
        },
    ),
    (
        "acc output true",
        Replace {
            motion: true,
            ..NONE
        },
    ),
    (
        "all but target gyro",
        Replace {
            rate: true,
            down: true,
            velocity: true,
            motion: true,
            ..NONE
        },
    ),
    (
        "all true",
        Replace {
            target_gyro: true,
            rate: true,
            down: true,
            velocity: true,
            zero_velocity: false,
            world_offset: false,
            motion: true,
            motion_noise: 0.0,
        },
    ),
];

const NONE: Replace = Replace {
    target_gyro: false,
    rate: false,
    down: false,
    velocity: false,
    zero_velocity: false,
    world_offset: false,
    motion: false,
    motion_noise: 0.0,
};

impl Replace {
    /// From letters: g the target gyro, r the terms' rate, d the attitude, v the velocity, z
    /// the velocity zeroed, o the velocity's error at the start taken out (fixed in the
    /// world), m the acceleration rows' output, n that output true plus the paper's
    /// accelerometer noise ("-": nothing).
    pub fn from_letters(s: &str) -> Replace {
        Replace {
            target_gyro: s.contains('g'),
            rate: s.contains('r'),
            down: s.contains('d'),
            velocity: s.contains('v'),
            zero_velocity: s.contains('z'),
            world_offset: s.contains('o'),
            motion: s.contains('m') || s.contains('n'),
            // The paper's accelerometer, 0.05 g.
            motion_noise: if s.contains('n') { 0.49 } else { 0.0 },
        }
    }
}

/// One estimation on `v` and the lag learned from its last log with each of `variants`
/// (default [`VARIANTS`]), the profile's outputs weighted by `weights` (DOF order; ones: the
/// estimator's score): the outcome, the variants' names and lags (NaN where nothing was
/// learned).
pub fn probe(
    v: Vehicle,
    sensors: SensorConfig,
    seed: u64,
    cfg: EstimatorConfig,
    ideal: Ideal,
    variants: &[(String, Replace)],
    weights: &[f64; 6],
) -> (Outcome, Vec<(String, f64)>) {
    let gravity = v.body.gravity_mps2;
    let mut truth: HashMap<u64, Truth> = HashMap::new();
    let mut last: Option<DynamicRun> = None;
    let mut pulses = usize::MAX;
    // The simulator's symmetric truth at the last sample (LAG_PROBE_FIT's reference).
    let mut truth_b: Option<DMatrix<f64>> = None;
    let (mut idle_sum, mut idle_world, mut idle_n) = (Vector3::zeros(), Vector3::zeros(), 0.0);
    let mut idle_f = Vector3::zeros();
    let outcome = estimate_observed(v, sensors, seed, cfg, ideal, &mut |machine, sim| {
        if machine.state() == thrusterd_core::machine::State::Idle {
            idle_sum += sim.angular_velocity();
            idle_world += sim.attitude() * sim.angular_velocity();
            idle_n += 1.0;
            // The specific force in the world, forgetting over 20 s (LAG_PROBE_ERR's print).
            let f_world = sim.attitude() * Vector3::from(sim.ideal_sample().accel);
            idle_f = idle_f * (1.0 - 0.005 / 20.0) + f_world * (0.005 / 20.0);
        }
        let (f, r) = sim.truth();
        truth_b = Some((f + r) * 0.5);
        let down = sim.attitude().inverse_transform_vector(&Vector3::z());
        let ideal = sim.ideal_sample();
        truth.insert(
            sim.time_ns(),
            Truth {
                rate: sim.angular_velocity(),
                velocity: sim.linear_velocity(),
                down,
                motion: Vector3::from(ideal.accel) + down * gravity,
            },
        );
        // The run as the last decision saw it: snapshot when a pulse ends.
        if let Some(est) = machine.estimator() {
            if est.pulses() != pulses {
                pulses = est.pulses();
                last = est.dynamic_fit().cloned();
            }
        }
    });
    if idle_n > 0.0 && std::env::var_os("LAG_PROBE_ERR").is_some() {
        // What the vehicle did while idle (truth): its mean rotation, body and world, and
        // the world's specific force, which a rest's "down" averages.
        println!(
            "  idle mean true rate body {:.4?} world {:.4?} over {idle_n} samples",
            (idle_sum / idle_n).as_slice(),
            (idle_world / idle_n).as_slice()
        );
        println!(
            "  idle specific force in the world, last 20 s: {:.4?} (horizontal over g {:.4})",
            idle_f.as_slice(),
            idle_f.xy().norm() / idle_f.norm()
        );
    }
    let Some(run) = last else {
        return (outcome, Vec::new());
    };
    if std::env::var_os("LAG_PROBE_ERR").is_some() {
        print_errors(&run, &truth);
    }
    if std::env::var_os("LAG_PROBE_OUTPUTS").is_some() {
        output_scan::print_output_scan(&run, &outcome);
    }
    if let Ok(spec) = std::env::var("LAG_PROBE_SMOOTH") {
        print_smoothed(&run, &spec, &truth, weights);
    }
    if let Ok(spec) = std::env::var("LAG_PROBE_LEAK") {
        print_leaky(&run, &spec, &truth, weights);
    }
    if let Ok(spec) = std::env::var("LAG_PROBE_SIM") {
        print_simulated(&run, &spec, &truth, weights);
    }
    if let (Ok(spec), Some(truth_b)) = (std::env::var("LAG_PROBE_SIMEX"), truth_b.as_ref()) {
        rate_noise::print_simex(&run, &spec, &outcome, truth_b, seed, gravity);
    }
    if let (Ok(spec), Some(truth_b)) = (std::env::var("LAG_PROBE_BOOT"), truth_b.as_ref()) {
        nav_bootstrap::print_nav_bootstrap(&run, &spec, &outcome, &truth, truth_b, seed, gravity);
    }
    if let (Some(_), Some(truth_b)) = (std::env::var_os("LAG_PROBE_VEL_PARTS"), truth_b.as_ref()) {
        velocity_error::print_velocity_parts(&run, &outcome, &truth, truth_b);
    }
    if let (Ok(spec), Some(truth_b)) = (std::env::var("LAG_PROBE_TOW"), truth_b.as_ref()) {
        tow_scan::print_tow_scan(&run, &spec, &truth, truth_b, weights);
    }
    if let (Ok(spec), Some(truth_b)) = (std::env::var("LAG_PROBE_SMOOTH_FIT"), truth_b.as_ref()) {
        rate_noise::print_smoothed_fit(&run, &spec, &outcome, truth_b);
    }
    let default: Vec<(String, Replace)> =
        VARIANTS.iter().map(|(n, r)| (n.to_string(), *r)).collect();
    let variants = if variants.is_empty() {
        &default[..]
    } else {
        variants
    };
    let offset = start_offset_in_world(&run, &truth);
    let lags = variants
        .iter()
        .map(|(name, r)| {
            let mut rng = Normal(0x9e37_79b9_7f4a_7c15 ^ seed);
            let mapped = run.with_log_mapped(|s| replaced(s, r, &truth, gravity, offset, &mut rng));
            let mapped = mapped.map(|m| shifted_commands(m, env_or("LAG_PROBE_SHIFT", 0)));
            if let (Some(m), Some(truth_b), true) = (
                mapped.as_ref(),
                truth_b.as_ref(),
                std::env::var_os("LAG_PROBE_FIT").is_some(),
            ) {
                print_fit(name, m, &outcome, truth_b);
            }
            let lag = mapped
                .and_then(|m| {
                    learn_common_lag_weighted(&m, &LagRange::default(), &Vector3::zeros(), weights)
                })
                .map_or(f64::NAN, |l| l.lag_s);
            (name.clone(), lag)
        })
        .collect();
    (outcome, lags)
}

/// LAG_PROBE_SHIFT's run: each sample of `run`'s log under the command `shift` samples later
/// (negative: earlier), the ends held. Why: tells a command paired with the wrong sample
/// (a fit better shifted) from one paired right.
fn shifted_commands(run: DynamicRun, shift: i64) -> DynamicRun {
    if shift == 0 {
        return run;
    }
    let commands: Vec<u32> = run
        .log()
        .map(|l| l.iter().map(|s| s.command).collect())
        .unwrap_or_default();
    let last = commands.len() as i64 - 1;
    let mut k = 0i64;
    run.with_log_mapped(|s| {
        let mut out = *s;
        out.command = commands[(k + shift).clamp(0, last.max(0)) as usize];
        k += 1;
        out
    })
    .unwrap_or(run)
}

/// LAG_PROBE_FIT: the variant's log fitted at the lags the estimation learned, its err_rot /
/// err_acc against the simulator's symmetric truth. Why: the variants' lags say where the
/// profile moves; this says whether the model does, with every input true.
fn print_fit(name: &str, run: &DynamicRun, outcome: &Outcome, truth_b: &DMatrix<f64>) {
    let n = run.thrusters();
    let per_thruster = &outcome.terms.spin_up_per_thruster_s;
    let mut lags = lags_for_fit(n, outcome.spin_up_s, None, Some(per_thruster));
    // LAG_PROBE_LAGS (s, comma-separated, one per thruster): fitted at these instead (the
    // simulator's, to tell the lags' error from the fit's).
    if let Ok(given) = std::env::var("LAG_PROBE_LAGS") {
        for (l, v) in lags.iter_mut().zip(given.split(',')) {
            *l = v.parse().expect("LAG_PROBE_LAGS: seconds");
        }
    }
    let Some(fit) = run.refit(&lags[..n]) else {
        return;
    };
    let sol = fit.solve(&[1e-3; 6], 0.0, 0.0, None);
    let (rot, acc) = rel_err(&sol.b, truth_b);
    // The fit's own statistical bound (no model-error floor): what the errors are to be
    // held against where the inputs are true and only white noise is left.
    println!(
        "  fit {name}: err_rot {rot:.4} err_acc {acc:.4} statistical bound {:.4}/{:.4}",
        sol.rel_err[0], sol.rel_err[1]
    );
}

/// `run`'s log fitted at `lags`: its B.
pub(crate) fn fitted_b(run: &DynamicRun, lags: &[f64]) -> Option<DMatrix<f64>> {
    Some(run.refit(lags)?.solve(&[1e-3; 6], 0.0, 0.0, None).b)
}

/// B's relative Frobenius error against `truth_b`, rotation and acceleration rows.
pub(crate) fn rel_err(b: &DMatrix<f64>, truth_b: &DMatrix<f64>) -> (f64, f64) {
    let err = |rows: usize| {
        (b.rows(rows, 3) - truth_b.rows(rows, 3)).norm() / truth_b.rows(rows, 3).norm()
    };
    (err(0), err(3))
}

/// The environment's `key` parsed, or `default` when unset or unparsable.
fn env_or<T: std::str::FromStr>(key: &str, default: T) -> T {
    std::env::var(key)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// Sample `s` with the inputs `r` names replaced by the truth at its time.
fn replaced(
    s: &Navigated,
    r: &Replace,
    truth: &HashMap<u64, Truth>,
    gravity: f64,
    world_offset: Vector3<f64>,
    rng: &mut Normal,
) -> Navigated {
    let Some(t) = truth.get(&((s.t_s * 1e9).round() as u64)) else {
        return *s;
    };
    let mut out = *s;
    if r.target_gyro {
        out.gyro = t.rate;
    }
    if r.rate {
        // LAG_PROBE_RNOISE: white noise of that many rad/s on the true rate (the terms' noise
        // without the target's).
        let sd: f64 = env_or("LAG_PROBE_RNOISE", 0.0);
        out.rate = t.rate + Vector3::from_fn(|_, _| sd * rng.sample());
    }
    if r.velocity {
        out.velocity = t.velocity;
    }
    if r.zero_velocity {
        out.velocity = Vector3::zeros();
    }
    if r.world_offset {
        out.velocity = s.velocity + s.attitude.inverse_transform_vector(&world_offset);
    }
    if r.down {
        out.down = t.down;
        // The navigated gravity in the acceleration rows' output goes with the attitude.
        out.motion += (t.down - s.down) * gravity;
    }
    if r.motion {
        out.motion = t.motion + Vector3::from_fn(|_, _| r.motion_noise * rng.sample());
    }
    out
}

/// The navigated velocity's error at the log's first sample with a truth, in the world
/// (true less navigated, through the navigation's attitude); zero without one.
fn start_offset_in_world(run: &DynamicRun, truth: &HashMap<u64, Truth>) -> Vector3<f64> {
    run.log()
        .and_then(|log| {
            log.iter().find_map(|s| {
                let t = truth.get(&((s.t_s * 1e9).round() as u64))?;
                Some(s.attitude.transform_vector(&(t.velocity - s.velocity)))
            })
        })
        .unwrap_or_else(Vector3::zeros)
}

/// Standard normal draws (xorshift64 and Box-Muller): the probe's own noise, seeded.
pub(crate) struct Normal(pub(crate) u64);

impl Normal {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        ((self.0 >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    pub(crate) fn sample(&mut self) -> f64 {
        let (u, v) = (self.uniform(), self.uniform());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }
}

/// RMS over the log of the navigated inputs' errors against the truth and of the truth itself,
/// per axis (a lab print for the decisive runs).
fn print_errors(run: &DynamicRun, truth: &HashMap<u64, Truth>) {
    let Some(log) = run.log() else { return };
    let mut err = [[0.0f64; 3]; 5];
    let mut sig = [[0.0f64; 3]; 5];
    let mut n = 0.0;
    for s in log.iter() {
        let Some(t) = truth.get(&((s.t_s * 1e9).round() as u64)) else {
            continue;
        };
        n += 1.0;
        let pairs = [
            (s.gyro, t.rate),
            (s.rate, t.rate),
            (s.down, t.down),
            (s.velocity, t.velocity),
            (s.motion, t.motion),
        ];
        for (k, (m, tr)) in pairs.iter().enumerate() {
            for a in 0..3 {
                err[k][a] += (m[a] - tr[a]).powi(2);
                sig[k][a] += tr[a].powi(2);
            }
        }
    }
    // The attitude's error at the log's start and end: where it came from.
    let ends: Vec<f64> = [log.iter().next(), log.iter().last()]
        .iter()
        .flatten()
        .filter_map(|s| {
            let t = truth.get(&((s.t_s * 1e9).round() as u64))?;
            Some((s.down - t.down).norm())
        })
        .collect();
    println!("  down error at the log's start / end: {ends:.4?}");
    for (k, name) in ["gyro", "rate", "down", "velocity", "motion"]
        .iter()
        .enumerate()
    {
        let f = |v: [f64; 3]| v.map(|x| format!("{:.4}", (x / n).sqrt())).join(" ");
        println!(
            "  {name:8}: error rms {} | truth rms {}",
            f(err[k]),
            f(sig[k])
        );
    }
}

/// The truth at vehicle time `t_s` (s), keyed by its nanosecond.
pub(crate) fn truth_at(truth: &HashMap<u64, Truth>, t_s: f64) -> Option<&Truth> {
    truth.get(&((t_s * 1e9).round() as u64))
}
