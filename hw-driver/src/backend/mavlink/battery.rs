//! The supply voltage and current from ArduSub's battery reports, without IO.
//!
//! SYS_STATUS carries the first battery monitor's `voltage_battery` (mV, UINT16_MAX =
//! unknown) and `current_battery` (cA, -1 = unknown); BATTERY_STATUS carries per-monitor cell
//! voltages (mV each, UINT16_MAX = unused; ArduPilot puts the pack voltage in the first cell
//! when it does not measure cells, so the sum of the used entries is the pack voltage either
//! way) and `current_battery` (cA, -1 = unknown). ArduSub without a battery monitor
//! (`BATT_MONITOR = 0`) reports 0 V: taken as unknown, since no ESC runs at 0 V. Only
//! monitor 0 of BATTERY_STATUS is read: the one that powers the thrusters on a BlueROV2.
//!
//! What the numbers are (ArduPilot `GCS_MAVLINK::send_battery_status`, `AP_BattMonitor::
//! gcs_voltage`):
//! - Both messages carry `gcs_voltage()`: with bit 6 of `BATT_OPTIONS` ("send resistance
//!   compensated voltage to GCS") that is a resting estimate, V + I R, not the voltage at the
//!   ESCs: under load volts higher, exactly the sag thrust follows. The driver reads
//!   `BATT_OPTIONS` and, with bit 6 set, reports the voltage unknown and says which bit to
//!   clear.
//! - A monitor with cell voltages puts cells 11-14 in `voltages_ext`, which the `mavlink`
//!   crate's BATTERY_STATUS does not decode: the sum of `voltages` would miss them on a pack
//!   of more than 10 cells. SYS_STATUS's pack voltage is used whenever it is fresh; the cells
//!   only when SYS_STATUS carries none.

use mavlink::dialects::ardupilotmega::{BATTERY_STATUS_DATA, SYS_STATUS_DATA};

use super::params::ParamReader;
use crate::backend::Supply;

/// A supply reading older than this is not reported, ns (ArduSub sends SYS_STATUS at 1-2 Hz).
pub const SUPPLY_STALE_NS: u64 = 5_000_000_000;

/// The first battery monitor's options.
pub const BATT_OPTIONS: &str = "BATT_OPTIONS";
/// `AP_BattMonitor_Params::Options::GCS_Resting_Voltage`.
pub const GCS_RESTING_VOLTAGE: u32 = 1 << 6;

/// A supply reading in SI units: volts, and amps when reported.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SupplyReading {
    pub voltage_v: f64,
    pub current_a: Option<f64>,
}

fn current(centiamps: i16) -> Option<f64> {
    (centiamps != -1).then(|| f64::from(centiamps) / 100.0)
}

/// The reading in a SYS_STATUS, if it has a voltage.
pub fn from_sys_status(s: &SYS_STATUS_DATA) -> Option<SupplyReading> {
    if s.voltage_battery == u16::MAX || s.voltage_battery == 0 {
        return None;
    }
    Some(SupplyReading {
        voltage_v: f64::from(s.voltage_battery) / 1000.0,
        current_a: current(s.current_battery),
    })
}

/// The reading in a BATTERY_STATUS of monitor 0, if it has a voltage.
pub fn from_battery_status(b: &BATTERY_STATUS_DATA) -> Option<SupplyReading> {
    if b.id != 0 {
        return None;
    }
    let mv: u32 = b
        .voltages
        .iter()
        .filter(|v| **v != u16::MAX)
        .map(|v| u32::from(*v))
        .sum();
    if mv == 0 {
        return None;
    }
    Some(SupplyReading {
        voltage_v: f64::from(mv) / 1000.0,
        current_a: current(b.current_battery),
    })
}

/// Which message a reading came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Source {
    SysStatus,
    BatteryStatus,
}

/// The supply as the autopilot reports it, and whether its voltage is the one at the ESCs.
#[derive(Debug, Clone, PartialEq)]
pub struct SupplyTracker {
    latest: Option<(u64, SupplyReading, Source)>,
    /// SYS_STATUS's last reading with a voltage, ns (it wins over BATTERY_STATUS while fresh).
    sys_status_ns: Option<u64>,
    /// `BATT_OPTIONS`, read at each link-up ([`ParamReader`]).
    pub options: ParamReader<1>,
}

impl Default for SupplyTracker {
    fn default() -> Self {
        SupplyTracker {
            latest: None,
            sys_status_ns: None,
            options: ParamReader::new([BATT_OPTIONS]),
        }
    }
}

impl SupplyTracker {
    /// `BATT_OPTIONS` as the autopilot said it, if it did.
    fn options_bits(&self) -> Option<u32> {
        self.options.known()[0].map(|v| v.max(0.0) as u32)
    }

    /// The reported voltage is a resting estimate, not the one at the ESCs.
    fn resting_estimate(&self) -> bool {
        self.options_bits()
            .is_some_and(|bits| bits & GCS_RESTING_VOLTAGE != 0)
    }

    /// Why the reported voltage is not the one at the ESCs, if it is not.
    pub fn not_the_esc_voltage(&self) -> Option<String> {
        let bits = self.options_bits().filter(|_| self.resting_estimate())?;
        Some(format!(
            "{BATT_OPTIONS} = {bits}: bit 6 makes the autopilot report a resting estimate \
             (V + I R), not the voltage at the ESCs; clear it"
        ))
    }

