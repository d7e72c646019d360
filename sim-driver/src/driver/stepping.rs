//! Stepped lockstep (`thruster-sim run --lockstep --stepped`): vehicle time advances only as
//! far as the process that started the simulator allows, so that process (the lab's operator:
//! `thrusterctl demo`, `experiment`, `study`) acts at exact vehicle times and one seed gives
//! one result however busy the machine is (issue 27).
//!
//! The protocol is lines of text on the simulator's standard input and output:
//! - in: `run N` (N >= 1): take N more samples;
//! - out: `at SEQ T_NS` when the allowance is used up: sample `SEQ` (taken at vehicle time
//!   `T_NS`) has been published and its answer held, and nothing newer exists. The first
//!   `at` comes once the first sample has been answered.
//!
//! The simulator's log goes to standard error, so standard output carries these lines only.
//! A closed standard input (the controller is gone) stops the run like a signal.

use std::io::{BufRead, Write};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};

use super::shutdown::Shutdown;
use super::wait::MAX_BLOCK;

/// Why the controller's line was refused (the run stops: a controller that sends garbage
/// would otherwise act at vehicle times it did not mean).
#[derive(Debug, thiserror::Error)]
pub enum SteppingError {
    /// Not `run N` with 1 <= N <= 10^9.
    #[error("stepping: expected `run N` (N in 1..=1000000000) on standard input, got {0:?}")]
    BadLine(String),
    /// Writing `at ...` to standard output failed (the controller closed it).
    #[error("stepping: writing to standard output failed: {0}")]
    Write(#[from] std::io::Error),
}

/// Most samples one `run` may allow (a typo of many digits is refused, not run for days).
const MAX_RUN: u64 = 1_000_000_000;

/// What came from standard input.
enum Order {
    Run(u64),
    Bad(String),
    Closed,
}

/// The allowance of samples and the line reader behind it.
pub struct Stepping {
    orders: Receiver<Order>,
    allowed: u64,
}

impl Stepping {
    /// Starts reading standard input on a thread of its own (a blocking read must not keep
    /// the loop from seeing a signal).
    pub fn from_stdin() -> Stepping {
        let (tx, orders) = mpsc::channel();
        std::thread::Builder::new()
            .name("stepping-stdin".into())
            .spawn(move || {
                let stdin = std::io::stdin();
                for line in stdin.lock().lines() {
                    let order = match line {
                        Ok(l) => parse(&l),
                        Err(_) => Order::Closed,
                    };
                    let last = matches!(order, Order::Closed | Order::Bad(_));
                    if tx.send(order).is_err() || last {
                        return;
                    }
                }
                let _ = tx.send(Order::Closed);
            })
            .expect("spawning the stepping reader");
        Stepping { orders, allowed: 0 }
    }

    /// True when the next [`Stepping::permit`] reports where the run stands and waits.
    pub fn will_wait(&self) -> bool {
        self.allowed == 0
    }

    /// Called before each new sample is taken (sample `seq`, taken at `t_ns`, is the newest
    /// and answered): uses one sample of the allowance, or reports `at seq t_ns` and waits
    /// for more. False when the run should stop (signal, or the controller is gone).
    pub fn permit(&mut self, seq: u64, t_ns: u64, stop: &Shutdown) -> Result<bool, SteppingError> {
        if self.allowed == 0 {
            let mut out = std::io::stdout().lock();
            writeln!(out, "at {seq} {t_ns}")?;
            out.flush()?;
        }
        while self.allowed == 0 {
            if stop.requested() {
                return Ok(false);
            }
            match self.orders.recv_timeout(MAX_BLOCK) {
                Ok(Order::Run(n)) => self.allowed = n,
                Ok(Order::Bad(line)) => return Err(SteppingError::BadLine(line)),
                Ok(Order::Closed) | Err(RecvTimeoutError::Disconnected) => return Ok(false),
                Err(RecvTimeoutError::Timeout) => {}
            }
        }
        self.allowed -= 1;
        Ok(true)
    }
}

fn parse(line: &str) -> Order {
    let mut words = line.split_whitespace();
    match (
        words.next(),
        words.next().map(str::parse::<u64>),
        words.next(),
    ) {
        (Some("run"), Some(Ok(n)), None) if (1..=MAX_RUN).contains(&n) => Order::Run(n),
        _ => Order::Bad(line.to_string()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_run_with_a_count_in_range_is_an_order() {
        assert!(matches!(parse("run 8"), Order::Run(8)));
        assert!(matches!(parse("  run   1 "), Order::Run(1)));
        for bad in [
            "run 0",
            "run",
            "run -3",
            "run 8 9",
            "walk 8",
            "",
            "run 1000000001",
        ] {
            assert!(matches!(parse(bad), Order::Bad(_)), "{bad:?} was taken");
        }
    }
}
