//! Command line: clap definitions and the range checks clap cannot express.
//!
//! Every check here runs before any IPC, so a typo never reaches the vehicle and the
//! operator gets the reason at once (exit code [`exit::USAGE`]).

use std::path::{Path, PathBuf};
use std::time::Duration;

use clap::{Args, Subcommand, ValueEnum};
use thruster_protocol::services::DEFAULT_ROOT_BASE;
use thruster_protocol::validate::limits::{MAX_DEPTH_M, MIN_DEPTH_M};
use thruster_protocol::{ControlRequest, ReconfigKind, RequestKind, MAX_THRUSTERS};

use crate::exit::Failure;

/// Namespace thrusterd uses unless told otherwise.
pub const DEFAULT_NAMESPACE: &str = "thrusterd";

/// Longest accepted `--timeout-ms`: longer waits belong to `estimate --max-wait-s`.
const MAX_TIMEOUT_MS: u64 = 600_000;

// The options every verb takes (`global`: they go anywhere on the command line). A plain
// comment: a doc comment here would become the help text of the command that flattens it.
#[derive(Args, Debug)]
pub struct Globals {
    /// Namespace of the vehicle's thrusterd (the daemon's --namespace).
    #[arg(long, global = true, default_value = DEFAULT_NAMESPACE)]
    pub namespace: String,

    /// How long to wait for the daemon's answer and for its published status or model, ms.
    #[arg(long, global = true, default_value_t = 2000)]
    pub timeout_ms: u64,

    /// Base folder of iceoryx2's files (the daemon's `[ipc] root`, the simulator's
    /// `ipc_root`); every process of a namespace must use the same one.
    #[arg(long, global = true, default_value = DEFAULT_ROOT_BASE)]
    pub ipc_root: PathBuf,
}

