//! The Linux backend in-process against fake sysfs trees: the nanosecond values and the
//! order of the PWM set-up writes, channels left by an earlier run, exports that never
//! appear, IIO scaling, device lookup, axes and polling rate.

mod common;

use std::time::{Duration, Instant};

use common::fake_sysfs::{FakeSysfs, Write, SURFACE_KPA};
use thruster_hw::backend::linux::{LinuxBackend, MAX_READ_FAILURES};
use thruster_hw::backend::{Backend, BackendError, OutputSpec, Waker};
use thruster_hw::clock::monotonic_ns;
use thruster_hw::config::LinuxConfig;
use thruster_hw::core::axes::AxisMap;
use thruster_hw::core::pwm::Pwm;

fn config(fake: &FakeSysfs) -> LinuxConfig {
    LinuxConfig {
        sysfs_root: fake.root().to_path_buf(),
        rate_hz: 100.0,
        gyro_device: "icm20602".into(),
        mag_device: Some("ak09916".into()),
        pressure_device: Some("iio:device2".into()),
        export_timeout_ms: 500,
        ..LinuxConfig::default()
    }
}

fn outputs() -> Vec<OutputSpec> {
    vec![
        OutputSpec {
            channel: 0,
            neutral: Pwm(1500),
        },
        OutputSpec {
            channel: 3,
            neutral: Pwm(1510),
        },
    ]
}

