//! The inputs the daemon reads beside the IMU: announced reconfigurations, setpoints, the
//! driver's reports and the DVL. In real time each is read and applied when it comes. In
//! lockstep each is applied with the next sample only (before it, or a reconfiguration once
//! its command is computed), so the sample an input lands at is a matter of vehicle time; but
//! it is still read when it comes and held here until then: an operator's publisher
//! (`thrusterctl reconfigure`) is gone once the daemon has confirmed the delivery, and what
//! nobody read before that is gone with it.

use std::cell::RefCell;
use std::collections::VecDeque;

use thruster_protocol::services::{Inbox, IpcError, TopicMessage};
use thruster_protocol::{DriverStatusMsg, DvlSample, ReconfigEvent, Setpoint};

/// Most messages of one kind held between two samples (a lockstep driver that holds for long
/// while a publisher floods): beyond it the oldest go, counted.
const HOLD_MAX: usize = 256;

pub struct SideInputs {
    pub reconfig: Inbox<ReconfigEvent>,
    pub setpoint: Inbox<Setpoint>,
    pub driver: Inbox<DriverStatusMsg>,
    pub dvl: Inbox<DvlSample>,
    held: RefCell<Held>,
}

#[derive(Default)]
struct Held {
    reconfig: VecDeque<ReconfigEvent>,
    setpoint: VecDeque<Setpoint>,
    driver: VecDeque<DriverStatusMsg>,
    dvl: VecDeque<DvlSample>,
}

impl SideInputs {
    pub fn new(
        reconfig: Inbox<ReconfigEvent>,
        setpoint: Inbox<Setpoint>,
        driver: Inbox<DriverStatusMsg>,
        dvl: Inbox<DvlSample>,
    ) -> SideInputs {
        SideInputs {
            reconfig,
            setpoint,
            driver,
            dvl,
            held: RefCell::new(Held::default()),
        }
    }

    /// Reads every waiting message into the held queues (applied with the next sample);
    /// how many older ones were dropped to stay within [`HOLD_MAX`].
    pub fn hold_all(&self) -> Result<usize, IpcError> {
        let mut held = self.held.borrow_mut();
        let held = &mut *held;
        Ok(hold(&self.reconfig, &mut held.reconfig)?
            + hold(&self.setpoint, &mut held.setpoint)?
            + hold(&self.driver, &mut held.driver)?
            + hold(&self.dvl, &mut held.dvl)?)
    }

    /// The next reconfiguration: a held one first, in arrival order.
    pub fn next_reconfig(&self) -> Result<Option<ReconfigEvent>, IpcError> {
        next(&self.reconfig, &mut self.held.borrow_mut().reconfig)
    }

    pub fn next_setpoint(&self) -> Result<Option<Setpoint>, IpcError> {
        next(&self.setpoint, &mut self.held.borrow_mut().setpoint)
    }

    pub fn next_driver_report(&self) -> Result<Option<DriverStatusMsg>, IpcError> {
        next(&self.driver, &mut self.held.borrow_mut().driver)
    }

    pub fn next_dvl(&self) -> Result<Option<DvlSample>, IpcError> {
        next(&self.dvl, &mut self.held.borrow_mut().dvl)
    }
}

fn hold<T: TopicMessage>(inbox: &Inbox<T>, held: &mut VecDeque<T>) -> Result<usize, IpcError> {
    let mut dropped = 0;
    while let Some(m) = inbox.recv()? {
        if held.len() == HOLD_MAX {
            held.pop_front();
            dropped += 1;
        }
        held.push_back(m);
    }
    Ok(dropped)
}

fn next<T: TopicMessage>(inbox: &Inbox<T>, held: &mut VecDeque<T>) -> Result<Option<T>, IpcError> {
    match held.pop_front() {
        Some(m) => Ok(Some(m)),
        None => inbox.recv(),
    }
}
