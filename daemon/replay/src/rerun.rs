//! The recorded session run through the daemon's own state machine: the IMU samples the
//! daemon accepted (the same validator decides), and every journal entry after the sample
//! it followed in the daemon. Pure: no clock, no IPC; the machine's time is the samples'.

use thruster_protocol::validate::ImuSampleValidator;
use thruster_protocol::{ImuSample, InputKind, InputMsg, ModelMsg, RequestKind, ThrustCommand};
use thrusterd_core::checkpoint_parts::Place;
use thrusterd_core::config::DaemonConfig;
use thrusterd_core::machine::{Event, Machine, Request, SolveResult, SolverMode, State};
use thrusterd_core::wire;

/// Why the recording does not hold the session the journal describes.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RerunError {
    #[error("input journal entry {seq} followed the daemon's IMU sample seq {daemon_seq} (its {imu_count}-th accepted), but the recording's {imu_count}-th accepted sample has seq {replay_seq}: the recording lost IMU samples or did not start with the daemon")]
    Misplaced {
        seq: u64,
        imu_count: u64,
        daemon_seq: u64,
        replay_seq: u64,
    },
    #[error("the daemon answered IMU sample seq {0}, which the recording does not hold (lost by the recorder)")]
    LostImu(u64),
    #[error("the recording lost the daemon's thrust commands {from}..{to}: which IMU samples the daemon received there is unknown")]
    LostThrust { from: u64, to: u64 },
    #[error("the configuration drives {config} thrusters, the recorded daemon drove {recorded} (thrust channel): give the count the daemon ran with (--thrusters)")]
    ThrusterCount { config: usize, recorded: usize },
}

/// What the machine did with the recorded inputs.
#[derive(Debug, Clone)]
pub struct Outcome {
    /// Every model swapped in, as the daemon would have published it (`ModelMsg`, with the
    /// daemon's sequence numbering).
    pub models: Vec<ModelMsg>,
    /// IMU samples in the recording; those the daemon never received (no answer: published
    /// before it subscribed, or dropped on the way), not fed; accepted by the validator, and
    /// rejected.
    pub imu_recorded: usize,
    pub imu_not_received: u64,
    pub imu_accepted: u64,
    pub imu_rejected: u64,
    /// Journal entries applied, and those after the recording's last IMU sample (not
    /// applied: nothing followed them).
    pub inputs_applied: usize,
    pub inputs_after_end: usize,
    /// Entries the daemon and the replay answered differently (refused / took): empty when
    /// the replay follows the daemon.
    pub divergences: Vec<String>,
    /// The machine's state and status text at the end.
    pub final_state: State,
    pub final_text: String,
    /// Vehicle seconds from the first to the last sample.
    pub vehicle_s: f64,
    /// Accepted samples whose replayed command was compared with the daemon's recorded one.
    pub commands_compared: u64,
    /// The first accepted sample the replay answered with another command than the daemon
    /// did, when one did. From there on the recorded samples show the vehicle answering the
    /// daemon's commands, not the replay's: what the machine learns after it is not what
    /// its settings would have learned in the water.
    pub diverged_at: Option<Divergence>,
    /// Per model in `models`: made before the commands diverged (what these settings would
    /// have learned), or after (not an answer).
    pub models_valid: Vec<bool>,
    /// From a checkpoint: recorded samples before it (not fed to the machine).
    pub imu_before_checkpoint: u64,
}

/// Where the replayed commands first left the recorded ones.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Divergence {
    /// The accepted sample's number (1 = the first), seq and vehicle time since the first.
    pub imu_count: u64,
    pub imu_seq: u64,
    pub t_s: f64,
}

