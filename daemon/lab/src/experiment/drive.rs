//! Driving one run: daemon and simulator started on a private namespace ([`Session`]), the
//! model got (estimated, declared or the truth loaded), the plan's setpoints sent at vehicle
//! times, and every vehicle sample recorded against the setpoint in effect ([`RunOutput`]).

use super::*;

/// One vehicle sample scored against the setpoint in effect.
#[derive(Debug, Clone, Copy)]
pub(super) struct Row {
    /// Vehicle time, s.
    pub(super) t: f64,
    /// Setpoint and true roll, pitch, yaw (yaw relative to the start heading), degrees.
    pub(super) sp: [f64; 3],
    pub(super) tru: [f64; 3],
    /// Total angle between true attitude and setpoint, degrees.
    pub(super) err: f64,
    /// Heading error, degrees (signed).
    pub(super) yaw_err: f64,
    /// Tilt error (the body z axes' angle), degrees.
    pub(super) tilt_err: f64,
    /// Seconds since the current step began.
    pub(super) since_step: f64,
    pub(super) step: usize,
    pub(super) state: DaemonState,
    /// Body rates, deg/s; body velocity, m/s.
    pub(super) rate: [f64; 3],
    pub(super) vel: [f64; 3],
    /// The newest thrust command when the sample was scored: `nu` thrusters, -1..1.
    pub(super) u: [f64; MAX_THRUSTERS],
    pub(super) nu: usize,
}

#[derive(Debug, Clone)]
pub(super) struct Swap {
    pub(super) t: f64,
    pub(super) version: u64,
    pub(super) source: String,
}

/// Everything one run recorded.
pub(super) struct RunOutput {
    pub(super) spec: RunSpec,
    pub(super) wall_s: f64,
    pub(super) pace: Option<f64>,
    pub(super) estimation: Option<(f64, u32)>,
    pub(super) model: ModelMsg,
    pub(super) truth: TruthMsg,
    /// The truth the first model is scored against: at the voltage it describes.
    pub(super) model_truth: TruthMsg,
    pub(super) hold_start: f64,
    pub(super) rows: Vec<Row>,
    pub(super) swaps: Vec<Swap>,
    /// Models the continuous refinement updated (new versions of the model in force, not
    /// new models: they are not in `swaps`).
    pub(super) refinements: usize,
    /// The model in force published again with the same B and its bound restated (a curve
    /// named, the hold's gain: `curve_named`, `gain_gap`): not new models either. (Vehicle
    /// s when it came, its rotation bound.)
    pub(super) restated: Vec<(f64, f64)>,
    /// Status changes: (t, state, text).
    pub(super) notes: Vec<(f64, String, String)>,
    pub(super) mismatch_at: Option<f64>,
    /// Mismatch warnings in the daemon's log.
    pub(super) mismatch_reports: usize,
    /// The daemon's warning for each of them (what it found, on which thruster, which test).
    pub(super) mismatch_lines: Vec<String>,
    /// First estimation pulse after the scenario's change.
    pub(super) reestimate_at: Option<f64>,
    pub(super) truth_changes: Vec<f64>,
    /// (t, sum over thrusters of |du/dt|) from consecutive thrust commands, 1/s.
    pub(super) activity: Vec<(f64, f64)>,
    pub(super) final_model: ModelMsg,
    pub(super) final_truth: TruthMsg,
    pub(super) shutdown: Shutdown,
}

pub(super) fn quat(q: [f64; 4]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3]))
}

pub(super) fn secs(ns: u64) -> f64 {
    ns as f64 * 1e-9
}

pub(super) fn source_name(m: &ModelMsg) -> String {
    m.source()
        .map(|s| format!("{s:?}"))
        .unwrap_or_else(|_| "?".into())
}

/// A file removed when dropped.
pub(super) struct Scratch(PathBuf);

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// The vehicle file with its `[battery]` capacity and hotel load replaced, written beside the
/// other temporary files of this process for the run (`label`), removed when dropped.
pub(super) fn with_battery(
    vehicle: &Path,
    label: &str,
    capacity_ah: f64,
    hotel_a: f64,
) -> Result<Scratch> {
    let text = std::fs::read_to_string(vehicle)
        .with_context(|| format!("reading {}", vehicle.display()))?;
    let mut doc: toml::Table =
        toml::from_str(&text).with_context(|| format!("parsing {}", vehicle.display()))?;
    let Some(toml::Value::Table(battery)) = doc.get_mut("battery") else {
        bail!("{} has no [battery]", vehicle.display());
    };
    battery.insert("capacity_ah".into(), toml::Value::Float(capacity_ah));
    battery.insert("hotel_current_a".into(), toml::Value::Float(hotel_a));
    let path = std::env::temp_dir().join(format!(
        "thrusterctl-{}-{label}-{}",
        std::process::id(),
        vehicle
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or("vehicle.toml")
    ));
    std::fs::write(&path, toml::to_string(&doc)?)
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(Scratch(path))
}

