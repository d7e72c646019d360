//! Which of the autopilot's barometers is in the water, without IO.
//!
//! ArduSub has up to three barometers and reports instance 0 as SCALED_PRESSURE and 1 as
//! SCALED_PRESSURE2 (`GCS_MAVLINK::send_scaled_pressure_instance`); instance 2 it never
//! reports (ArduSub's SCALED_PRESSURE3 carries its temperature sensor, with `press_abs` 0:
//! `GCS_MAVLINK_Sub::send_scaled_pressure3`). The instances are numbered in probe order,
//! onboard ones first, so the Bar30 is SCALED_PRESSURE2 on a board with one air barometer
//! (Navigator, Pixhawk 1) but instance 2 on a Cube (two onboard MS5611s): depth from
//! SCALED_PRESSURE2 there is the electronics tube's air, about 0 m whatever the depth, and a
//! depth hold on it dives. So the driver reads the barometers' device ids (`BARO1_DEVID`..
//! `BARO3_DEVID`, the values of this boot, 0 for an empty slot) and takes depth only from a
//! message whose instance is a water-pressure sensor.
//!
//! A device id (AP_HAL `DeviceStructure`) is bus type (bits 0-2), bus (3-7), address (8-15)
//! and the driver's device type (16-23; `AP_Baro_Backend::DevTypes`). ArduSub's water sensors
//! are the MS5837 (I2C 0x76) and the Keller LD (0x40), and every SITL barometer in a Sub
//! build. The MS5837's type has changed: MS5611's 0x0B before late 2022, then 0x12, then
//! 0x12 / 0x18 for the 30BA / 02BA; and master of mid-2025 stamps 0 (its type is set after
//! the id is, ArduPilot PR 34339). So an MS5837 is also recognised as type 0 at I2C 0x76,
//! and type 0x0B at I2C 0x76 (an old Bar30, or an onboard MS5611 on I2C) is "unknown": used
//! when named, not chosen on its own.

use super::params::ParamReader;
use crate::config::PressureMessage;

/// The barometers' device ids, instance 0..=2.
pub const PARAMS: [&str; 3] = ["BARO1_DEVID", "BARO2_DEVID", "BARO3_DEVID"];

/// What a barometer is, from its device id.
#[derive(Debug, Clone, PartialEq)]
pub enum BaroKind {
    /// No barometer in this slot on this boot.
    Absent,
    /// A water-pressure sensor (the part's name).
    Water(String),
    /// An air barometer (the part's name).
    Air(String),
    /// Not known to be either.
    Unknown(String),
}

const BUS_I2C: u32 = 1;
const BUS_SITL: u32 = 4;

/// `AP_Baro_Backend::DevTypes`, by value.
fn part(devtype: u32) -> Option<&'static str> {
    const NAMES: [&str; 24] = [
        "SITL",
        "BMP085",
        "BMP280",
        "BMP388",
        "DPS280",
        "DPS310",
        "FBM320",
        "ICM20789",
        "KellerLD",
        "LPS2XH",
        "MS5611",
        "SPL06",
        "DroneCAN",
        "MSP",
        "ICP101XX",
        "ICP201XX",
        "MS5607",
        "MS5837-30BA",
        "MS5637",
        "BMP390",
        "BMP581",
        "SPA06",
        "AUAV",
        "MS5837-02BA",
    ];
    let i = usize::try_from(devtype).ok()?.checked_sub(1)?;
    NAMES.get(i).copied()
}

/// What the barometer with this device id is.
pub fn kind(devid: u32) -> BaroKind {
    if devid == 0 {
        return BaroKind::Absent;
    }
    let (bus_type, address, devtype) = (devid & 0x7, (devid >> 8) & 0xff, (devid >> 16) & 0xff);
    let at = format!("bus type {bus_type}, address 0x{address:02x}");
    match (bus_type, address, devtype, part(devtype)) {
        (BUS_SITL, ..) => BaroKind::Water("SITL (water in a Sub build)".to_string()),
        (BUS_I2C, 0x76, 0, _) => BaroKind::Water("MS5837 (device type 0)".to_string()),
        (BUS_I2C, 0x76, 0x0b, _) => {
            BaroKind::Unknown("MS5611 type at I2C 0x76 (an older firmware's MS5837?)".to_string())
        }
        (_, _, 0x09 | 0x12 | 0x18, Some(p)) => BaroKind::Water(p.to_string()),
        (_, _, 0x0d | 0x0e, Some(p)) => BaroKind::Unknown(format!("{p} ({at})")),
        (_, _, _, Some(p)) => BaroKind::Air(p.to_string()),
        (_, _, _, None) => BaroKind::Unknown(format!("device type 0x{devtype:02x} ({at})")),
    }
}