/// Writes seen by the fake kernel, once it has caught up with `n` of them.
fn writes_after(fake: &FakeSysfs, n: usize) -> Vec<Write> {
    let end = Instant::now() + Duration::from_secs(2);
    loop {
        let w = fake.writes();
        if w.len() >= n || Instant::now() >= end {
            return w;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

fn of(writes: &[Write], channel: Option<u32>) -> Vec<(String, String)> {
    writes
        .iter()
        .filter(|w| w.channel == channel)
        .map(|w| (w.attr.clone(), w.value.clone()))
        .collect()
}

fn pair(a: &str, v: &str) -> (String, String) {
    (a.to_string(), v.to_string())
}

#[test]
fn export_then_period_neutral_duty_enable_in_ns_and_only_changes_written() {
    let fake = FakeSysfs::new(true);
    let mut b = LinuxBackend::new(config(&fake), outputs());
    b.start(Waker::noop(), monotonic_ns()).unwrap();
    let w = writes_after(&fake, 8);
    assert_eq!(of(&w, None), [pair("export", "0"), pair("export", "3")]);
    assert_eq!(
        of(&w, Some(0)),
        [
            pair("period", "2621440"),
            pair("duty_cycle", "1500000"),
            pair("enable", "1")
        ]
    );
    assert_eq!(
        of(&w, Some(3)),
        [
            pair("period", "2621440"),
            pair("duty_cycle", "1510000"),
            pair("enable", "1")
        ]
    );
    assert_eq!(
        (fake.pulse_us(0), fake.pulse_us(3)),
        (Some(1500), Some(1510))
    );

    // One change at a time: the fake kernel reads a file when it sees the write, so two
    // quick writes to one file would both show the second value.
    b.write_outputs(&[Pwm(1750), Pwm(1400)], monotonic_ns())
        .unwrap();
    assert_eq!(writes_after(&fake, 10).len(), 10);
    b.write_outputs(&[Pwm(1750), Pwm(1400)], monotonic_ns())
        .unwrap();
    std::thread::sleep(Duration::from_millis(30));
    assert_eq!(
        fake.writes().len(),
        10,
        "unchanged pulses are not rewritten"
    );
    b.write_outputs(&[Pwm(1750), Pwm(1100)], monotonic_ns())
        .unwrap();
    let w = writes_after(&fake, 11);
    let duty = |ch| -> Vec<String> {
        of(&w, Some(ch))
            .into_iter()
            .filter(|(a, _)| a == "duty_cycle")
            .map(|(_, v)| v)
            .collect()
    };
    assert_eq!(
        duty(0),
        ["1500000", "1750000"],
        "unchanged pulses are not rewritten"
    );
    assert_eq!(duty(3), ["1510000", "1400000", "1100000"]);

    b.stop().unwrap();
    assert_eq!(
        (fake.pulse_us(0), fake.pulse_us(3)),
        (Some(1500), Some(1510))
    );
    let enable = std::fs::read_to_string(fake.chip().join("pwm3/enable")).unwrap();
    assert_eq!(
        enable.trim(),
        "1",
        "the pulse train goes on at neutral after stop"
    );
}

#[test]
fn a_channel_left_with_a_long_duty_gets_neutral_before_the_shorter_period() {
    let fake = FakeSysfs::new(true);
    fake.pre_export(0, 20_000_000, 10_000_000, true);
    fake.pre_export(3, 20_000_000, 1_000_000, true);
    std::thread::sleep(Duration::from_millis(80)); // the fake kernel picks them up
                                                   // Whether the fake's watcher saw those set-up writes depends on when it added its watch
                                                   // on the new channel folders (a loaded machine saw them): only the backend's count.
    fake.clear_writes();
    let mut b = LinuxBackend::new(config(&fake), outputs());
    b.start(Waker::noop(), monotonic_ns()).unwrap();
    let w = writes_after(&fake, 6);
    assert!(of(&w, None).is_empty(), "already exported: no export write");
    // 10 ms duty > 2.5 ms period: the kernel would refuse the period first.
    assert_eq!(
        of(&w, Some(0)),
        [
            pair("duty_cycle", "1500000"),
            pair("period", "2621440"),
            pair("enable", "1")
        ]
    );
    assert_eq!(
        of(&w, Some(3)),
        [
            pair("period", "2621440"),
            pair("duty_cycle", "1510000"),
            pair("enable", "1")
        ]
    );
}

#[test]
fn an_export_that_never_appears_times_out_naming_the_file() {
    let fake = FakeSysfs::new(false);
    let cfg = LinuxConfig {
        export_timeout_ms: 100,
        ..config(&fake)
    };
    let mut b = LinuxBackend::new(cfg, outputs());
    let t = Instant::now();
    let e = b.start(Waker::noop(), monotonic_ns()).unwrap_err();
    assert!(matches!(e, BackendError::Timeout(_)), "{e}");
    assert!(e.to_string().contains("pwm0/enable"), "{e}");
    assert!(t.elapsed() < Duration::from_secs(1));
}

#[test]
fn missing_chip_or_device_fails_before_any_output_is_touched() {
    let fake = FakeSysfs::new(true);
    let cfg = LinuxConfig {
        pwm_chip: 3,
        ..config(&fake)
    };
    let e = LinuxBackend::new(cfg, outputs())
        .start(Waker::noop(), monotonic_ns())
        .unwrap_err();
    assert!(e.to_string().contains("pwmchip3"), "{e}");
    let cfg = LinuxConfig {
        mag_device: Some("hmc5883".into()),
        ..config(&fake)
    };
    let e = LinuxBackend::new(cfg, outputs())
        .start(Waker::noop(), monotonic_ns())
        .unwrap_err();
    assert!(e.to_string().contains("hmc5883"), "{e}");
    std::thread::sleep(Duration::from_millis(50));
    assert!(fake.writes().is_empty(), "{:?}", fake.writes());
}

#[test]
fn iio_values_are_scaled_rotated_to_frd_and_converted_to_si() {
    let fake = FakeSysfs::new(true);
    fake.set_imu(
        [0.1, -0.2, 0.3],
        [0.5, -0.3, -9.81],
        [20.0, -5.0, 40.0],
        3.0,
    );
    let mut b = LinuxBackend::new(config(&fake), outputs());
    let t0 = monotonic_ns();
    b.start(Waker::noop(), t0).unwrap();
    let r = b
        .read_sensors(t0)
        .unwrap()
        .expect("a reading is due at start");
    assert!(r.t_ns >= t0 && r.t_ns - t0 < 50_000_000);
    let close = |got: [f64; 3], want: [f64; 3], tol: f64| {
        for k in 0..3 {
            assert!((got[k] - want[k]).abs() <= tol, "{got:?} vs {want:?}");
        }
    };
    close(r.gyro, [0.1, -0.2, 0.3], 1e-4);
    close(r.accel, [0.5, -0.3, -9.81], 6e-4);
    close(r.mag.unwrap(), [20.0, -5.0, 40.0], 0.15);
    assert!((r.depth.unwrap() - 3.0).abs() < 1e-5);
    // The raw files hold the sensor frame (face-up chip: z up), so body z = -raw z.
    let raw_z: f64 = std::fs::read_to_string(
        fake.root()
            .join("bus/iio/devices/iio:device0/in_accel_z_raw"),
    )
    .unwrap()
    .trim()
    .parse()
    .unwrap();
    assert!(raw_z > 0.0, "a face-up accelerometer reads +g on its z");
    // Not due again before one period (10 ms at 100 Hz).
    assert_eq!(b.read_sensors(t0 + 5_000_000).unwrap(), None);
    assert_eq!(b.next_deadline_ns(), Some(t0 + 10_000_000));
    assert!(b.read_sensors(t0 + 10_000_000).unwrap().is_some());
    let _ = SURFACE_KPA;
}

#[test]
fn the_supply_voltage_comes_from_an_optional_iio_channel_through_the_divider() {
    let fake = FakeSysfs::new(true);
    fake.set_imu([0.0; 3], [0.0, 0.0, -9.81], [0.0; 3], 0.0);
    // An ADS1115 at 0.125 mV per count behind an 11:1 divider: 11,000 counts = 1375 mV at
    // the ADC = 15.125 V of supply.
    let adc = fake.root().join("bus/iio/devices/iio:device5");
    std::fs::create_dir_all(&adc).unwrap();
    std::fs::write(adc.join("name"), "ads1115\n").unwrap();
    std::fs::write(adc.join("in_voltage1_raw"), "11000\n").unwrap();
    std::fs::write(adc.join("in_voltage_scale"), "0.125\n").unwrap();
    let cfg = LinuxConfig {
        supply_device: Some("ads1115".into()),
        supply_channel: 1,
        supply_gain: 11.0,
        ..config(&fake)
    };
    let mut b = LinuxBackend::new(cfg.clone(), outputs());
    let t0 = monotonic_ns();
    b.start(Waker::noop(), t0).unwrap();
    // Read on the slow sensors' thread, whose first value `start` waits for.
    let v = b
        .supply(monotonic_ns())
        .voltage_v
        .expect("read by the end of start");
    assert!((v - 15.125).abs() < 1e-9, "{v}");
    assert_eq!(
        b.supply(monotonic_ns()).current_a,
        None,
        "no current channel"
    );
    // The ADC gone: the last reading goes stale a second after it was read (read every
    // 100 ms), the driver goes on.
    std::fs::remove_file(adc.join("in_voltage1_raw")).unwrap();
    let gone = std::time::Instant::now();
    let stale_after = loop {
        b.read_sensors(monotonic_ns()).unwrap();
        if b.supply(monotonic_ns()).voltage_v.is_none() {
            break gone.elapsed();
        }
        assert!(gone.elapsed() < Duration::from_secs(5), "never went stale");
        std::thread::sleep(Duration::from_millis(10));
    };
    assert!(
        stale_after >= Duration::from_millis(890),
        "stale {stale_after:?} after the ADC went"
    );
    drop(b);
    // Configured but absent: refused at start, naming the file.
    let mut b = LinuxBackend::new(cfg, outputs());
    let err = b.start(Waker::noop(), t0).unwrap_err().to_string();
    assert!(err.contains("in_voltage1_raw"), "{err}");
    // Not configured: unknown, as before.
    let mut b = LinuxBackend::new(config(&fake), outputs());
    b.start(Waker::noop(), t0).unwrap();
    b.read_sensors(t0).unwrap();
    assert_eq!(b.supply(t0).voltage_v, None);
}

/// The raw files of `kind` on iio:device0, as numbers.
fn raw3(fake: &FakeSysfs, kind: &str) -> [f64; 3] {
    let dir = fake.root().join("bus/iio/devices/iio:device0");
    ["x", "y", "z"].map(|axis| {
        std::fs::read_to_string(dir.join(format!("in_{kind}_{axis}_raw")))
            .unwrap()
            .trim()
            .parse()
            .unwrap()
    })
}

#[test]
fn a_chip_the_device_tree_mounts_rotated_reads_in_body_axes_through_the_kernels_matrix() {
    let fake = FakeSysfs::new(true);
    let (gyro, accel) = ([0.1, -0.2, 0.3], [0.5, -0.3, -9.81]);
    fake.set_imu(gyro, accel, [0.0; 3], 0.0);
    // The chip turned 90 deg about the board's z on the board: board = M chip, so the chip
    // reads chip = M^T board. inv_mpu6050 shows M per channel type, the device tree's
    // strings verbatim.
    let m = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]];
    let dir = fake.root().join("bus/iio/devices/iio:device0");
    for kind in ["anglvel", "accel"] {
        let board = raw3(&fake, kind);
        let chip: [f64; 3] = std::array::from_fn(|j| (0..3).map(|i| m[i][j] * board[i]).sum());
        for (axis, v) in ["x", "y", "z"].iter().zip(chip) {
            std::fs::write(dir.join(format!("in_{kind}_{axis}_raw")), format!("{v}\n")).unwrap();
        }
        std::fs::write(
            dir.join(format!("in_{kind}_mount_matrix")),
            "0, -1, 0; 1, 0, 0; 0, 0, 1\n",
        )
        .unwrap();
    }
    let close =
        |got: [f64; 3], want: [f64; 3], tol: f64| (0..3).all(|k| (got[k] - want[k]).abs() <= tol);
    let read = || {
        let mut b = LinuxBackend::new(config(&fake), outputs());
        let t0 = monotonic_ns();
        b.start(Waker::noop(), t0).unwrap();
        b.read_sensors(t0).unwrap().unwrap()
    };
    let r = read();
    assert!(close(r.gyro, gyro, 1e-4), "{:?}", r.gyro);
    assert!(close(r.accel, accel, 6e-4), "{:?}", r.accel);
    // Without the kernel's matrix the same chip reads its own axes: x and y swapped.
    for kind in ["anglvel", "accel"] {
        std::fs::remove_file(dir.join(format!("in_{kind}_mount_matrix"))).unwrap();
    }
    let r = read();
    assert!(!close(r.accel, accel, 0.1), "{:?}", r.accel);
    assert!(close(r.accel, [0.3, 0.5, -9.81], 6e-4), "{:?}", r.accel);
    // A matrix that is not a rotation stops the start, naming the file.
    std::fs::write(dir.join("in_mount_matrix"), "1, 0, 0; 0, 1, 0; 0, 0, 2\n").unwrap();
    let mut b = LinuxBackend::new(config(&fake), outputs());
    let err = b
        .start(Waker::noop(), monotonic_ns())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("in_mount_matrix") && err.contains("not a rotation"),
        "{err}"
    );
}