pub(super) fn run_one(bins: &Binaries, args: &ExperimentArgs, spec: &RunSpec) -> Result<RunOutput> {
    let shipped = config_file(&format!("vehicles/{}.toml", spec.vehicle));
    let drained = spec
        .battery
        .map(|(capacity, hotel)| with_battery(&shipped, spec.label, capacity, hotel))
        .transpose()?;
    let vehicle = drained
        .as_ref()
        .map_or_else(|| shipped.clone(), |s| s.0.clone());
    let session_spec = SessionSpec {
        tag: "exp",
        vehicle: vehicle.clone(),
        noise: spec.noise.into(),
        seed: args.seed,
        realtime: false,
        pace: match (&args.record, args.pace > 0.0) {
            (Some(_), true) => Some(args.pace.min(RECORD_PACE)),
            (Some(_), false) => Some(RECORD_PACE),
            (None, true) => Some(args.pace),
            (None, false) => None,
        },
        daemon_config: DaemonConfig::Text(daemon_config(spec, bins, &vehicle)?),
        scenario: spec.change.map(|(t, a)| scenario(t, a, spec.action)),
        sim_config: args.water.sim_config()?,
        record: args
            .record
            .as_deref()
            .map(|out| thrusterctl_operator::record::options(run_path(out, spec.label), None, None))
            .transpose()?,
    };
    let wall = Instant::now();
    let mut session = Session::start(bins, &session_spec)?;
    // Generated, so it parses; were it not, the daemon says why and the session is cleaned up.
    let supply = session_spec.daemon_config.supply().unwrap_or_default();
    let result = drive(&mut session, spec, &vehicle, &supply);
    let recorded = session.stop_recording();
    let pace = session.pace;
    let shutdown = session.finish();
    let mut out = result.with_context(|| format!("run {:?}", spec.label))?;
    if let Some(recorded) = recorded {
        let recorded = recorded.with_context(|| format!("recording run {:?}", spec.label))?;
        // On stderr: `--json` keeps stdout one JSON object.
        eprintln!("{}: {}", spec.label, recorded.line());
    }
    out.shutdown = shutdown;
    out.wall_s = wall.elapsed().as_secs_f64();
    out.pace = pace;
    if !shutdown.clean || shutdown.leftovers > 0 {
        bail!(
            "run {}: shutdown was not clean (exit ok: {}, files left: {})",
            spec.label,
            shutdown.clean,
            shutdown.leftovers
        );
    }
    Ok(out)
}

/// A daemon log line without its wall-clock stamp (the first word).
pub(super) fn without_stamp(line: &str) -> String {
    line.split_once(' ')
        .map_or(line, |(_, rest)| rest)
        .trim()
        .to_string()
}

/// Hand the daemon the simulator's true model through a model file and `load`, the way an
/// operator loads one: it passes the same checks as any other model.
pub(super) fn load_truth(session: &mut Session, truth: &TruthMsg) -> Result<()> {
    let n = truth.thruster_count();
    let b = nalgebra::DMatrix::from_fn(6, n, |j, i| truth.symmetric(j, i));
    let model = thrusterd_core::model::Model::nominal(b, None);
    let file = session.scratch_path("oracle-model.json");
    std::fs::write(&file, thrusterd_core::model_file::to_json(&model))
        .with_context(|| format!("writing {}", file.display()))?;
    let request = thrusterctl_operator::cli::path_request(RequestKind::Load, &file)?;
    let r = session.request(request)?;
    if !r.is_ok() {
        bail!("the daemon refused the true model: {}", r.text());
    }
    Ok(())
}

