//! The experiment's results as types: the summary, every run's scores and hot-swap's. The
//! headline, the report and the tests read fields, so a wrong name is a compile error (it was
//! a string path into the JSON, checked only when a run had ended). Their JSON is the output:
//! written through a [`Value`], whose map (serde_json without `preserve_order`) sorts the
//! keys as every summary has had them, and read back with unknown fields refused. Degrade's and dive's scores live with their
//! experiments ([`degrade::Scores`], [`dive::Scores`]).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::*;

/// A score: rounded to 4 decimals where measured, NaN where not (no settled step, an event
/// that did not happen). The JSON writes NaN as `null` and reads `null` back as NaN, so a
/// ratio of an unmeasured score is unmeasured too, as it was when read from the JSON.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(from = "Option<f64>", into = "Option<f64>")]
pub(super) struct Num(f64);

impl Num {
    /// Not measured.
    pub(super) const NONE: Num = Num(f64::NAN);

    /// The number, NaN where not measured.
    pub(super) fn get(self) -> f64 {
        self.0
    }

    /// The number where measured.
    pub(super) fn value(self) -> Option<f64> {
        self.0.is_finite().then_some(self.0)
    }
}

impl Default for Num {
    fn default() -> Num {
        Num::NONE
    }
}

impl From<Option<f64>> for Num {
    fn from(x: Option<f64>) -> Num {
        Num(x.unwrap_or(f64::NAN))
    }
}

impl From<Num> for Option<f64> {
    fn from(x: Num) -> Option<f64> {
        x.value()
    }
}

/// A score as the JSON keeps it: 4 decimals, what is not finite not measured.
pub(super) fn num(x: f64) -> Num {
    if x.is_finite() {
        Num((x * 1e4).round() / 1e4)
    } else {
        Num::NONE
    }
}

pub(super) fn opt(x: Option<f64>) -> Num {
    x.map_or(Num::NONE, num)
}

/// What `thrusterctl experiment NAME --json` prints and `--out` writes.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct Summary {
    pub(super) experiment: String,
    pub(super) seed: u64,
    /// The simulated vehicle's IMU position and water (`crate::water`'s own JSON).
    pub(super) vehicle_as_is: Value,
    pub(super) noise: String,
    pub(super) pace_requested: f64,
    pub(super) sim_has_pace: bool,
    pub(super) daemon_has_monitor: bool,
    pub(super) runs: Runs,
    /// The claim and its figures: one shape per experiment, read only whole (printed, and
    /// every number of it spread over seeds by `crate::seeds`).
    pub(super) headline: Value,
}

impl Summary {
    /// The JSON: through a [`Value`], so the keys come sorted as they always have (a struct
    /// written directly keeps its fields' order).
    pub(super) fn json(&self) -> Result<Value> {
        Ok(serde_json::to_value(self)?)
    }
}

/// Every run's scores by its label ([`RunSpec::label`]).
#[derive(Debug, Default, Serialize, Deserialize)]
#[serde(transparent)]
pub(super) struct Runs(pub(super) BTreeMap<String, RunScores>);

impl Runs {
    /// The run labelled `label`, an error naming it where the experiment has none.
    pub(super) fn get(&self, label: &str) -> Result<&RunScores> {
        self.0
            .get(label)
            .with_context(|| format!("the experiment has no run {label:?}"))
    }
}

/// One run's scores: every run's, and its experiment's where it has its own.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RunScores {
    pub(super) vehicle: String,
    pub(super) model: ModelScores,
    pub(super) estimation_vehicle_s: Num,
    pub(super) estimation_pulses: Option<u32>,
    pub(super) hold_start_s: Num,
    pub(super) hold_s: Num,
    pub(super) mean_err_deg: Num,
    pub(super) settled_mean_err_deg: Num,
    pub(super) max_err_deg: Num,
    pub(super) mean_abs_yaw_err_deg: Num,
    pub(super) per_maneuver: PerManeuver,
    pub(super) oscillation: Oscillation,
    pub(super) monitor_mismatch_at_s: Num,
    pub(super) monitor_mismatch_reports: usize,
    pub(super) monitor_mismatch_lines: Vec<String>,
    pub(super) model_refinements: usize,
    pub(super) model_swaps: Vec<SwapScore>,
    pub(super) status_changes: usize,
    pub(super) vehicle_samples_scored: usize,
    pub(super) wall_s: Num,
    pub(super) pace: Num,
    pub(super) clean_exit: bool,
    pub(super) files_left: usize,
    /// hot-swap's runs only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(super) hot_swap: Option<HotSwapScores>,
    /// degrade's runs only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(super) degrade: Option<degrade::Scores>,
    /// dive's runs only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(super) dive: Option<dive::Scores>,
    /// The simulator's sensor noise preset of the run.
    pub(super) noise: String,
}

