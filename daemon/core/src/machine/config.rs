//! How the machine is configured: its own settings and everything it is set up with.

use serde::{Deserialize, Serialize};

use super::types::Geometry;
use crate::adaptation::identification::IdentificationConfig;
use crate::adaptation::monitor::MonitorConfig;
use crate::adaptation::refinement::RefinementConfig;
use crate::attitude::AttitudeConfig;
use crate::controller::ControllerConfig;
use crate::estimator::EstimatorConfig;
use crate::model::RigidBody;

/// What a reconfiguration event leads to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ReconfigPolicy {
    /// Re-estimate at once (default).
    Estimate,
    /// Swap nominal/cached models where possible, estimate only on request.
    OnRequest,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MachineConfig {
    /// Rest period for the noise levels, s (default 1.0: 200 samples at 200 Hz put the sigma
    /// within ~5 %).
    pub noise_s: f64,
    /// An estimation asked for while idle counts the rest the vehicle took while idle, up to
    /// the request, towards `noise_s` (default true): after `noise_s` idle it pulses at the
    /// next sample. Why: the rest after the request was a fixed second of every
    /// time-to-model, a fifth of it with a realistic IMU (issue 30). The rest is the same
    /// one, taken earlier: the last 1-2 `noise_s` of an unbroken idle spell with no
    /// reconfiguration in it (`machine::estimation::idle_rest`). Estimations that start
    /// while controlling, or on a reconfiguration, still measure after the start.
    pub rest_from_idle: bool,
    /// With `rest_from_idle`, once the machine has idled this long (s; default 60, 0 = never),
    /// the gyro's bias over the last 1-2 `gyro_bias_rest_s` of the idle spell, from how the
    /// gyro turned gravity and the magnetometer's heading (`navigation::long_rest_bias`), and
    /// "down" averaged over its last third, carried by the gyro (`long_rest_down`), stand for
    /// the 1-2 s rest's when the two biases differ by more than noise and a walking bias
    /// explain: the rest moved. Why: in a swell the 1-2 s rest takes the swell's rotation for
    /// bias (0.04-0.19 rad/s at a 6.7 s period) and its acceleration for a tilt, and the
    /// navigation carried both through the run (eight_vectored in the full moderate swell:
    /// gravity 0.36 rad off). In still water the short rest stays: fresher.
    pub gyro_bias_rest_s: f64,
    /// A long idle rest (`gyro_bias_rest_s`) saw still water when the vehicle swayed from one
    /// second to the next no more than this many times what the IMU's white noise explains
    /// (`navigation::long_rest_sway`; default 1.5, still water reading 1 +- 0.1; 0: the
    /// reading not used, neither still nor moved). Only then does the open-loop fit hold the
    /// velocity terms lightly (`estimator.velocity_term_prior_sd`). Why: at the paper's noise that prior's tighter
    /// bound is honest in still water but not in a swell, which neither the 1-2 s rest nor the
    /// fit's unexplained rotation can see there, and a minute's rest can. Where it read more,
    /// the water moved: `estimator.moving_rest_drift_states`.
    pub max_still_sway: f64,
    /// A noise rest begun within 10 s (`MAX_SWING_WAIT_S`, `machine/estimation.rs`) of the
    /// thrusters driving the vehicle starts over while its gyro swings, beyond the gyro's
    /// white noise, more than this, rad/s (default 0.0125, a quarter of
    /// `max_unexplained_rate_radps`; 0: never). Why: an
    /// estimate asked for 0.5 s after an emergency stop that came 10 ms into the pulses found
    /// AMOUR-5 swinging at up to 0.23 rad/s from that push; the rest took the swing for the
    /// gyro's noise (0.053 rad/s against a white 0.002), the water check read it as
    /// unexplained rotation and refused the model, and every estimate asked at once after
    /// that refusal again (0.09-0.12 rad/s: the vehicle swinging from the last pulses). Seen
    /// in CI, decided in process (docs/reliability.md, "An estimate right after the
    /// thrusters stopped").
    pub max_rest_swing_radps: f64,
    /// An estimation that starts while the daemon controls (a reconfiguration, a mismatch, a
    /// request) first levels the vehicle with the model in force, for at most this long, s
    /// (default 5; 0 = pulse from wherever the vehicle is). Why: started mid-manoeuvre, the
    /// "rest" the noise is measured in was a swinging vehicle, and the pulses then tumbled
    /// AMOUR-5 past 150 deg in the hot-swap experiment.
    pub level_max_s: f64,
    /// Levelling ends once the tilt stayed below `level_tilt_deg` for `level_hold_s`
    /// (defaults 5 deg, 1 s).
    pub level_tilt_deg: f64,
    pub level_hold_s: f64,
    /// Length of one excitation pulse, s (default 0.1; the paper used 1.0). Short pulses keep
    /// the vehicle in the regime where the response is still the thrust's, not the drag's: on a
    /// BlueROV2-class body quadratic roll/yaw damping already takes ~5 % off the rate after
    /// 0.1 s (docs/simulation.md).
    pub pulse_s: f64,
    /// Minimum pause after a pulse, s (default 0.15).
    pub settle_min_s: f64,
    /// Maximum pause after a pulse, s (default 1.0; the paper paused a fixed 3 s). The per-pulse
    /// intercept absorbs what is left of the last pulse's motion.
    pub settle_max_s: f64,
    /// The pause ends once every gyro axis stayed within k sigma of rest for this long, s
    /// (default 0.1).
    pub settle_quiet_s: f64,
    /// A new estimated model is swapped in only if both relative error bounds are below this
    /// (default 0.25).
    pub max_swap_rel_err: f64,
    /// An estimated model is refused when more of the vehicle's rotation than this is
    /// explained by neither thrust nor its own dynamics, rad/s (the larger of the rotation
    /// rows' residual and the gyro's level over the rest, beyond the gyro's white noise: in a
    /// swell the rest is not still; `DynamicTerms::unexplained_rate_radps`; default
    /// 0.05). Why: a swell's torque made models 5-38 % off whose bounds said 4-20 %; it left
    /// 0.013-0.12 rad/s unexplained where still water leaves 0-0.0001 (docs/study.md, "Moving
    /// water"). Not 0.01: a real-time session on a loaded machine in still water left 0.021.
    pub max_unexplained_rate_radps: f64,
    /// In moving water (rotation left unexplained), an estimated model is refused when the
    /// rotation rows alone and the acceleration rows alone put the learned lag so far apart
    /// that the gap would move B by more than this many times its reported bound
    /// (`estimator::dynamic::lag_agreement::gap_over_bound`; default 1.5, issue 32's
    /// coverage; 0: never). Why: open loop in a swell the lag came out 5-12 % off with a
    /// deviation of 0.5-1 %, and the model 10-17 % off under a 4-6 % bound; the groups were
    /// then 3-18 deviations apart (docs/study.md, "The lag in a swell").
    pub max_lag_gap_over_bound: f64,
    /// In moving water (rotation left unexplained), an open-loop model is refused when the
    /// vehicle tilted more than this during the run, deg (default 50; 0: never). Why: the
    /// pulses tilt every vehicle file 13-27 deg in still water (amour5_reverse60's uneven
    /// thrust 63-75 deg, never refused: still water leaves no rotation unexplained), so a
    /// vehicle past 50 deg was thrown by the water, and the fit's acceleration rows, which
    /// rest on the dead-reckoned velocity, were then 0.08-0.29 off under bounds of 0.04-0.13
    /// (docs/study.md, "A vehicle the water threw").
    pub max_moving_water_tilt_deg: f64,
    /// "estimate" (default) or "on_request".
    pub on_reconfig: ReconfigPolicy,
    /// Hold attitude with the new model after an estimation (default true); otherwise Idle.
    pub control_after_estimate: bool,
    /// A gap between sample timestamps above this is a sensor dropout, s (default 0.1).
    pub max_sample_gap_s: f64,
    /// Consecutive good samples that end a fault (default 20).
    pub recover_samples: u32,
    /// Thruster deadband the daemon compensates, as a fraction of full command (default 0: the
    /// drivers, thruster-sim and thruster-hw, own their actuators' deadband). For a driver that
    /// does not, a command u != 0 goes out as sign(u) (deadband + (1 - deadband) |u|), so thrust
    /// stays proportional to what the estimator and controller asked for.
    pub deadband: f64,
    /// Vehicle time a solve (the estimate after a pulse, a stop decision, an interval's
    /// decision under control, the final model, a refinement window's fit) is given, s
    /// (default 0.02). Its result is applied at the first sample at or after submission +
    /// this, whoever computed it, so the daemon (a solver thread) and replay (inline) reach
    /// the same models at the same samples. 20 ms is over 5x the slowest solve (3.6 ms at
    /// N = 16 with a carried-over prior) and 4 samples at 200 Hz; longer delays every
    /// decision by as much (the run goes on pulsing or dithering meanwhile; at 30 ms the
    /// change test's noise-free detection moved from 3.8 s to the window's 6.5 s, through the
    /// vehicle's slightly different path). In (0, 1].
    pub solve_budget_s: f64,
    /// While the daemon controls, an attitude error (on the axes the model actuates) whose mean
    /// over the last `lost_hold_s` is beyond `lost_hold_deg` means the model in force does not
    /// hold the vehicle: thrusters neutral, and (with `monitor.action = "estimate"`) an
    /// estimation from rest, which needs no model; lost again before an operator's estimate or
    /// hold, a reconfiguration or a minute held, the thrusters stay neutral. Defaults 45 deg,
    /// 10 s (0 s: off; 30 deg fired on a held vehicle in rough water with pitch steps, whose
    /// 10 s mean reached 30.4). Why: every other check judges a model only while the vehicle is
    /// held, so a wrong declared geometry was held 36-69 deg off its setpoint for good
    /// (`machine::hold_watch`).
    /// A 100 deg heading error after the pulses is undone in 3-5 s; the limit is not a
    /// manoeuvre's.
    pub lost_hold_deg: f64,
    pub lost_hold_s: f64,
}