    pub fn on_sys_status(&mut self, t_ns: u64, s: &SYS_STATUS_DATA) {
        if let Some(r) = from_sys_status(s) {
            self.latest = Some((t_ns, r, Source::SysStatus));
            self.sys_status_ns = Some(t_ns);
        }
    }

    pub fn on_battery_status(&mut self, t_ns: u64, b: &BATTERY_STATUS_DATA) {
        let sys_status_fresh = self
            .sys_status_ns
            .is_some_and(|t| t_ns.saturating_sub(t) <= SUPPLY_STALE_NS);
        if sys_status_fresh {
            return;
        }
        if let Some(r) = from_battery_status(b) {
            self.latest = Some((t_ns, r, Source::BatteryStatus));
        }
    }

    /// The supply as last reported, if younger than [`SUPPLY_STALE_NS`] at `now_ns`; the
    /// voltage unknown while it is a resting estimate.
    pub fn supply(&self, now_ns: u64) -> Supply {
        match self.latest {
            Some((t, r, _)) if now_ns.saturating_sub(t) <= SUPPLY_STALE_NS => Supply {
                voltage_v: (!self.resting_estimate()).then_some(r.voltage_v),
                current_a: r.current_a,
            },
            _ => Supply::default(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sys_status_in_millivolts_and_centiamps_with_unknowns() {
        let mut s = SYS_STATUS_DATA {
            voltage_battery: 15_870,
            current_battery: 1_234,
            ..SYS_STATUS_DATA::default()
        };
        let r = from_sys_status(&s).unwrap();
        assert!((r.voltage_v - 15.87).abs() < 1e-12);
        assert_eq!(r.current_a, Some(12.34));
        s.current_battery = -1;
        assert_eq!(from_sys_status(&s).unwrap().current_a, None);
        s.voltage_battery = u16::MAX;
        assert!(from_sys_status(&s).is_none());
        s.voltage_battery = 0;
        assert!(from_sys_status(&s).is_none());
    }

    #[test]
    fn battery_status_sums_the_used_cells_of_monitor_0() {
        let mut cells = [u16::MAX; 10];
        cells[..4].copy_from_slice(&[4_100, 4_050, 4_000, 4_150]);
        let mut b = BATTERY_STATUS_DATA {
            voltages: cells,
            current_battery: 500,
            id: 0,
            ..BATTERY_STATUS_DATA::default()
        };
        let r = from_battery_status(&b).unwrap();
        assert!((r.voltage_v - 16.3).abs() < 1e-12);
        assert_eq!(r.current_a, Some(5.0));
        // The pack voltage in the first cell, the rest unused.
        b.voltages = [u16::MAX; 10];
        b.voltages[0] = 14_200;
        assert!((from_battery_status(&b).unwrap().voltage_v - 14.2).abs() < 1e-12);
        b.id = 1;
        assert!(from_battery_status(&b).is_none());
        b.id = 0;
        b.voltages = [u16::MAX; 10];
        assert!(from_battery_status(&b).is_none());
    }

    #[test]
    fn sys_status_wins_over_cells_and_a_resting_estimate_is_not_the_esc_voltage() {
        use crate::backend::mavlink::params::tests::value;
        let mut t = SupplyTracker::default();
        // A 12-cell pack with cell monitoring: cells 11-14 are in voltages_ext, which the
        // crate does not decode; the 10 cells sum to 41 V, SYS_STATUS says 49.2 V.
        let mut cells = [4_100; 10];
        cells[9] = 4_100;
        let b = BATTERY_STATUS_DATA {
            voltages: cells,
            current_battery: 2_000,
            id: 0,
            ..BATTERY_STATUS_DATA::default()
        };
        let s = SYS_STATUS_DATA {
            voltage_battery: 49_200,
            current_battery: 2_000,
            ..SYS_STATUS_DATA::default()
        };
        t.on_battery_status(1, &b);
        assert_eq!(
            t.supply(1).voltage_v,
            Some(41.0),
            "cells alone: the best there is"
        );
        t.on_sys_status(2, &s);
        t.on_battery_status(3, &b);
        assert_eq!(t.supply(3).voltage_v, Some(49.2));
        // SYS_STATUS gone for longer than the stale time: the cells again.
        t.on_battery_status(3 + SUPPLY_STALE_NS + 1, &b);
        assert_eq!(t.supply(3 + SUPPLY_STALE_NS + 1).voltage_v, Some(41.0));
        // BATT_OPTIONS bit 6: the voltage is V + I R; unknown, the current still reported.
        t.options.link_up(0);
        t.on_sys_status(10, &s);
        assert_eq!(
            t.options.on_value(&value(BATT_OPTIONS, 64.0 + 2.0)),
            Some((BATT_OPTIONS, 66.0))
        );
        let why = t.not_the_esc_voltage().unwrap();
        assert!(why.contains("= 66") && why.contains("bit 6"), "{why}");
        assert_eq!(t.supply(10).voltage_v, None);
        assert_eq!(t.supply(10).current_a, Some(20.0));
        t.options.on_value(&value(BATT_OPTIONS, 2.0));
        assert_eq!(t.supply(10).voltage_v, Some(49.2));
        assert_eq!(t.supply(10 + SUPPLY_STALE_NS + 1), Supply::default());
    }
}