/// The message that carries barometer `instance`, if ArduSub sends one.
fn message_of(instance: usize) -> Option<&'static str> {
    match instance {
        0 => Some("SCALED_PRESSURE"),
        1 => Some("SCALED_PRESSURE2"),
        _ => None,
    }
}

/// Which barometer instance the depth comes from, as far as the autopilot has told.
#[derive(Debug, Clone, PartialEq)]
pub struct WaterBaro {
    want: PressureMessage,
    /// The autopilot parameters this judges, read at each link-up ([`ParamReader`]).
    pub params: ParamReader<3>,
}

impl WaterBaro {
    pub fn new(want: PressureMessage) -> Self {
        WaterBaro {
            want,
            params: ParamReader::new(PARAMS),
        }
    }
    /// What barometer `i` is, if its id has come. ArduPilot sends an INT32 parameter as its
    /// value cast to float; device ids are under 2^24, exact in an f32.
    fn kind_of(&self, i: usize) -> Option<BaroKind> {
        self.params.known()[i].map(|v| kind(v.max(0.0) as u32))
    }

    /// The instance (0 or 1) whose message carries the depth, or why there is none now.
    pub fn verdict(&self) -> Result<usize, String> {
        match self.want {
            PressureMessage::Auto => self.auto(),
            PressureMessage::ScaledPressure => self.named(0),
            PressureMessage::ScaledPressure2 => self.named(1),
        }
    }

    /// The first water sensor, as ArduSub itself takes the first (`Sub::init_ardupilot`).
    fn auto(&self) -> Result<usize, String> {
        let mut seen = Vec::new();
        for (i, name) in PARAMS.iter().enumerate() {
            match self.kind_of(i) {
                None => return Err(format!("waiting for the autopilot's {name}")),
                Some(BaroKind::Water(p)) => {
                    return message_of(i).map(|_| i).ok_or_else(|| {
                        format!(
                            "the water sensor ({p}) is barometer {}, which ArduSub reports in \
                             no message",
                            i + 1
                        )
                    })
                }
                Some(BaroKind::Absent) => seen.push("none".to_string()),
                Some(BaroKind::Air(p) | BaroKind::Unknown(p)) => seen.push(p),
            }
        }
        Err(format!(
            "no water-pressure sensor among barometers 1-3 ({}): name one in pressure_message",
            seen.join(", ")
        ))
    }

