//! The supply voltage and current from ArduSub's battery reports, without IO.
//!
//! SYS_STATUS carries the first battery monitor's `voltage_battery` (mV, UINT16_MAX =
//! unknown) and `current_battery` (cA, -1 = unknown); BATTERY_STATUS carries per-monitor cell
//! voltages (mV each, UINT16_MAX = unused; ArduPilot puts the pack voltage in the first cell
//! when it does not measure cells, so the sum of the used entries is the pack voltage either
//! way) and `current_battery` (cA, -1 = unknown). ArduSub without a battery monitor
//! (`BATT_MONITOR = 0`) reports 0 V: taken as unknown, since no ESC runs at 0 V. Only
//! monitor 0 of BATTERY_STATUS is read: the one that powers the thrusters on a BlueROV2.

use mavlink::dialects::ardupilotmega::{BATTERY_STATUS_DATA, SYS_STATUS_DATA};

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
}