impl RunScores {
    /// hot-swap's scores, an error naming the run where it has none.
    pub(super) fn hot_swap(&self, label: &str) -> Result<&HotSwapScores> {
        self.hot_swap
            .as_ref()
            .with_context(|| format!("run {label:?} has no hot-swap scores"))
    }

    pub(super) fn degrade(&self, label: &str) -> Result<&degrade::Scores> {
        self.degrade
            .as_ref()
            .with_context(|| format!("run {label:?} has no degrade scores"))
    }

    pub(super) fn dive(&self, label: &str) -> Result<&dive::Scores> {
        self.dive
            .as_ref()
            .with_context(|| format!("run {label:?} has no dive scores"))
    }
}

/// The model the run held with, against the simulator's truth.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct ModelScores {
    /// How the run got it (manual, estimated, the truth loaded).
    pub(super) start: String,
    pub(super) method: String,
    pub(super) source: String,
    pub(super) version: u64,
    pub(super) actuated: Vec<String>,
    pub(super) rel_err_rot_vs_truth: Num,
    pub(super) rel_err_acc_vs_truth: Num,
}

/// The maneuvers a plan's steps belong to ([`Step::group`]), each scored where the run made it.
#[derive(Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct PerManeuver {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(super) level: Option<ManeuverScores>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(super) yaw: Option<ManeuverScores>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(super) pitch: Option<ManeuverScores>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(super) roll: Option<ManeuverScores>,
}

impl PerManeuver {
    /// The maneuvers made, in the JSON's (alphabetical) order, the report's since it printed
    /// them from the JSON.
    pub(super) fn made(&self) -> impl Iterator<Item = (&'static str, &ManeuverScores)> {
        [
            ("level", &self.level),
            ("pitch", &self.pitch),
            ("roll", &self.roll),
            ("yaw", &self.yaw),
        ]
        .into_iter()
        .filter_map(|(name, s)| s.as_ref().map(|s| (name, s)))
    }

    /// The pitch maneuver's scores, an error naming the run where it made none.
    pub(super) fn pitch(&self, label: &str) -> Result<&ManeuverScores> {
        self.pitch
            .as_ref()
            .with_context(|| format!("run {label:?} made no pitch maneuver"))
    }

    pub(super) fn yaw(&self, label: &str) -> Result<&ManeuverScores> {
        self.yaw
            .as_ref()
            .with_context(|| format!("run {label:?} made no yaw maneuver"))
    }
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct ManeuverScores {
    pub(super) mean_err_deg: Num,
    pub(super) settled_mean_err_deg: Num,
    pub(super) mean_abs_yaw_err_deg: Num,
    pub(super) max_abs_yaw_err_deg: Num,
}

/// What is left after the first step's transient, in the DOFs that matter.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct Oscillation {
    pub(super) roll_rate_rms_deg_s: Num,
    pub(super) sway_vel_rms_m_s: Num,
    pub(super) heave_vel_rms_m_s: Num,
    pub(super) high_passed_err_rms_deg: Num,
    pub(super) thrust_activity_per_s: Num,
}

/// A new model in force ([`Swap`]).
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct SwapScore {
    pub(super) t_s: Num,
    pub(super) version: u64,
    pub(super) source: String,
}

/// hot-swap's scores: before / during / after the change, the swap and recovery times.
#[derive(Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct HotSwapScores {
    /// While the daemon re-estimated after the change; none where it did not.
    pub(super) reestimation: Option<Reestimation>,
    pub(super) t_change_s: Num,
    pub(super) announced: bool,
    pub(super) truth_changed_at_s: Num,
    pub(super) detection_delay_s: Num,
    pub(super) reestimation_start_delay_s: Num,
    pub(super) first_swap_delay_s: Num,
    pub(super) first_swap_source: Option<String>,
    pub(super) new_model_delay_s: Num,
    pub(super) new_model_version: Option<u64>,
    pub(super) new_model_rel_err_rot_vs_truth: Num,
    pub(super) recovery_threshold_deg: Num,
    pub(super) recovered_after_s: Num,
    pub(super) worst_window_after_change_deg: Num,
    pub(super) before: Part,
    pub(super) during: Part,
    pub(super) after: Part,
}

/// The hold over one part of a hot-swap run.
#[derive(Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct Part {
    pub(super) mean_err_deg: Num,
    pub(super) max_err_deg: Num,
    pub(super) mean_abs_yaw_err_deg: Num,
    pub(super) mean_abs_yaw_err_pitching_deg: Num,
    pub(super) samples: usize,
}