/// Checks that the recording holds every thrust command the daemon sent (their `seq` counts
/// up by one) and every IMU sample it answered (thrust's `imu_seq`): then the samples it
/// received are exactly the answered ones, and the stream fed below is the daemon's.
pub fn check_complete(imu: &[ImuSample], thrust: &[ThrustCommand]) -> Result<(), RerunError> {
    if let Some(w) = thrust.windows(2).find(|w| w[1].seq != w[0].seq + 1) {
        return Err(RerunError::LostThrust {
            from: w[0].seq + 1,
            to: w[1].seq.saturating_sub(1),
        });
    }
    let recorded: std::collections::HashSet<u64> = imu.iter().map(|s| s.seq).collect();
    match thrust
        .iter()
        .find(|t| t.imu_seq != 0 && !recorded.contains(&t.imu_seq))
    {
        Some(t) => Err(RerunError::LostImu(t.imu_seq)),
        None => Ok(()),
    }
}

/// A replay that starts from a checkpoint: the machine it holds, and where it was taken.
pub struct Resume {
    pub machine: Machine,
    pub place: Place,
}

/// Runs `imu` and `inputs` (a checked journal) through a machine set up from `cfg`, or from
/// `from` (a checkpoint: then `inputs` are the entries after it, and only the samples after
/// its sample are fed; those before it go through the validator only, as in the daemon).
pub fn rerun(
    cfg: &DaemonConfig,
    from: Option<Resume>,
    imu: &[ImuSample],
    inputs: &[InputMsg],
    thrust: &[ThrustCommand],
) -> Result<Outcome, RerunError> {
    // The count the daemon drove at its first answer (after the checkpoint, when from one).
    let recorded_thrusters = thrust
        .iter()
        .find(|t| from.as_ref().is_none_or(|r| t.imu_seq > r.place.imu_seq))
        .map(|t| t.count as usize);
    // The daemon's answer to each sample: the first command naming it (a later one with the
    // same seq is the neutral of a stale deadline).
    let mut answers = std::collections::HashMap::with_capacity(thrust.len());
    for t in thrust {
        answers.entry(t.imu_seq).or_insert(*t);
    }
    let (mut machine, place) = match from {
        Some(r) => (r.machine, Some(r.place)),
        None => (Machine::new(cfg.machine_setup()), None),
    };
    if let Some(recorded) = recorded_thrusters {
        if recorded != machine.thrusters() {
            return Err(RerunError::ThrusterCount {
                config: machine.thrusters(),
                recorded,
            });
        }
    }
    let mut out = Outcome {
        models: Vec::new(),
        imu_recorded: imu.len(),
        imu_not_received: 0,
        imu_accepted: 0,
        imu_rejected: 0,
        inputs_applied: 0,
        inputs_after_end: 0,
        divergences: Vec::new(),
        final_state: State::Idle,
        final_text: String::new(),
        vehicle_s: 0.0,
        commands_compared: 0,
        diverged_at: None,
        models_valid: Vec::new(),
        imu_before_checkpoint: 0,
    };
    // A journal that says when each solve's result reached the daemon's machine (the daemon
    // journals every one): the replay computes each job at once and hands its result over at
    // the same place, so a result the daemon applied late is applied late here too. Without
    // (an older recording) the jobs run inline and are applied at their due sample, which is
    // the daemon's outcome whenever no solve was late.
    let journaled = inputs
        .iter()
        .any(|m| m.kind() == Ok(InputKind::SolveDelivered));
    let mut solved = Solved::default();
    // A restored machine has the daemon's mode (external); without journaled deliveries
    // after the checkpoint it makes no job that needs one, so either mode is the same there.
    machine.set_solver_mode(if journaled {
        SolverMode::External
    } else {
        SolverMode::Inline
    });
    let t0 = imu.first().map_or(0, |s| s.t_ns);
    let mut validator = ImuSampleValidator::default();
    let mut next = 0;
    let mut model_seq = 0;
    // Entries before the first sample (the start, "no IMU yet"); from a checkpoint, those
    // after it, before the next sample.
    let mut started = place.is_none();
    if started {
        apply_due(
            &mut machine,
            inputs,
            &mut next,
            0,
            None,
            &mut solved,
            &mut out,
        )?;
        collect(&mut machine, &mut model_seq, &mut out);
    }
    for sample in imu {
        if let Some(p) = place.filter(|_| !started) {
            if sample.seq <= p.imu_seq {
                // Before the checkpoint: its effect on the machine is in the checkpoint; the
                // validator still sees it, as the daemon's did.
                if answers.contains_key(&sample.seq) {
                    let _ = validator.check(sample);
                }
                out.imu_before_checkpoint += 1;
                continue;
            }
            started = true;
            out.imu_accepted = p.imu_count;
            apply_due(
                &mut machine,
                inputs,
                &mut next,
                p.imu_count,
                Some(p.imu_seq),
                &mut solved,
                &mut out,
            )?;
            collect(&mut machine, &mut model_seq, &mut out);
        }
        // The daemon answers every sample it receives (a command, or neutral for a rejected
        // one): an unanswered one never reached it (a driver publishing before the daemon
        // subscribed, or the end of the recording).
        let Some(recorded) = answers.get(&sample.seq) else {
            out.imu_not_received += 1;
            continue;
        };
        if validator.check(sample).is_err() {
            // The daemon answered it with neutral and never showed it to the machine.
            out.imu_rejected += 1;
            continue;
        }
        out.imu_accepted += 1;
        let cmd = machine.on_imu(&wire::imu_input(sample));
        solved.run(&mut machine);
        if out.diverged_at.is_none() {
            out.commands_compared += 1;
            if !same_command(&cmd, recorded) {
                out.diverged_at = Some(Divergence {
                    imu_count: out.imu_accepted,
                    imu_seq: sample.seq,
                    t_s: sample.t_ns.saturating_sub(t0) as f64 * 1e-9,
                });
            }
        }
        apply_due(
            &mut machine,
            inputs,
            &mut next,
            out.imu_accepted,
            Some(sample.seq),
            &mut solved,
            &mut out,
        )?;
        // The daemon publishes swaps after the round's inputs; the order of swaps is the same.
        collect(&mut machine, &mut model_seq, &mut out);
    }
    out.inputs_after_end = inputs.len() - next;
    out.final_state = machine.state();
    out.final_text = machine.status().text;
    if let (Some(a), Some(b)) = (imu.first(), imu.last()) {
        out.vehicle_s = b.t_ns.saturating_sub(a.t_ns) as f64 * 1e-9;
    }
    Ok(out)
}