pub(super) fn drive(
    session: &mut Session,
    spec: &RunSpec,
    vehicle: &Path,
    supply: &thrusterd_core::supply::SupplyConfig,
) -> Result<RunOutput> {
    let (first, truth) = session.ready()?;
    // The truth at the voltage a model describes (`model_truth`): the daemon's reference
    // when a battery's reading is referred or the commands linearized. What the first model
    // is scored against, and what an oracle start loads. The truth at ready serves as the
    // published one (the inbox's later ones are the run's).
    let model_truth = crate::model_truth::truth_for_model(vehicle, supply, &truth)?;
    let estimation = match spec.start {
        Start::Estimate => {
            let done = session.estimate(Duration::from_secs(180), &mut |_| {})?;
            Some((
                secs(done.vehicle_time_ns.saturating_sub(first.vehicle_time_ns)),
                done.pulse,
            ))
        }
        Start::Manual => {
            // The declared geometry's nominal model is in from the start.
            session.wait_status("the nominal model", Duration::from_secs(30), &mut |s| {
                s.model_version >= 1
            })?;
            session.command(RequestKind::Hold)?;
            None
        }
        Start::Oracle => {
            load_truth(session, &model_truth)?;
            session.wait_status("the true model", Duration::from_secs(30), &mut |s| {
                s.model_version >= 1
            })?;
            session.command(RequestKind::Hold)?;
            None
        }
    };
    let model = session.model()?;
    let mut last_version = model.version;
    let start = session.vehicle_state()?;
    let hold_start = secs(start.t_ns);
    if let Some((t_c, _)) = spec.change {
        if hold_start > t_c - 5.0 {
            bail!(
                "the first estimation ended at {hold_start:.1} s, too close to the change at \
                 {t_c:.1} s (use a later --t-change)"
            );
        }
    }
    let heading = quat(start.attitude).euler_angles().2;
    let depth = start.position_ned[2];
    let mut plan = spec.plan.clone();
    // A repeating plan runs until an absolute vehicle time: make it relative to the hold.
    plan.repeat_until_s = plan.repeat_until_s.map(|t| t - hold_start);
    let end = hold_start + plan.duration_s();

    let mut rows = Vec::new();
    let mut swaps = Vec::new();
    let mut refinements = 0;
    let mut restated = Vec::new();
    let mut last_b = model.effectiveness;
    // Vehicle time of the last status read: a restated model keeps the time it was made.
    let mut now = hold_start;
    let mut loaded_truth: Option<TruthMsg> = None;
    let mut notes: Vec<(f64, String, String)> = Vec::new();
    let mut mismatch_at = None;
    let mut reestimate_at = None;
    let mut truth_changes = Vec::new();
    let mut activity = Vec::new();
    let mut last_truth = truth.effectiveness;
    let mut final_truth = truth;
    let mut final_model = model;
    let mut state = DaemonState::Active;
    let mut text = String::new();
    let mut prev_cmd: Option<thruster_protocol::ThrustCommand> = None;
    let mut step: Option<usize> = None;
    let mut target = UnitQuaternion::identity();
    let mut sp_deg = [0.0; 3];
    let (mut step_t, mut last_send) = (hold_start, f64::NEG_INFINITY);
    let mut resend = false;
    let mut batch: Vec<VehicleStateMsg> = Vec::with_capacity(32);
    let change_t = spec.change.map(|c| c.0);
    let wall_limit = Duration::from_secs(120) + Duration::from_secs_f64(plan.duration_s() * 2.0);
    let wall = Instant::now();
    'run: loop {
        let mut got = false;
        while let Some(st) = session.status_inbox().recv()? {
            let t = secs(st.vehicle_time_ns);
            now = t;
            let s = st.state().unwrap_or(DaemonState::Fault);
            if s != state || st.text() != text {
                notes.push((t, s.name().to_string(), st.text().to_string()));
            }
            if st.text().contains("mismatch") && mismatch_at.is_none() {
                mismatch_at = Some(t);
            }
            // Back in control after a (re-)estimation: the daemon holds level until told
            // otherwise, so the maneuver's setpoint goes again at once.
            if s == DaemonState::Active && state != DaemonState::Active {
                resend = true;
            }
            state = s;
            text = st.text().to_string();
        }
        while let Some(m) = session.model_inbox().recv()? {
            if m.version > last_version && m.refinements > 0 {
                last_version = m.version;
                refinements += 1;
            } else if m.version > last_version && m.effectiveness == last_b {
                last_version = m.version;
                restated.push((now, m.rel_err_rot));
            } else if m.version > last_version {
                last_version = m.version;
                swaps.push(Swap {
                    t: secs(m.t_ns),
                    version: m.version,
                    source: source_name(&m),
                });
            }
            last_b = m.effectiveness;
            final_model = m;
        }
        while let Some(tr) = session.truth_inbox().recv()? {
            if tr.effectiveness != last_truth {
                last_truth = tr.effectiveness;
                truth_changes.push(secs(tr.t_ns));
                // The oracle run: the daemon gets the new true model at once (a perfect and
                // instant re-estimation), the reference for what re-learning can reach.
                // A gradual change (degrade: a step every 0.1 s) is loaded once it has moved
                // the truth by 2 % since the last load, not at every step.
                let moved = loaded_truth
                    .as_ref()
                    .map_or(f64::INFINITY, |l| degrade::truth_moved(l, &tr));
                if spec.start == Start::Oracle && moved > 0.02 {
                    load_truth(session, &tr)?;
                    loaded_truth = Some(tr);
                }
            }
            final_truth = tr;
        }
        while let Some(c) = session.thrust_inbox().recv()? {
            let t = secs(c.t_ns);
            if let Some(p) = prev_cmd.filter(|p| c.seq == p.seq + 1 && c.t_ns > p.t_ns) {
                let dt = secs(c.t_ns - p.t_ns);
                let du: f64 = c
                    .thrusters()
                    .iter()
                    .zip(p.thrusters())
                    .map(|(a, b)| (a - b).abs())
                    .sum();
                activity.push((t, du / dt));
            }
            if reestimate_at.is_none()
                && change_t.is_some_and(|tc| t >= tc)
                && c.mode() == Ok(ThrustMode::Estimating)
            {
                reestimate_at = Some(t);
            }
            prev_cmd = Some(c);
        }
        batch.clear();
        while let Some(v) = session.vehicle_inbox().recv()? {
            batch.push(v);
        }
        for v in &batch {
            got = true;
            if step.is_none() {
                break;
            }
            let t = secs(v.t_ns);
            let q = quat(v.attitude);
            let mut tru = euler_deg(&q);
            tru[2] = wrap_deg(tru[2] - heading.to_degrees());
            rows.push(Row {
                t,
                sp: sp_deg,
                tru,
                err: angle_error_deg(&q, &target),
                yaw_err: yaw_error_deg(&q, &target),
                tilt_err: tilt_error_deg(&q, &target),
                since_step: t - step_t,
                step: step.unwrap_or(0),
                state,
                rate: v.rate.map(f64::to_degrees),
                vel: v.velocity,
                u: prev_cmd.map_or([0.0; MAX_THRUSTERS], |c| {
                    let mut u = [0.0; MAX_THRUSTERS];
                    u[..c.thrusters().len()].copy_from_slice(c.thrusters());
                    u
                }),
                nu: prev_cmd.map_or(0, |c| c.thrusters().len()),
            });
        }
        // Setpoints are decided on the newest sample, the vehicle time they are scored from.
        let now = batch
            .last()
            .map(|v| secs(v.t_ns))
            .unwrap_or(if step.is_none() { hold_start } else { f64::NAN });
        if now.is_finite() {
            let due = plan.step_at(now - hold_start);
            match due {
                None if step.is_some() || now >= end => break 'run,
                None => {}
                Some(i) if Some(i) != step => {
                    let s = &plan.steps[i];
                    target = s.attitude(heading);
                    sp_deg = [s.roll_deg, s.pitch_deg, s.yaw_deg];
                    session.send_setpoint(&target, Some(depth))?;
                    step = Some(i);
                    step_t = now;
                    last_send = now;
                }
                // Resent every second too: a lost message or a daemon that restarted
                // control never holds the wrong attitude for long.
                Some(_) if resend || now - last_send >= 1.0 => {
                    session.send_setpoint(&target, Some(depth))?;
                    last_send = now;
                    resend = false;
                }
                Some(_) => {}
            }
        }
        if !got {
            session.check_alive("the maneuver")?;
            if wall.elapsed() > wall_limit {
                return Err(session.timeout_error("the end of the maneuver"));
            }
            session.tick()?;
        }
    }
    // The monitor's findings also go to the daemon's log, one warning each: counted there,
    // since a status message can be overtaken at 50x real time.
    let mismatch_lines: Vec<String> = session
        .daemon_log()
        .lines()
        .filter(|l| l.contains("WARN") && l.contains("model mismatch"))
        // Without the log's wall-clock stamp: the JSON holds what happened in vehicle time,
        // the same in every run of a seed.
        .map(without_stamp)
        .collect();
    let mismatch_reports = mismatch_lines.len();
    if mismatch_at.is_none() {
        if let Some(line) = session
            .daemon_log()
            .lines()
            .find(|l| l.contains("mismatch"))
        {
            notes.push((f64::NAN, "log".into(), without_stamp(line)));
        }
    }
    Ok(RunOutput {
        spec: spec.clone(),
        wall_s: 0.0,
        pace: None,
        estimation,
        model,
        truth,
        model_truth,
        hold_start,
        rows,
        swaps,
        refinements,
        restated,
        notes,
        mismatch_at,
        mismatch_reports,
        mismatch_lines,
        reestimate_at,
        truth_changes,
        activity,
        final_model,
        final_truth,
        shutdown: Shutdown {
            clean: false,
            leftovers: 0,
        },
    })
}