/// How far the vehicle went while the daemon re-estimated, from the true attitude.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct Reestimation {
    pub(super) max_tilt_deg: Num,
    pub(super) max_heading_change_deg: Num,
    /// From the setpoint: the manoeuvres go on while the daemon identifies under control, so
    /// the tilt includes the commanded pitch.
    pub(super) max_err_deg: Num,
    pub(super) vehicle_s: Num,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hot-swap run's scores as `--json` writes them (figures from a run, some not measured).
    fn hot_swap_run() -> Value {
        let part = json!({
            "mean_err_deg": 4.1, "max_err_deg": 21.3, "mean_abs_yaw_err_deg": 1.2,
            "mean_abs_yaw_err_pitching_deg": null, "samples": 812,
        });
        json!({
            "vehicle": "amour5",
            "model": {
                "start": "estimated", "method": "Dynamic", "source": "Estimated", "version": 1,
                "actuated": ["roll", "pitch", "yaw", "surge", "heave"],
                "rel_err_rot_vs_truth": 0.0512, "rel_err_acc_vs_truth": 0.063,
            },
            "estimation_vehicle_s": 7.0, "estimation_pulses": 60,
            "hold_start_s": 9.05, "hold_s": 120.0,
            "mean_err_deg": 5.55, "settled_mean_err_deg": null, "max_err_deg": 23.8,
            "mean_abs_yaw_err_deg": 4.67,
            "per_maneuver": {
                "level": {"mean_err_deg": 7.14, "settled_mean_err_deg": null,
                          "mean_abs_yaw_err_deg": 2.0, "max_abs_yaw_err_deg": 6.5},
                "pitch": {"mean_err_deg": 3.96, "settled_mean_err_deg": 2.5,
                          "mean_abs_yaw_err_deg": 1.5, "max_abs_yaw_err_deg": 4.25},
            },
            "oscillation": {
                "roll_rate_rms_deg_s": 3.2, "sway_vel_rms_m_s": 0.01, "heave_vel_rms_m_s": 0.02,
                "high_passed_err_rms_deg": 0.4, "thrust_activity_per_s": 1.75,
            },
            "monitor_mismatch_at_s": null, "monitor_mismatch_reports": 0,
            "monitor_mismatch_lines": [], "model_refinements": 0,
            "model_swaps": [{"t_s": 45.3, "version": 2, "source": "Estimated"}],
            "status_changes": 9, "vehicle_samples_scored": 24000, "wall_s": 12.5,
            "pace": null, "clean_exit": true, "files_left": 0,
            "hot_swap": {
                "reestimation": null, "t_change_s": 40.0, "announced": false,
                "truth_changed_at_s": 40.0, "detection_delay_s": 0.35,
                "reestimation_start_delay_s": 0.31, "first_swap_delay_s": 5.3,
                "first_swap_source": "Estimated", "new_model_delay_s": 5.3,
                "new_model_version": 2, "new_model_rel_err_rot_vs_truth": 0.07,
                "recovery_threshold_deg": 13.18, "recovered_after_s": null,
                "worst_window_after_change_deg": 19.0,
                "before": part, "during": part, "after": part,
            },
            "noise": "realistic",
        })
    }

    /// Read back and written again, a run's scores are the JSON they came from: every field
    /// typed, `null` kept as not measured, the maneuvers not made and the other experiments'
    /// scores left out.
    #[test]
    fn a_runs_scores_read_back_write_the_same_json() {
        let v = hot_swap_run();
        let run: RunScores = serde_json::from_value(v.clone()).unwrap();
        assert!(run.settled_mean_err_deg.value().is_none());
        assert_eq!(
            run.per_maneuver
                .pitch("silent")
                .unwrap()
                .max_abs_yaw_err_deg
                .get(),
            4.25
        );
        assert!(run.per_maneuver.yaw("silent").is_err());
        let names: Vec<_> = run.per_maneuver.made().map(|(g, _)| g).collect();
        assert_eq!(names, ["level", "pitch"]);
        assert_eq!(serde_json::to_value(&run).unwrap(), v);
    }

    #[test]
    fn a_misnamed_score_is_refused() {
        let mut v = hot_swap_run();
        v["oscillation"]["roll_rate_rms_deg"] = json!(3.2);
        let e = serde_json::from_value::<RunScores>(v).unwrap_err();
        assert!(
            e.to_string().contains("unknown field `roll_rate_rms_deg`"),
            "{e}"
        );
    }

    /// As the JSON always held them: 4 decimals, and nothing measured where not finite.
    #[test]
    fn scores_round_to_four_decimals_and_not_finite_is_null() {
        assert_eq!(serde_json::to_string(&num(1.234_567)).unwrap(), "1.2346");
        assert_eq!(serde_json::to_string(&num(f64::NAN)).unwrap(), "null");
        assert_eq!(serde_json::to_string(&opt(None)).unwrap(), "null");
        assert_eq!(serde_json::to_string(&num(5.0)).unwrap(), "5.0");
    }
}