/// The replayed command as the daemon would have sent it, against the recorded one: count,
/// mode and every thrust to the bit.
fn same_command(cmd: &thrusterd_core::machine::Command, recorded: &ThrustCommand) -> bool {
    let mut msg = wire::thrust_command(0, recorded.imu_seq, recorded.t_ns, cmd);
    thruster_protocol::validate::sanitize_thrust(msg.thrusters_mut());
    let n = msg.thrusters_mut().len();
    msg.count == recorded.count
        && msg.mode == recorded.mode
        && msg.thrust[..n]
            .iter()
            .zip(&recorded.thrust[..n])
            .all(|(a, b)| a.to_bits() == b.to_bits())
}

/// Applies the entries that followed the `count`-th accepted sample (seq `seq`).
fn apply_due(
    machine: &mut Machine,
    inputs: &[InputMsg],
    next: &mut usize,
    count: u64,
    seq: Option<u64>,
    solved: &mut Solved,
    out: &mut Outcome,
) -> Result<(), RerunError> {
    while let Some(m) = inputs.get(*next).filter(|m| m.imu_count == count) {
        if let Some(seq) = seq {
            if m.imu_seq != seq {
                return Err(RerunError::Misplaced {
                    seq: m.seq,
                    imu_count: count,
                    daemon_seq: m.imu_seq,
                    replay_seq: seq,
                });
            }
        }
        let refused = apply(machine, m, solved);
        solved.run(machine);
        if refused != (m.refused != 0) {
            let verb = |r: bool| if r { "refused" } else { "took" };
            out.divergences.push(format!(
                "input journal entry {} ({} after IMU sample {}): the daemon {} it, the replay {} it",
                m.seq,
                m.kind().map(|k| k.name()).unwrap_or("?"),
                count,
                verb(m.refused != 0),
                verb(refused),
            ));
        }
        out.inputs_applied += 1;
        *next += 1;
    }
    Ok(())
}