#[test]
fn a_bar30_read_with_the_2_bar_formula_is_refused_at_start_and_multiplied_when_configured() {
    use thruster_hw::config::PressureFormula;
    let fake = FakeSysfs::new(true);
    let p = fake
        .root()
        .join("bus/iio/devices/iio:device2/in_pressure_input");
    // What mainline `ms5637` reports for a Bar30 at 3 m: 1/20 of the pressure, as
    // "%d.%06u" kPa.
    let kpa_at = |depth_m: f64| SURFACE_KPA + depth_m * 997.0 * 9.80665 / 1000.0;
    std::fs::write(&p, format!("{:.6}\n", kpa_at(3.0) / 20.0)).unwrap();
    let mut b = LinuxBackend::new(config(&fake), outputs());
    let err = b
        .start(Waker::noop(), monotonic_ns())
        .unwrap_err()
        .to_string();
    for says in [
        "iio:device2",
        "below 30 kPa",
        "pressure_formula = \"bar30_read_as_02ba\"",
    ] {
        assert!(err.contains(says), "{says}: {err}");
    }
    assert!(fake.pulse_us(0).is_none(), "no output touched");
    drop(b);
    let cfg = LinuxConfig {
        pressure_formula: PressureFormula::Bar30ReadAs02ba,
        ..config(&fake)
    };
    let mut b = LinuxBackend::new(cfg, outputs());
    let t0 = monotonic_ns();
    b.start(Waker::noop(), t0).unwrap();
    let depth = b.read_sensors(t0).unwrap().unwrap().depth.unwrap();
    assert!((depth - 3.0).abs() < 1e-4, "{depth}");
    // A pressure gone implausible later costs the depth only, counted.
    std::fs::write(&p, "0.000000\n").unwrap();
    let gone = Instant::now();
    let mut t = t0;
    loop {
        t += 10_000_000;
        std::thread::sleep(Duration::from_millis(10));
        match b.read_sensors(t.max(monotonic_ns())).unwrap() {
            Some(r) if r.depth.is_none() => break,
            _ => assert!(gone.elapsed() < Duration::from_secs(3), "depth kept"),
        }
    }
    let refused = b.stats().into_iter().find(|(k, _)| *k == "depth_refused");
    assert!(matches!(refused, Some((_, n)) if n >= 1), "{refused:?}");
}