/// The operator's verbs (the thrusterctl binary adds the lab's `demo` and `experiment`).
#[derive(Subcommand, Debug)]
pub enum Command {
    /// Show the daemon's state, progress and health.
    Status {
        /// One JSON object instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Start (re-)estimating the thruster model.
    Estimate {
        /// Follow progress until the estimate is done (exit code != 0 if it fails).
        #[arg(long)]
        wait: bool,
        /// Excitation power, normalised command in (0, 1]; the daemon's default if omitted.
        #[arg(long)]
        power: Option<f64>,
        /// With --wait: give up waiting after this many seconds (estimation continues).
        #[arg(long, default_value_t = 600.0)]
        max_wait_s: f64,
    },
    /// Abort the estimation that runs: back to Idle, thrusters neutral (an identification
    /// under control goes back to holding with the model in force; a confirmation waiting for
    /// the hold is cancelled, the model in force kept). Refused when none runs.
    Abort,
    /// Control the vehicle with the current model (hold the setpoint).
    Hold,
    /// Stop controlling: zero thrust.
    Idle,
    /// Emergency stop: thrusters neutral now in any state, and nothing starts them again (no
    /// automatic re-estimation, no resumed hold) until `estimate` or `hold`.
    Stop,
    /// Save the current model (to the daemon's default location if PATH is omitted).
    Save {
        /// File to write, on the daemon's machine; relative paths are made absolute here.
        path: Option<PathBuf>,
    },
    /// Go back to the previous model.
    Revert,
    /// Load a model from a file.
    Load {
        /// File to read, on the daemon's machine; relative paths are made absolute here.
        path: PathBuf,
    },
    /// Stop the daemon cleanly.
    Shutdown,
    /// Show the model in use: matrices, actuated DOFs, confidence, contribution chart.
    Model {
        /// One JSON object instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Print status lines as they change and the daemon's telemetry live, until Ctrl-C: on a
    /// terminal a small dashboard redrawn in place, otherwise plain lines.
    Watch {
        /// One JSON object per line instead of text (telemetry as {"telemetry": {...}}).
        #[arg(long)]
        json: bool,
        /// Show telemetry at most every this many ms (default 100 on a terminal, 1000
        /// otherwise; 0: every message the daemon publishes, as far as this reader keeps up).
        #[arg(long)]
        interval_ms: Option<u64>,
    },
    /// Record every topic of the namespace to MCAP (JSON + JSON Schema per channel, for
    /// Foxglove) until Ctrl-C/SIGTERM or --duration-s; a subscriber only, it never slows the
    /// daemon. Prints the message counts and sequence-gap losses at the end.
    Record {
        /// The MCAP file to write (rotated files: FILE-0001.mcap, FILE-0002.mcap, ...).
        #[arg(long)]
        out: PathBuf,
        /// Start a new file once one holds this many MiB (default: one file).
        #[arg(long)]
        max_mb: Option<f64>,
        /// Stop after this many seconds (wall clock; default: until Ctrl-C or SIGTERM).
        #[arg(long)]
        duration_s: Option<f64>,
        /// Chunk compression: zstd (about 0.36 of the size, what Foxglove's writers use) or
        /// none.
        #[arg(long, default_value = "zstd", value_parser = ["zstd", "none"])]
        compression: String,
    },
    /// Announce a change of the thruster configuration (starts re-estimation).
    Reconfigure {
        /// What changed.
        #[arg(long, value_enum)]
        kind: KindArg,
        /// Index of the thruster concerned (0-based); not needed for --kind unknown.
        #[arg(long)]
        thruster: Option<u32>,
        /// Thruster count after the change.
        #[arg(long)]
        count: u32,
        /// Vehicle file (config/vehicles format) declaring the new geometry of all thrusters.
        #[arg(long)]
        geometry: Option<PathBuf>,
    },
    /// Set the attitude (and optionally depth) to hold.
    Setpoint {
        /// Roll, degrees, in [-180, 180]; left out: the roll held now is kept.
        #[arg(long, allow_negative_numbers = true)]
        roll: Option<f64>,
        /// Pitch, degrees, in [-90, 90]; left out: the pitch held now is kept.
        #[arg(long, allow_negative_numbers = true)]
        pitch: Option<f64>,
        /// Yaw (heading from north), degrees, in [-360, 360]; left out: the heading held
        /// now is kept.
        #[arg(long, allow_negative_numbers = true)]
        yaw: Option<f64>,
        /// Depth to hold, m, positive down, or `free` to release the depth hold (heave
        /// free); left out: the depth held now is kept.
        #[arg(long, allow_negative_numbers = true, value_parser = parse_depth, value_name = "M|free")]
        depth: Option<Depth>,
    },
}

/// `--kind` values of `reconfigure`.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum KindArg {
    Added,
    Removed,
    Moved,
    Unknown,
}

impl KindArg {
    pub fn wire(self) -> ReconfigKind {
        match self {
            KindArg::Added => ReconfigKind::ThrusterAdded,
            KindArg::Removed => ReconfigKind::ThrusterRemoved,
            KindArg::Moved => ReconfigKind::ThrusterMoved,
            KindArg::Unknown => ReconfigKind::Unknown,
        }
    }
}

/// `--timeout-ms` as a duration: at least 1 ms (0 would make every call time out before
/// the daemon could answer) and at most [`MAX_TIMEOUT_MS`].
pub fn timeout(ms: u64) -> Result<Duration, Failure> {
    if !(1..=MAX_TIMEOUT_MS).contains(&ms) {
        return Err(Failure::usage(format!(
            "--timeout-ms must be in 1..={MAX_TIMEOUT_MS}, got {ms}"
        )));
    }
    Ok(Duration::from_millis(ms))
}

/// `--max-wait-s` as a duration: finite and positive.
pub fn max_wait(seconds: f64) -> Result<Duration, Failure> {
    if !(seconds.is_finite() && seconds > 0.0 && seconds <= 86_400.0) {
        return Err(Failure::usage(format!(
            "--max-wait-s must be in (0, 86400], got {seconds}"
        )));
    }
    Ok(Duration::from_secs_f64(seconds))
}

/// The Estimate request's `value`: 0 asks for the daemon's default power.
pub fn estimate_power(power: Option<f64>) -> Result<f64, Failure> {
    match power {
        None => Ok(0.0),
        Some(p) if p.is_finite() && p > 0.0 && p <= 1.0 => Ok(p),
        Some(p) => Err(Failure::usage(format!(
            "--power must be in (0, 1] (a normalised thruster command), got {p}"
        ))),
    }
}

/// A request carrying a file path. The daemon runs elsewhere (as a service, with its own
/// working directory), so relative paths are resolved here; a path that does not fit the
/// request's text field is refused rather than silently truncated to another file.
pub fn path_request(kind: RequestKind, path: &Path) -> Result<ControlRequest, Failure> {
    let absolute = std::path::absolute(path)
        .map_err(|e| Failure::usage(format!("cannot resolve {}: {e}", path.display())))?;
    let text = absolute
        .to_str()
        .ok_or_else(|| Failure::usage(format!("{} is not valid UTF-8", absolute.display())))?;
    let request = ControlRequest::with_text(kind, text);
    if request.text.as_str() != text {
        return Err(Failure::usage(format!(
            "path {text:?} is too long for the protocol ({} bytes at most) or contains NUL",
            request.text.as_bytes().len()
        )));
    }
    Ok(request)
}

/// Checked arguments of `reconfigure`, without the geometry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReconfigArgs {
    pub kind: ReconfigKind,
    pub thruster: u32,
    pub count: u32,
}

