//! The dynamic fit's inputs after navigation, kept so that the fit can be made again with
//! another thruster lag ([`super::lag_search`]): the lag is the one unknown the regression is
//! not linear in, so it is found by refitting, and a refit needs the samples.
//!
//! The per-sample path must not allocate and a solve job's snapshot must not copy the whole
//! log on the control thread. So the log is made of fixed chunks allocated once, when the run
//! starts: full chunks are shared (`Arc`) with snapshots and never written again; only the open
//! chunk is written, and a snapshot copies just its filled part (a job's creation allocates
//! anyway). When every chunk is full the log stops growing and says so: the lag is then learned
//! from the first [`CAPACITY`] samples, which at 1 kHz is 32 s of excitation.

use std::sync::Arc;

use nalgebra::Vector3;

/// Samples per chunk.
const CHUNK: usize = 512;

/// Chunks allocated when the log is made.
const CHUNKS: usize = 64;

/// Samples the log holds at most (~5.5 MB: 168 bytes each with the attitude).
pub const CAPACITY: usize = CHUNK * CHUNKS;

/// One sample as the fit sees it, after the navigation.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Navigated {
    /// Vehicle time, s.
    pub t_s: f64,
    /// Bias-free gyro, rad/s (the rotation rows' output).
    pub gyro: Vector3<f64>,
    /// The navigation's body velocity, rate and gravity direction (the terms' inputs).
    pub velocity: Vector3<f64>,
    pub rate: Vector3<f64>,
    pub down: Vector3<f64>,
    /// The body's acceleration (the translation rows' output).
    pub motion: Vector3<f64>,
    /// Index of the command in force into [`SampleLog::command`]; `u32::MAX`: neutral.
    pub command: u32,
    /// The navigation's attitude (body to NED): the disturbance states' world-fixed force
    /// is seen through it (`DynamicRun::with_disturbance`, a research hook).
    #[serde(default = "identity")]
    pub attitude: nalgebra::UnitQuaternion<f64>,
}

fn identity() -> nalgebra::UnitQuaternion<f64> {
    nalgebra::UnitQuaternion::identity()
}

/// The navigated samples of one run and the commands they were taken under.
#[derive(Debug)]
pub struct SampleLog {
    /// Full chunks, shared with snapshots, never written again.
    sealed: Vec<Arc<Vec<Navigated>>>,
    /// The chunk being written (capacity [`CHUNK`]); never shared (a snapshot copies it), so
    /// it is written in place.
    open: Arc<Vec<Navigated>>,
    /// Empty chunks allocated up front, taken as the open one fills: already in their `Arc`,
    /// so sealing a chunk allocates nothing.
    spare: Vec<Arc<Vec<Navigated>>>,
    /// Every distinct command (one per pulse), N values each, concatenated.
    commands: Vec<f64>,
    n: usize,
    /// Samples that did not fit any more.
    dropped: u64,
}

impl SampleLog {
    /// An empty log for `n` thrusters with room for [`CAPACITY`] samples and `max_commands`
    /// commands, all allocated now.
    pub fn new(n: usize, max_commands: usize) -> Self {
        SampleLog {
            sealed: Vec::with_capacity(CHUNKS),
            open: Arc::new(Vec::with_capacity(CHUNK)),
            spare: (1..CHUNKS)
                .map(|_| Arc::new(Vec::with_capacity(CHUNK)))
                .collect(),
            commands: Vec::with_capacity(n * max_commands.max(1)),
            n,
            dropped: 0,
        }
    }

    /// Store command `u` (N values) and return its index, or `u32::MAX` when there is no room.
    /// Called when a pulse starts (an allocation point anyway).
    pub fn add_command(&mut self, u: &[f64]) -> u32 {
        let index = self.commands.len() / self.n.max(1);
        if u.len() != self.n || self.commands.len() + self.n > self.commands.capacity() {
            return u32::MAX;
        }
        self.commands.extend_from_slice(u);
        index as u32
    }