    /// The configured instance, unless the autopilot says it is in the air or absent. Used
    /// unverified while its id has not come (an autopilot without the parameter).
    fn named(&self, i: usize) -> Result<usize, String> {
        let msg = message_of(i).unwrap_or("?");
        match self.kind_of(i) {
            Some(BaroKind::Air(p)) => Err(format!(
                "{msg} is barometer {}, an air barometer ({p}), not the water's",
                i + 1
            )),
            Some(BaroKind::Absent) => Err(format!("the autopilot has no barometer {}", i + 1)),
            _ => Ok(i),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::backend::mavlink::params::tests::{asked, value};

    /// A device id as `AP_HAL::Device::make_bus_id` builds it.
    fn devid(bus_type: u32, bus: u32, address: u32, devtype: u32) -> f32 {
        (bus_type | bus << 3 | address << 8 | devtype << 16) as f32
    }

    fn told(want: PressureMessage, ids: [Option<f32>; 3]) -> WaterBaro {
        let mut w = WaterBaro::new(want);
        w.params.link_up(0);
        for (name, id) in PARAMS.iter().zip(ids) {
            if let Some(id) = id {
                w.params.on_value(&value(name, id));
            }
        }
        w
    }

    #[test]
    fn device_ids_name_the_part_and_whether_it_is_in_the_water() {
        // A Bar30 on I2C bus 0 at 0x76 as ArduSub 4.5 stamps it: 0x127601.
        assert_eq!(devid(1, 0, 0x76, 0x12), 1_209_857.0);
        assert_eq!(kind(1_209_857), BaroKind::Water("MS5837-30BA".into()));
        assert_eq!(
            kind(devid(1, 2, 0x40, 0x09) as u32),
            BaroKind::Water("KellerLD".into())
        );
        assert_eq!(
            kind(devid(1, 6, 0x76, 0x18) as u32),
            BaroKind::Water("MS5837-02BA".into())
        );
        // Master of mid-2025: type 0 (set after the id).
        assert!(matches!(
            kind(devid(1, 6, 0x76, 0) as u32),
            BaroKind::Water(_)
        ));
        assert!(matches!(kind(devid(4, 0, 1, 1) as u32), BaroKind::Water(_)));
        // A Cube's onboard MS5611 on SPI; a Navigator's BMP280.
        assert_eq!(
            kind(devid(2, 1, 3, 0x0b) as u32),
            BaroKind::Air("MS5611".into())
        );
        assert_eq!(
            kind(devid(1, 1, 0x76, 0x03) as u32),
            BaroKind::Air("BMP280".into())
        );
        // Older firmware stamped the MS5837 as an MS5611: at 0x76 on I2C it may be either.
        assert!(matches!(
            kind(devid(1, 0, 0x76, 0x0b) as u32),
            BaroKind::Unknown(_)
        ));
        assert!(matches!(
            kind(devid(3, 0, 5, 0x0d) as u32),
            BaroKind::Unknown(_)
        ));
        assert!(matches!(
            kind(devid(1, 0, 0x50, 0x7f) as u32),
            BaroKind::Unknown(_)
        ));
        assert_eq!(kind(0), BaroKind::Absent);
    }

    #[test]
    fn auto_takes_the_first_water_sensor_ardusub_reports_and_says_why_not() {
        let bmp280 = Some(devid(1, 1, 0x76, 0x03));
        let ms5611 = Some(devid(2, 0, 1, 0x0b));
        let bar30 = Some(devid(1, 0, 0x76, 0x12));
        let auto = PressureMessage::Auto;
        // Navigator: BMP280 then the Bar30: SCALED_PRESSURE2.
        assert_eq!(told(auto, [bmp280, bar30, Some(0.0)]).verdict(), Ok(1));
        // Known as soon as the first water sensor is, whatever comes after.
        assert_eq!(told(auto, [bar30, None, None]).verdict(), Ok(0));
        let w = told(auto, [bmp280, None, None]).verdict().unwrap_err();
        assert_eq!(w, "waiting for the autopilot's BARO2_DEVID");
        // Cube: two MS5611s, the Bar30 third: reported in no message.
        let e = told(auto, [ms5611, ms5611, bar30]).verdict().unwrap_err();
        assert!(e.contains("barometer 3") && e.contains("no message"), "{e}");
        let e = told(auto, [ms5611, Some(0.0), Some(0.0)])
            .verdict()
            .unwrap_err();
        assert!(e.contains("(MS5611, none, none)"), "{e}");
        assert!(e.len() <= 100, "{} bytes: {e}", e.len());
    }

    #[test]
    fn a_named_message_is_refused_only_when_the_autopilot_says_it_is_air() {
        let ms5611 = Some(devid(2, 0, 1, 0x0b));
        let old_bar30 = Some(devid(1, 0, 0x76, 0x0b));
        let named = PressureMessage::ScaledPressure2;
        assert_eq!(
            told(named, [None, None, None]).verdict(),
            Ok(1),
            "unverified"
        );
        let e = told(named, [ms5611, ms5611, None]).verdict().unwrap_err();
        assert!(e.contains("SCALED_PRESSURE2") && e.contains("air"), "{e}");
        assert_eq!(told(named, [ms5611, old_bar30, None]).verdict(), Ok(1));
        let e = told(PressureMessage::ScaledPressure, [Some(0.0), None, None])
            .verdict()
            .unwrap_err();
        assert!(e.contains("no barometer 1"), "{e}");
    }

    #[test]
    fn the_three_ids_are_asked_for_at_link_up() {
        let mut w = WaterBaro::new(PressureMessage::Auto);
        let mut out = Vec::new();
        w.params.requests(0, 1, 1, &mut out);
        assert!(out.is_empty());
        w.params.link_up(7);
        w.params.requests(7, 1, 1, &mut out);
        assert_eq!(asked(&out, 1, 1), PARAMS);
        w.params.link_lost();
        assert!(w.verdict().is_err());
    }
}