#[test]
fn configured_axes_and_no_optional_sensors() {
    let fake = FakeSysfs::new(true);
    fake.set_imu([0.1, -0.2, 0.3], [0.0, 0.0, -9.81], [0.0; 3], 0.0);
    let names = ["y".to_string(), "x".to_string(), "-z".to_string()];
    let cfg = LinuxConfig {
        imu_axes: AxisMap::parse(&names).unwrap(),
        mag_device: None,
        pressure_device: None,
        ..config(&fake)
    };
    let mut b = LinuxBackend::new(cfg, outputs());
    let t0 = monotonic_ns();
    b.start(Waker::noop(), t0).unwrap();
    let r = b.read_sensors(t0).unwrap().unwrap();
    // Sensor frame holds [0.1, 0.2, -0.3] (x, -y, -z of the body values written).
    for (g, want) in r.gyro.iter().zip([0.2, 0.1, 0.3]) {
        assert!((g - want).abs() < 1e-4, "{:?}", r.gyro);
    }
    assert_eq!((r.mag, r.depth), (None, None));
}

#[test]
fn sensor_read_failures_skip_samples_then_fail_the_backend() {
    let fake = FakeSysfs::new(true);
    let mut b = LinuxBackend::new(config(&fake), outputs());
    let mut t = monotonic_ns();
    b.start(Waker::noop(), t).unwrap();
    assert!(b.read_sensors(t).unwrap().is_some());
    let raw = fake
        .root()
        .join("bus/iio/devices/iio:device0/in_anglvel_y_raw");
    std::fs::write(&raw, "garbage\n").unwrap();
    for _ in 0..MAX_READ_FAILURES {
        t += 10_000_000;
        assert_eq!(
            b.read_sensors(t).unwrap(),
            None,
            "a bad read skips one sample"
        );
    }
    // A good read resets the count...
    std::fs::write(&raw, "5\n").unwrap();
    t += 10_000_000;
    assert!(b.read_sensors(t).unwrap().is_some());
    // ...and a sensor that stays broken fails the backend.
    std::fs::remove_file(&raw).unwrap();
    let mut err = None;
    for _ in 0..=MAX_READ_FAILURES {
        t += 10_000_000;
        if let Err(e) = b.read_sensors(t) {
            err = Some(e);
        }
    }
    let e = err.expect("fails after MAX_READ_FAILURES").to_string();
    assert!(e.contains("in_anglvel_y_raw"), "{e}");
}