/// Checks `reconfigure`'s numbers the way the daemon will (see the protocol's
/// `ReconfigEvent` validation), but with messages that name the option.
pub fn reconfig_args(
    kind: KindArg,
    thruster: Option<u32>,
    count: u32,
) -> Result<ReconfigArgs, Failure> {
    let max = MAX_THRUSTERS as u32;
    if !(1..=max).contains(&count) {
        return Err(Failure::usage(format!(
            "--count must be in 1..={max}, got {count}"
        )));
    }
    let thruster = match (kind, thruster) {
        (KindArg::Unknown, t) => t.unwrap_or(0),
        (_, None) => {
            return Err(Failure::usage(format!(
                "--thruster is required with --kind {}",
                kind.to_possible_value()
                    .map_or_else(|| "?".to_string(), |v| v.get_name().to_string())
            )))
        }
        (_, Some(t)) => t,
    };
    if thruster >= max {
        return Err(Failure::usage(format!(
            "--thruster must be below {max}, got {thruster}"
        )));
    }
    match kind {
        // The added or moved thruster is one of the `count` thrusters after the change.
        KindArg::Added | KindArg::Moved if thruster >= count => {
            return Err(Failure::usage(format!(
                "--thruster {thruster} is not among the {count} thrusters after the change"
            )))
        }
        // The removed one is no longer counted: it was at most index `count`.
        KindArg::Removed if thruster > count => {
            return Err(Failure::usage(format!(
                "--thruster {thruster} cannot have been removed: there were only {} thrusters",
                count + 1
            )))
        }
        _ => {}
    }
    Ok(ReconfigArgs {
        kind: kind.wire(),
        thruster,
        count,
    })
}

/// What a setpoint does with depth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Depth {
    /// Keep the depth held now (free if none is held): what leaving `--depth` out means, as
    /// for the angles. Releasing depth is never implied (issue 27: an attitude command once
    /// let a held vehicle rise 7 m).
    Keep,
    /// `--depth free`: release the depth hold, heave free.
    Free,
    /// `--depth M`: hold M metres, positive down.
    Hold(f64),
}

/// `--depth`'s value: `free` or a number of metres (checked later, with the other ranges).
pub fn parse_depth(text: &str) -> Result<Depth, String> {
    if text.eq_ignore_ascii_case("free") {
        return Ok(Depth::Free);
    }
    text.parse::<f64>()
        .map(Depth::Hold)
        .map_err(|_| format!("expected metres (a number) or `free`, got {text:?}"))
}

/// Checked `setpoint` arguments, degrees and metres.
#[derive(Debug, Clone, Copy, PartialEq)]
/// Angles in degrees; `None`: keep the value the daemon holds now.
pub struct SetpointArgs {
    pub roll_deg: Option<f64>,
    pub pitch_deg: Option<f64>,
    pub yaw_deg: Option<f64>,
    pub depth: Depth,
}

pub fn setpoint_args(
    roll: Option<f64>,
    pitch: Option<f64>,
    yaw: Option<f64>,
    depth: Option<Depth>,
) -> Result<SetpointArgs, Failure> {
    if roll.is_none() && pitch.is_none() && yaw.is_none() && depth.is_none() {
        return Err(Failure::usage(
            "setpoint needs at least one of --roll, --pitch, --yaw, --depth (the others keep \
             their current value)",
        ));
    }
    // Pitch beyond +-90 or roll beyond +-180 only restate an attitude another triple
    // describes; such a value is more likely a typo than intended, so refuse it.
    for (name, value, limit) in [
        ("--roll", roll, 180.0),
        ("--pitch", pitch, 90.0),
        ("--yaw", yaw, 360.0),
    ] {
        if let Some(v) = value {
            check_range(name, v, -limit, limit, "degrees")?;
        }
    }
    if let Some(Depth::Hold(d)) = depth {
        check_range("--depth", d, MIN_DEPTH_M, MAX_DEPTH_M, "m")?;
    }
    Ok(SetpointArgs {
        roll_deg: roll,
        pitch_deg: pitch,
        yaw_deg: yaw,
        depth: depth.unwrap_or(Depth::Keep),
    })
}