    /// The command stored at `index` (None: neutral).
    pub fn command(&self, index: u32) -> Option<&[f64]> {
        let start = (index as usize).checked_mul(self.n)?;
        self.commands.get(start..start + self.n)
    }

    /// Append one sample; never allocates (dropped, and counted, once the log is full).
    pub fn push(&mut self, s: Navigated) {
        if self.open.len() == CHUNK {
            let Some(next) = self.spare.pop() else {
                self.dropped += 1;
                return;
            };
            let full = std::mem::replace(&mut self.open, next);
            self.sealed.push(full);
        }
        // The open chunk is never shared: a snapshot copies it into its own Arc.
        if let Some(open) = Arc::get_mut(&mut self.open) {
            open.push(s);
        } else {
            self.dropped += 1;
        }
    }

    /// Samples held.
    pub fn len(&self) -> usize {
        self.sealed.len() * CHUNK + self.open.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Samples that arrived after the log was full.
    pub fn dropped(&self) -> u64 {
        self.dropped
    }

    /// A copy with every sample replaced by `f`'s (the same commands): for the lab's decisive
    /// runs, which put the truth in place of one input to see what the fit does with it.
    pub fn mapped(&self, mut f: impl FnMut(&Navigated) -> Navigated) -> SampleLog {
        let mut out = SampleLog::new(self.n, self.commands.len() / self.n.max(1) + 1);
        out.commands.extend_from_slice(&self.commands);
        for s in self.iter() {
            out.push(f(s));
        }
        out
    }

    /// A copy whose commands are bent to the power `p`, the samples the same: a refit of it
    /// fits thrust ~ command^p ([`super::thrust_curve`]). Each thruster's value u goes to
    /// sign(u) m (|u| / m)^p, m the largest |u| the log holds for that thruster in that
    /// direction: the bend leaves the top level of each direction where it is, so the fit's
    /// forward-to-reverse ratio does not move with p. Why: the pulses' forward level is
    /// `reverse_ratio` times the reverse one, so a plain bend (m = 1) changes that ratio
    /// with p, and a reverse ratio the daemon was told wrong then chose the exponent
    /// (eight_vectored_lag80ms_curve, thrust ~ command^1.5 and 0.58 in reverse where 0.78
    /// was assumed, came out 2/3).
    /// `top_kept` false: the plain bend (m = 1), what a model carrying the curve is per unit
    /// of (`DynamicTerms::command_exponent`).
    pub fn with_commands_bent(&self, p: f64, top_kept: bool) -> SampleLog {
        let n = self.n.max(1);
        let mut top = vec![[1.0f64; 2]; n];
        if top_kept {
            top = vec![[0.0f64; 2]; n];
            for u in self.commands.chunks(n) {
                for (t, v) in top.iter_mut().zip(u) {
                    let d = usize::from(*v < 0.0);
                    t[d] = t[d].max(v.abs());
                }
            }
        }
        let mut out = self.mapped(|s| *s);
        for u in out.commands.chunks_mut(n) {
            for (t, v) in top.iter().zip(u.iter_mut()) {
                let m = t[usize::from(*v < 0.0)];
                if m > 0.0 {
                    *v = v.signum() * m * (v.abs() / m).powf(p);
                }
            }
        }
        out
    }

    /// Every sample, in order.
    pub fn iter(&self) -> impl Iterator<Item = &Navigated> {
        self.sealed
            .iter()
            .flat_map(|c| c.iter())
            .chain(self.open.iter())
    }
}

/// The log in a checkpoint (`machine::checkpoint`): its samples and commands, and the room
/// it had. The room is behaviour, not only memory: a command that does not fit the commands'
/// capacity is not stored, and a sample past the last spare chunk is dropped, so a restored
/// log must have exactly the room the original had left.
#[derive(serde::Serialize)]
struct LogOut<'a> {
    sealed: &'a [Arc<Vec<Navigated>>],
    open: &'a [Navigated],
    spare: usize,
    commands: &'a [f64],
    commands_capacity: usize,
    n: usize,
    dropped: u64,
}