#[test]
fn a_failing_output_ends_the_process_with_the_other_outputs_neutral() {
    use common::{assert_namespace_clean, Fixture, Harness, Linux, NEUTRAL};
    let mut h = Harness::<Linux>::start(100, "");
    h.drive_to(&[1.0; 4], [1900, 1100, 1900, 1800]);
    // The first thruster's PWM channel disappears (driver unbound, cable to the PCA9685...).
    std::fs::remove_dir_all(h.fx.0.chip().join(format!("pwm{}", Linux::CHANNELS[0]))).unwrap();
    let _ = h.daemon.answer(&[0.5; 4]);
    let status = h
        .proc
        .wait_exit(Duration::from_secs(3))
        .expect("the driver exits");
    assert_eq!(status.code(), Some(1), "{}", h.proc.log());
    let log = h.proc.log();
    assert!(log.contains("pwm0/duty_cycle"), "{log}");
    for (k, &ch) in Linux::CHANNELS.iter().enumerate().skip(1) {
        assert_eq!(h.fx.0.pulse_us(ch), Some(NEUTRAL[k]), "thruster {k}\n{log}");
    }
    let common::Harness { daemon, ns, .. } = h;
    drop(daemon);
    assert_namespace_clean(&ns);
}

#[test]
fn the_stall_guard_takes_a_silent_loops_outputs_neutral_and_gives_a_slow_one_its_own_back() {
    let limit = Duration::from_millis(300);
    let fake = FakeSysfs::new(true);
    let mut b = LinuxBackend::new(config(&fake), outputs()).with_stall_guard(limit);
    let t = monotonic_ns();
    b.start(Waker::noop(), t).unwrap();
    b.write_outputs(&[Pwm(1900), Pwm(1100)], t).unwrap();
    let pulses = |f: &FakeSysfs| (f.pulse_us(0), f.pulse_us(3));
    // A loop that calls in keeps its outputs.
    let end = Instant::now() + Duration::from_millis(600);
    let mut silent = Instant::now();
    while Instant::now() < end {
        std::thread::sleep(Duration::from_millis(10));
        b.service(monotonic_ns()).unwrap();
        silent = Instant::now();
        assert_eq!(pulses(&fake), (Some(1900), Some(1100)));
    }
    // A silent one gets neutral, not before the limit.
    let end = silent + Duration::from_secs(3);
    while pulses(&fake) != (Some(1500), Some(1510)) {
        assert!(Instant::now() < end, "not neutral: {:?}", pulses(&fake));
        std::thread::sleep(Duration::from_millis(2));
    }
    assert!(
        silent.elapsed() >= limit,
        "neutral after {:?}",
        silent.elapsed()
    );
    // It was only slow: the end of its next round writes what it had again, though its
    // outputs did not change (so it wrote none itself).
    b.service(monotonic_ns()).unwrap();
    assert_eq!(pulses(&fake), (Some(1900), Some(1100)));
    // Stopped (the guard's thread joined first): neutral, and it stays so.
    b.stop().unwrap();
    std::thread::sleep(limit * 2);
    assert_eq!(pulses(&fake), (Some(1500), Some(1510)));
}