/// Hands one journal entry to the machine as the daemon did; true when the machine refused.
fn apply(machine: &mut Machine, m: &InputMsg, solved: &mut Solved) -> bool {
    let text = m.text.as_str();
    match m.kind() {
        Ok(InputKind::Request) => {
            let request = match RequestKind::try_from(m.code) {
                Ok(RequestKind::Estimate) => {
                    // The daemon sets a requested power first; a refused power never reached
                    // the journal.
                    if m.value != 0.0 && machine.set_estimation_power(m.value).is_err() {
                        return true;
                    }
                    Request::Estimate
                }
                Ok(RequestKind::Abort) => Request::Abort,
                Ok(RequestKind::Hold) => Request::Hold,
                Ok(RequestKind::Idle) => Request::Idle,
                Ok(RequestKind::Stop) => Request::Stop,
                Ok(RequestKind::Revert) => Request::Revert,
                // Status, save, load and shutdown never go to the machine as requests.
                _ => return true,
            };
            machine.on_request(request).is_err()
        }
        Ok(InputKind::Setpoint) => {
            machine.on_setpoint_input(&wire::setpoint(&m.setpoint));
            false
        }
        Ok(InputKind::Reconfig) => {
            machine.on_reconfig(wire::reconfig(&m.reconfig));
            false
        }
        Ok(InputKind::Outputs) => {
            machine.on_outputs((m.code != 0).then_some(text));
            false
        }
        Ok(InputKind::ImuStale) => {
            machine.on_imu_stale(text);
            false
        }
        Ok(InputKind::NoImuYet) => {
            machine.on_no_imu_yet(text);
            false
        }
        Ok(InputKind::Dvl) => {
            machine.on_dvl(m.dvl);
            false
        }
        Ok(InputKind::Supply) => {
            machine.on_supply((m.code != 0).then_some(m.value));
            false
        }
        // A result the replay does not have (a job it never made) is "refused": the entry
        // is then reported as a divergence.
        Ok(InputKind::SolveDelivered) => match solved.results.remove(&u64::from(m.code)) {
            Some(r) => {
                machine.deliver(r);
                false
            }
            None => true,
        },
        // Start carries nothing for the machine; Load and unknown kinds were refused by
        // `journal::check`.
        Ok(InputKind::Start) | Ok(InputKind::Load) | Err(_) => false,
    }
}

/// The results of the solve jobs the replayed machine handed out (external mode), by job
/// id, until the journal says the daemon's machine got them.
#[derive(Default)]
struct Solved {
    results: std::collections::HashMap<u64, SolveResult>,
}

impl Solved {
    /// Runs every job the machine has handed out since the last call (none inline).
    fn run(&mut self, machine: &mut Machine) {
        while let Some(job) = machine.take_job() {
            let id = job.id();
            self.results.insert(id, job.run());
        }
    }
}

