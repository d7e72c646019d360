//! What the Linux backend's outputs do when the driver stops running them: a loop stuck in a
//! sensor read (the stall guard's thread takes them neutral), and a driver killed outright
//! (`thruster-hw neutral`, the unit's ExecStopPost). The real process, fake sysfs.

mod common;

use std::fs;
use std::io::Write as _;
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use common::{Fixture, Harness, Linux, BIN, NEUTRAL};

const FULL: [u16; 4] = [1900, 1100, 1900, 1800];

/// Puts a FIFO where the gyro's x reading is: the driver's next read blocks in open(2) until
/// a writer comes, as a read from a hung I2C device blocks.
fn hang_the_gyro(root: &Path) -> std::path::PathBuf {
    let raw = root.join("bus/iio/devices/iio:device0/in_anglvel_x_raw");
    let fifo = raw.with_extension("fifo");
    let status = Command::new("mkfifo").arg(&fifo).status().unwrap();
    assert!(status.success(), "mkfifo");
    fs::rename(&fifo, &raw).unwrap();
    raw
}

/// Lets the blocked read through and puts a plain file back for the reads after it.
fn release_the_gyro(raw: &Path) {
    // The reader is blocked opening the FIFO, so this open does not block.
    let mut fifo = fs::OpenOptions::new().write(true).open(raw).unwrap();
    let plain = raw.with_extension("plain");
    fs::write(&plain, "0\n").unwrap();
    fs::rename(&plain, raw).unwrap();
    fifo.write_all(b"0\n").unwrap();
}

#[test]
fn a_sensor_read_that_hangs_leaves_the_outputs_neutral_and_commands_work_again_after_it() {
    let mut h = Harness::<Linux>::start(100, "");
    h.drive_to(&[1.0; 4], FULL);
    let raw = hang_the_gyro(h.fx.0.root());
    let t0 = Instant::now();
    // The loop is stuck: no samples, so no commands, and its own watchdog cannot run. Without
    // the guard the ESCs would hold FULL until systemd killed the process.
    h.wait_pulses(Duration::from_secs(3), |p| p == NEUTRAL);
    let took = t0.elapsed();
    let log = h.proc.log();
    assert!(log.contains("has not run for"), "{log}");
    assert!(
        h.daemon.try_sample(Duration::from_millis(100)).is_none(),
        "the loop was not stuck: a sample came"
    );
    eprintln!("neutral {took:?} after the read hung (watchdog_ms 200)");

    release_the_gyro(&raw);
    // Its watchdog expired meanwhile: the loop keeps neutral (nothing stale written back)...
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(
        h.fx.pulses().as_deref(),
        Some(&NEUTRAL[..]),
        "{}",
        h.proc.log()
    );
    // ...and the next commands drive the thrusters again.
    h.drive_to(&[1.0; 4], FULL);
    let (proc, _) = h.finish();
    assert!(
        proc.summary_value("watchdog_expiries") >= 1,
        "the loop's own watchdog should have seen the stale command\n{}",
        proc.log()
    );
}