impl Default for MachineConfig {
    fn default() -> Self {
        MachineConfig {
            noise_s: 1.0,
            rest_from_idle: true,
            gyro_bias_rest_s: 60.0,
            max_still_sway: 1.5,
            max_rest_swing_radps: 0.0125,
            level_max_s: 5.0,
            level_tilt_deg: 5.0,
            level_hold_s: 1.0,
            pulse_s: 0.1,
            settle_min_s: 0.15,
            settle_max_s: 1.0,
            settle_quiet_s: 0.1,
            max_swap_rel_err: 0.25,
            max_unexplained_rate_radps: 0.05,
            max_lag_gap_over_bound: 1.5,
            max_moving_water_tilt_deg: 50.0,
            on_reconfig: ReconfigPolicy::Estimate,
            control_after_estimate: true,
            max_sample_gap_s: 0.1,
            recover_samples: 20,
            deadband: 0.0,
            solve_budget_s: 0.02,
            lost_hold_deg: 45.0,
            lost_hold_s: 10.0,
        }
    }
}

/// Everything the machine is configured with.
#[derive(Debug, Clone, Default)]
pub struct MachineSetup {
    pub machine: MachineConfig,
    pub estimator: EstimatorConfig,
    pub controller: ControllerConfig,
    pub attitude: AttitudeConfig,
    pub monitor: MonitorConfig,
    pub identification: IdentificationConfig,
    pub refinement: RefinementConfig,
    pub body: RigidBody,
    /// Thrusters at start.
    pub thrusters: usize,
    /// Declared geometry at start (positions m, directions), if known.
    pub geometry: Option<Geometry>,
    /// Commands referred to a reference supply voltage (`[supply]`).
    pub supply: crate::supply::SupplyConfig,
}