/// Takes the machine's events; a swap becomes the message the daemon published.
fn collect(machine: &mut Machine, model_seq: &mut u64, out: &mut Outcome) {
    for event in machine.take_events() {
        if let Event::ModelSwapped(model) = event {
            out.models.push(wire::model_msg(*model_seq, &model));
            // Made from samples up to this one and commands before it: still the setting's
            // own answer if the commands diverged at this sample at the earliest.
            out.models_valid.push(
                out.diverged_at
                    .is_none_or(|d| d.imu_count >= out.imu_accepted),
            );
            *model_seq += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `n` samples at rest at 200 Hz.
    fn rest(n: u64) -> Vec<ImuSample> {
        (1..=n)
            .map(|seq| ImuSample {
                seq,
                t_ns: seq * 5_000_000,
                gyro: [0.0; 3],
                accel: [0.0, 0.0, -9.81],
                mag: [0.0; 3],
                depth: 0.0,
                flags: 0,
            })
            .collect()
    }

    fn neutral_answers(imu: &[ImuSample], count: u32) -> Vec<ThrustCommand> {
        imu.iter()
            .map(|s| ThrustCommand::neutral(s.seq - 1, s.seq, s.t_ns, count))
            .collect()
    }

    fn entry(seq: u64, kind: InputKind, imu_count: u64, imu_seq: u64) -> InputMsg {
        let mut m = InputMsg {
            seq,
            imu_count,
            imu_seq,
            ..InputMsg::default()
        };
        m.set_kind(kind);
        m
    }

    fn hold(seq: u64, at: u64, refused: bool) -> InputMsg {
        let mut m = entry(seq, InputKind::Request, at, at);
        m.code = RequestKind::Hold.as_u32();
        m.refused = u32::from(refused);
        m
    }

    #[test]
    fn an_idle_session_replays_with_the_same_commands_and_answers() {
        let cfg = DaemonConfig::default();
        let imu = rest(50);
        let thrust = neutral_answers(&imu, 5);
        // Hold without a model: the daemon refused it, so must the replay.
        let inputs = [entry(0, InputKind::Start, 0, 0), hold(1, 10, true)];
        let o = rerun(&cfg, None, &imu, &inputs, &thrust).unwrap();
        assert_eq!(o.imu_accepted, 50);
        assert_eq!(o.inputs_applied, 2);
        assert_eq!(o.commands_compared, 50);
        assert_eq!(o.diverged_at, None);
        assert!(o.divergences.is_empty(), "{:?}", o.divergences);
        assert!(o.models.is_empty());
    }

    /// From a checkpoint taken after sample 30 (the daemon's machine as it was then): only
    /// the samples after it are fed, counted on from the checkpoint's count, and the entries
    /// after it are placed by that count; a sample before it is only validated.
    #[test]
    fn a_replay_from_a_checkpoint_feeds_what_came_after_it() {
        let cfg = DaemonConfig::default();
        let imu = rest(80);
        let thrust = neutral_answers(&imu, 5);
        let mut daemon = Machine::new(cfg.machine_setup());
        for s in &imu[..30] {
            daemon.on_imu(&wire::imu_input(s));
        }
        let place = Place {
            imu_count: 30,
            imu_seq: 30,
            t_ns: imu[29].t_ns,
            journal_next: 2,
            ..Place::default()
        };
        let resume = Resume {
            machine: Machine::restore(cfg.machine_setup(), &daemon.checkpoint().unwrap()).unwrap(),
            place,
        };
        // Entry 2 right after the checkpoint's sample, entry 3 later: both refused (no model).
        let inputs = [hold(2, 30, true), hold(3, 60, true)];
        let o = rerun(&cfg, Some(resume), &imu, &inputs, &thrust).unwrap();
        assert_eq!(o.imu_before_checkpoint, 30);
        assert_eq!(o.imu_accepted, 80);
        assert_eq!(o.commands_compared, 50);
        assert_eq!(o.inputs_applied, 2);
        assert!(o.divergences.is_empty(), "{:?}", o.divergences);
        assert_eq!(o.diverged_at, None);
        // An entry placed at another sample than the checkpoint's count says is found.
        let resume = Resume {
            machine: Machine::restore(cfg.machine_setup(), &daemon.checkpoint().unwrap()).unwrap(),
            place,
        };
        let inputs = [hold(2, 30, true), entry(3, InputKind::Request, 40, 41)];
        assert!(matches!(
            rerun(&cfg, Some(resume), &imu, &inputs, &thrust),
            Err(RerunError::Misplaced { seq: 3, .. })
        ));
    }

    /// A journal that hands over a result the replay's machine never asked for (a damaged
    /// or foreign journal): reported, not silently skipped.
    #[test]
    fn a_delivered_result_the_replay_never_made_is_reported() {
        let imu = rest(20);
        let mut delivered = entry(1, InputKind::SolveDelivered, 10, 10);
        delivered.code = 7;
        let inputs = [entry(0, InputKind::Start, 0, 0), delivered];
        let o = rerun(
            &DaemonConfig::default(),
            None,
            &imu,
            &inputs,
            &neutral_answers(&imu, 5),
        )
        .unwrap();
        assert_eq!(o.divergences.len(), 1, "{:?}", o.divergences);
        assert!(
            o.divergences[0].contains("SolveDelivered"),
            "{:?}",
            o.divergences
        );
    }

    #[test]
    fn a_different_answer_is_reported() {
        let imu = rest(20);
        let inputs = [entry(0, InputKind::Start, 0, 0), hold(1, 10, false)];
        let o = rerun(
            &DaemonConfig::default(),
            None,
            &imu,
            &inputs,
            &neutral_answers(&imu, 5),
        )
        .unwrap();
        assert_eq!(o.divergences.len(), 1, "{:?}", o.divergences);
        assert!(o.divergences[0].contains("the daemon took it, the replay refused it"));
    }

    #[test]
    fn a_command_that_differs_marks_where_the_replay_left_the_recording() {
        let imu = rest(30);
        let mut thrust = neutral_answers(&imu, 5);
        thrust[11].thrust[2] = 0.25;
        let o = rerun(
            &DaemonConfig::default(),
            None,
            &imu,
            &[entry(0, InputKind::Start, 0, 0)],
            &thrust,
        )
        .unwrap();
        let d = o.diverged_at.expect("diverged");
        assert_eq!((d.imu_count, d.imu_seq), (12, 12));
        assert_eq!(o.commands_compared, 12);
    }

    #[test]
    fn an_entry_placed_after_another_sample_is_refused() {
        let imu = rest(20);
        // The daemon's 10th accepted sample was seq 11: the recording lost one before it.
        let inputs = [entry(0, InputKind::Start, 0, 0), hold(1, 10, true)];
        let mut shifted = inputs;
        shifted[1].imu_seq = 11;
        let err = rerun(
            &DaemonConfig::default(),
            None,
            &imu,
            &shifted,
            &neutral_answers(&imu, 5),
        )
        .unwrap_err();
        assert!(
            matches!(
                err,
                RerunError::Misplaced {
                    seq: 1,
                    imu_count: 10,
                    daemon_seq: 11,
                    replay_seq: 10
                }
            ),
            "{err}"
        );
    }

    #[test]
    fn the_wrong_thruster_count_is_refused() {
        let imu = rest(5);
        let thrust = neutral_answers(&imu, 6);
        let err = rerun(&DaemonConfig::default(), None, &imu, &[], &thrust).unwrap_err();
        assert_eq!(
            err,
            RerunError::ThrusterCount {
                config: 5,
                recorded: 6
            }
        );
    }

    #[test]
    fn an_answer_to_a_sample_not_recorded_is_a_loss() {
        let imu = rest(5);
        let mut thrust = neutral_answers(&imu, 5);
        thrust.push(ThrustCommand::neutral(5, 7, 0, 5));
        assert_eq!(check_complete(&imu, &thrust), Err(RerunError::LostImu(7)));
        assert_eq!(check_complete(&imu, &thrust[..5]), Ok(()));
        let mut gap = neutral_answers(&imu, 5);
        gap.remove(2);
        assert_eq!(
            check_complete(&imu, &gap),
            Err(RerunError::LostThrust { from: 2, to: 2 })
        );
    }

    #[test]
    fn samples_the_daemon_never_answered_are_not_fed() {
        // The driver published 1..=7 before the daemon subscribed: the daemon's first
        // accepted sample is seq 8, and its journal says so.
        let imu = rest(30);
        let thrust = neutral_answers(&imu[7..], 5);
        let inputs = [entry(0, InputKind::Start, 0, 0), hold(1, 10, true)];
        let mut daemon = inputs;
        daemon[1].imu_seq = 17;
        let o = rerun(&DaemonConfig::default(), None, &imu, &daemon, &thrust).unwrap();
        assert_eq!(o.imu_not_received, 7);
        assert_eq!(o.imu_accepted, 23);
        assert_eq!(o.inputs_applied, 2);
    }
}