/// The fake holds writes to the kernel's rules (drivers/pwm/core.c: `export_store`,
/// `__pwm_apply`, the attribute stores), so a driver order the kernel refuses fails every
/// test that runs it. Each write waits for the fake to see it: it reads the file after the
/// event, and two quick writes to one file would read as the second twice.
#[test]
fn the_fake_kernel_refuses_what_the_kernel_refuses() {
    let fake = FakeSysfs::new(true);
    fake.expect_refusals();
    let chip = fake.chip();
    let ch = chip.join("pwm2");
    let steps: [(std::path::PathBuf, &str); 11] = [
        (chip.join("export"), "16"),
        (chip.join("export"), "2"),
        (chip.join("export"), "2"),
        (ch.join("duty_cycle"), "1000"),
        (ch.join("period"), "2000"),
        (ch.join("duty_cycle"), "3000"),
        (ch.join("duty_cycle"), "1000"),
        (ch.join("period"), "500"),
        (ch.join("enable"), "2"),
        (ch.join("polarity"), "reversed"),
        (ch.join("enable"), "1"),
    ];
    for (i, (path, value)) in steps.iter().enumerate() {
        if i == 3 {
            // The export's channel appears a moment later.
            let end = Instant::now() + Duration::from_secs(2);
            while !ch.join("enable").exists() && Instant::now() < end {
                std::thread::sleep(Duration::from_millis(5));
            }
        }
        std::fs::write(path, format!("{value}\n")).unwrap();
        let seen = writes_after(&fake, i + 1).len();
        assert_eq!(seen, i + 1, "the fake saw write {i} ({value})");
    }
    let refusals = fake.refusals();
    let starts: Vec<&str> = refusals
        .iter()
        .map(|r| r.split(':').next().unwrap())
        .collect();
    assert_eq!(
        starts,
        [
            "export = 16",
            "export = 2",
            "pwm2/duty_cycle = 1000",
            "pwm2/duty_cycle = 3000",
            "pwm2/period = 500",
            "pwm2/enable = \"2\"",
            "pwm2/polarity = \"reversed\"",
        ],
        "{refusals:#?}"
    );
    assert!(refusals[0].contains("ENODEV") && refusals[1].contains("EBUSY"));
    assert!(
        refusals[4].contains("duty 1000 ns of period 500 ns"),
        "{}",
        refusals[4]
    );
}