#[test]
fn a_killed_driver_leaves_its_last_pulse_until_thruster_hw_neutral() {
    let mut h = Harness::<Linux>::start(100, "");
    h.drive_to(&[1.0; 4], FULL);
    h.proc.signal(libc::SIGKILL);
    let status = h.proc.wait_exit(Duration::from_secs(3)).expect("killed");
    assert_eq!(
        std::os::unix::process::ExitStatusExt::signal(&status),
        Some(libc::SIGKILL)
    );
    // What the kernel keeps: the last duty, with nobody left to change it.
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(h.fx.pulses().as_deref(), Some(&FULL[..]));

    let config = h.proc.dir().join("thruster-hw.toml");
    let out = Command::new(BIN)
        .args(["neutral", "--config"])
        .arg(&config)
        .output()
        .unwrap();
    let text =
        String::from_utf8_lossy(&out.stderr).to_string() + &String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}");
    assert_eq!(h.fx.pulses().as_deref(), Some(&NEUTRAL[..]), "{text}");
    for ch in Linux::CHANNELS {
        assert!(text.contains(&format!("pwm{ch}: neutral")), "{text}");
    }

    // A channel that cannot be written fails the command, naming it, after trying the rest.
    let chip = h.fx.0.chip();
    for ch in Linux::CHANNELS {
        fs::write(chip.join(format!("pwm{ch}/duty_cycle")), "1900000\n").unwrap();
    }
    let broken = chip.join(format!("pwm{}/duty_cycle", Linux::CHANNELS[0]));
    fs::remove_file(&broken).unwrap();
    fs::create_dir(&broken).unwrap();
    let out = Command::new(BIN)
        .args(["neutral", "--config"])
        .arg(&config)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{text}");
    assert!(text.contains(&broken.display().to_string()), "{text}");
    for (k, &ch) in Linux::CHANNELS.iter().enumerate().skip(1) {
        let duty = fs::read_to_string(chip.join(format!("pwm{ch}/duty_cycle"))).unwrap();
        assert_eq!(
            duty.trim(),
            format!("{}", NEUTRAL[k] as u64 * 1000),
            "pwm{ch}"
        );
    }
}

/// A pressure read that hangs (a conversion that never ends, an I2C bus held) costs the
/// depth only: it is read on its own thread, so the samples keep coming at the IMU's rate,
/// the commands keep reaching the outputs, and the depth comes back with the sensor. Read in
/// the loop, as before the audit against the kernel's drivers, it stopped the samples and the
/// stall guard took the thrusters neutral.
#[test]
fn a_pressure_read_that_hangs_costs_the_depth_only() {
    let mut h = Harness::<Linux>::start(100, "");
    h.drive_to(&[1.0; 4], FULL);
    let raw =
        h.fx.0
            .root()
            .join("bus/iio/devices/iio:device2/in_pressure_input");
    let fifo = raw.with_extension("fifo");
    assert!(Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap()
        .success());
    fs::rename(&fifo, &raw).unwrap();
    // A second of commands at full thrust while the pressure read hangs.
    let t0 = Instant::now();
    let (mut samples, mut without_depth) = (0, 0);
    while t0.elapsed() < Duration::from_secs(1) {
        let (s, _) = h.daemon.answer(&[1.0; 4]);
        samples += 1;
        if !s.has_depth() {
            without_depth += 1;
        }
        assert_eq!(
            h.fx.pulses().as_deref(),
            Some(&FULL[..]),
            "outputs left FULL"
        );
    }
    eprintln!("pressure read hung: {samples} samples in 1 s, {without_depth} without depth");
    // 100 Hz: about 100 samples; the depth goes stale 0.5 s after the last read.
    assert!(
        samples >= 80,
        "{samples} samples in 1 s with the pressure read hung"
    );
    assert!(
        (20..=70).contains(&without_depth),
        "{without_depth} of {samples} samples without depth"
    );
    let log = h.proc.log();
    assert!(
        !log.contains("has not run for"),
        "the stall guard fired\n{log}"
    );
    // The sensor answers again: depth is back.
    let mut writer = fs::OpenOptions::new().write(true).open(&raw).unwrap();
    let plain = raw.with_extension("plain");
    fs::write(&plain, format!("{}\n", common::fake_sysfs::SURFACE_KPA)).unwrap();
    fs::rename(&plain, &raw).unwrap();
    writer
        .write_all(format!("{}\n", common::fake_sysfs::SURFACE_KPA).as_bytes())
        .unwrap();
    drop(writer);
    let end = Instant::now() + Duration::from_secs(2);
    loop {
        let (s, _) = h.daemon.answer(&[1.0; 4]);
        if s.has_depth() {
            break;
        }
        assert!(Instant::now() < end, "no depth after the sensor came back");
    }
    h.finish();
}