fn check_range(name: &str, value: f64, min: f64, max: f64, unit: &str) -> Result<(), Failure> {
    if !value.is_finite() {
        return Err(Failure::usage(format!(
            "{name} must be a finite number, got {value}"
        )));
    }
    if !(min..=max).contains(&value) {
        return Err(Failure::usage(format!(
            "{name} must be in [{min}, {max}] {unit}, got {value}"
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::exit;
    use clap::Parser;

    /// The operator's part of thrusterctl's command line (the binary adds the lab's verbs).
    #[derive(Parser, Debug)]
    #[command(name = "thrusterctl")]
    struct Cli {
        #[command(flatten)]
        globals: Globals,
        #[command(subcommand)]
        command: Command,
    }

    fn parse(args: &[&str]) -> Result<Cli, clap::Error> {
        Cli::try_parse_from(std::iter::once("thrusterctl").chain(args.iter().copied()))
    }

    #[test]
    fn globals_default_and_go_anywhere() {
        let cli = parse(&["status"]).unwrap();
        assert_eq!(cli.globals.namespace, "thrusterd");
        assert_eq!(cli.globals.timeout_ms, 2000);
        assert_eq!(cli.globals.ipc_root, Path::new(DEFAULT_ROOT_BASE));
        let cli = parse(&["status", "--namespace", "veh1", "--timeout-ms", "50"]).unwrap();
        assert_eq!(cli.globals.namespace, "veh1");
        assert_eq!(cli.globals.timeout_ms, 50);
    }

    #[test]
    fn negative_angles_parse_as_values() {
        let cli = parse(&[
            "setpoint", "--roll", "-10", "--pitch", "-5.5", "--yaw", "-90", "--depth", "2",
        ])
        .unwrap();
        match cli.command {
            Command::Setpoint {
                roll,
                pitch,
                yaw,
                depth,
            } => {
                assert_eq!(
                    (roll, pitch, yaw, depth),
                    (Some(-10.0), Some(-5.5), Some(-90.0), Some(Depth::Hold(2.0)))
                );
            }
            other => panic!("parsed as {other:?}"),
        }
    }

    #[test]
    fn depth_free_parses_and_a_word_is_refused() {
        let cli = parse(&["setpoint", "--pitch", "10", "--depth", "free"]).unwrap();
        match cli.command {
            Command::Setpoint { depth, .. } => assert_eq!(depth, Some(Depth::Free)),
            other => panic!("parsed as {other:?}"),
        }
        let cli = parse(&["setpoint", "--pitch", "10"]).unwrap();
        match cli.command {
            Command::Setpoint { depth, .. } => assert_eq!(depth, None),
            other => panic!("parsed as {other:?}"),
        }
        assert!(parse(&["setpoint", "--depth", "deep"]).is_err());
    }

    #[test]
    fn reconfigure_kind_values() {
        let cli = parse(&[
            "reconfigure",
            "--kind",
            "moved",
            "--thruster",
            "0",
            "--count",
            "5",
        ])
        .unwrap();
        assert!(matches!(
            cli.command,
            Command::Reconfigure {
                kind: KindArg::Moved,
                thruster: Some(0),
                count: 5,
                geometry: None
            }
        ));
        assert!(parse(&["reconfigure", "--kind", "rotated", "--count", "5"]).is_err());
    }

    #[test]
    fn timeout_bounds() {
        assert!(timeout(0).is_err());
        assert_eq!(timeout(1).unwrap(), Duration::from_millis(1));
        assert!(timeout(MAX_TIMEOUT_MS + 1).is_err());
        assert!(max_wait(f64::NAN).is_err());
        assert!(max_wait(0.0).is_err());
        assert_eq!(max_wait(1.5).unwrap(), Duration::from_millis(1500));
    }

    #[test]
    fn power_is_optional_and_bounded() {
        assert_eq!(estimate_power(None).unwrap(), 0.0);
        assert_eq!(estimate_power(Some(0.4)).unwrap(), 0.4);
        assert_eq!(estimate_power(Some(1.0)).unwrap(), 1.0);
        for bad in [0.0, -0.1, 1.01, f64::NAN, f64::INFINITY] {
            let e = estimate_power(Some(bad)).unwrap_err();
            assert_eq!(e.code, exit::USAGE, "{bad}");
            assert!(e.to_string().contains("--power"));
        }
    }

    #[test]
    fn reconfigure_checks_indices_against_count() {
        let ok = reconfig_args(KindArg::Added, Some(4), 5).unwrap();
        assert_eq!(ok.kind, ReconfigKind::ThrusterAdded);
        assert_eq!((ok.thruster, ok.count), (4, 5));
        assert!(reconfig_args(KindArg::Added, Some(5), 5).is_err());
        assert!(reconfig_args(KindArg::Moved, Some(5), 5).is_err());
        // Removing the last of 6 leaves 5: index 5 is fine, 6 is not.
        assert!(reconfig_args(KindArg::Removed, Some(5), 5).is_ok());
        assert!(reconfig_args(KindArg::Removed, Some(6), 5).is_err());
        assert!(reconfig_args(KindArg::Removed, Some(16), 16).is_err());
        // Unknown needs no thruster.
        assert_eq!(
            reconfig_args(KindArg::Unknown, None, 3).unwrap().thruster,
            0
        );
        let e = reconfig_args(KindArg::Moved, None, 3).unwrap_err();
        assert!(
            e.to_string()
                .contains("--thruster is required with --kind moved"),
            "{e}"
        );
        for count in [0, 17] {
            let e = reconfig_args(KindArg::Unknown, None, count).unwrap_err();
            assert!(e.to_string().contains("--count"), "{e}");
        }
    }

    #[test]
    fn setpoint_ranges() {
        let ok =
            setpoint_args(Some(10.0), Some(-20.0), Some(350.0), Some(Depth::Hold(1.5))).unwrap();
        assert_eq!(ok.depth, Depth::Hold(1.5));
        // One angle alone is enough (the README's `setpoint --pitch 10`), and it keeps depth.
        let pitch_only = setpoint_args(None, Some(10.0), None, None).unwrap();
        assert_eq!(pitch_only.depth, Depth::Keep);
        let free = setpoint_args(None, None, None, Some(Depth::Free)).unwrap();
        assert_eq!(free.depth, Depth::Free);
        assert_eq!(
            (
                pitch_only.roll_deg,
                pitch_only.pitch_deg,
                pitch_only.yaw_deg
            ),
            (None, Some(10.0), None)
        );
        let z = Some(0.0);
        let cases = [
            (Some(f64::NAN), z, z, None, "--roll must be a finite number"),
            (z, Some(91.0), z, None, "--pitch must be in [-90, 90]"),
            (Some(181.0), z, z, None, "--roll must be in [-180, 180]"),
            (z, z, Some(f64::INFINITY), None, "--yaw must be a finite"),
            (
                z,
                z,
                z,
                Some(Depth::Hold(f64::NAN)),
                "--depth must be a finite",
            ),
            (z, z, z, Some(Depth::Hold(-20.0)), "--depth must be in"),
            (None, None, None, None, "needs at least one of"),
        ];
        for (r, p, y, d, want) in cases {
            let e = setpoint_args(r, p, y, d).unwrap_err();
            assert_eq!(e.code, exit::USAGE);
            assert!(e.to_string().contains(want), "{e} vs {want}");
        }
    }

    #[test]
    fn paths_become_absolute_and_must_fit() {
        let req = path_request(RequestKind::Save, Path::new("model.toml")).unwrap();
        assert_eq!(req.kind().unwrap(), RequestKind::Save);
        let text = req.text.as_str();
        assert!(Path::new(text).is_absolute(), "{text}");
        assert!(text.ends_with("/model.toml"));
        let long = format!("/{}", "a".repeat(200));
        let e = path_request(RequestKind::Load, Path::new(&long)).unwrap_err();
        assert!(e.to_string().contains("too long"), "{e}");
    }
}