#[derive(serde::Deserialize)]
struct LogIn {
    sealed: Vec<Vec<Navigated>>,
    open: Vec<Navigated>,
    spare: usize,
    commands: Vec<f64>,
    commands_capacity: usize,
    n: usize,
    dropped: u64,
}

impl serde::Serialize for SampleLog {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        LogOut {
            sealed: &self.sealed,
            open: &self.open,
            spare: self.spare.len(),
            commands: &self.commands,
            commands_capacity: self.commands.capacity(),
            n: self.n,
            dropped: self.dropped,
        }
        .serialize(s)
    }
}

impl<'de> serde::Deserialize<'de> for SampleLog {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        use serde::de::Error;
        let log = LogIn::deserialize(d)?;
        if log.spare > CHUNKS
            || log.open.len() > CHUNK
            || log.commands.len() > log.commands_capacity
            || log.sealed.iter().any(|c| c.len() != CHUNK)
        {
            return Err(D::Error::custom("a sample log larger than its room"));
        }
        let mut open = Vec::with_capacity(CHUNK);
        open.extend_from_slice(&log.open);
        let mut commands = Vec::with_capacity(log.commands_capacity);
        commands.extend_from_slice(&log.commands);
        Ok(SampleLog {
            sealed: log.sealed.into_iter().map(Arc::new).collect(),
            open: Arc::new(open),
            spare: (0..log.spare)
                .map(|_| Arc::new(Vec::with_capacity(CHUNK)))
                .collect(),
            commands,
            n: log.n,
            dropped: log.dropped,
        })
    }
}

impl Clone for SampleLog {
    /// A read-only snapshot: the sealed chunks shared, the open one's samples copied, no spare
    /// room (a snapshot is solved, never written).
    fn clone(&self) -> Self {
        SampleLog {
            sealed: self.sealed.clone(),
            open: Arc::new(self.open.as_ref().clone()),
            spare: Vec::new(),
            commands: self.commands.clone(),
            n: self.n,
            dropped: self.dropped,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(k: usize) -> Navigated {
        Navigated {
            t_s: k as f64,
            gyro: Vector3::zeros(),
            velocity: Vector3::zeros(),
            rate: Vector3::zeros(),
            down: Vector3::z(),
            motion: Vector3::zeros(),
            command: u32::MAX,
            attitude: identity(),
        }
    }

    #[test]
    fn keeps_every_sample_in_order_across_chunks_and_snapshots() {
        let mut log = SampleLog::new(2, 4);
        for k in 0..(CHUNK * 2 + 7) {
            log.push(sample(k));
        }
        let snapshot = log.clone();
        for k in (CHUNK * 2 + 7)..(CHUNK * 3 + 1) {
            log.push(sample(k));
        }
        assert_eq!(snapshot.len(), CHUNK * 2 + 7);
        assert_eq!(log.len(), CHUNK * 3 + 1);
        assert!(log.iter().enumerate().all(|(k, s)| s.t_s == k as f64));
        assert!(snapshot.iter().enumerate().all(|(k, s)| s.t_s == k as f64));
    }

    #[test]
    fn stops_growing_when_full_and_counts_what_it_dropped() {
        let mut log = SampleLog::new(1, 1);
        for k in 0..CAPACITY + 10 {
            log.push(sample(k));
        }
        assert_eq!(log.len(), CAPACITY);
        assert_eq!(log.dropped(), 10);
    }

    #[test]
    fn commands_are_stored_up_to_their_room() {
        let mut log = SampleLog::new(2, 2);
        assert_eq!(log.add_command(&[0.5, -0.5]), 0);
        assert_eq!(log.add_command(&[1.0, 0.0]), 1);
        assert_eq!(log.add_command(&[1.0, 1.0]), u32::MAX);
        assert_eq!(log.add_command(&[1.0]), u32::MAX);
        assert_eq!(log.command(1), Some(&[1.0, 0.0][..]));
        assert_eq!(log.command(u32::MAX), None);
    }
}
