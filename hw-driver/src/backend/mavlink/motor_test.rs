//! MAV_CMD_DO_MOTOR_TEST as ArduSub reads it: which motor, which pulse.

use mavlink::dialects::ardupilotmega::{
    MavCmd, MavMessage, MotorTestOrder, MotorTestThrottleType, COMMAND_LONG_DATA,
};

use crate::core::pwm::Pwm;

/// DO_MOTOR_TEST param1 for the thruster on `channel` (config: 1-based, ArduSub's motor n,
/// i.e. the output whose `SERVOn_FUNCTION` is "Motor n", MAIN OUT n by default).
///
/// ArduSub's `Sub::handle_do_motor_test` passes param1 unchanged to
/// `AP_MotorsMatrix::output_test_num(output_channel, pwm)`, which indexes
/// `motor_enabled[output_channel]` and calls `rc_write(output_channel, pwm)`, and
/// `SRV_Channels::get_motor_function` maps that "zero-based motor channel" to k_motor1 +
/// channel: param1 = 0 is motor 1. Sending the 1-based channel drove motor n + 1 and had
/// the last motor of a frame refused. Source lines: docs/hardware.md.
pub fn ardusub_motor_index(channel: u32) -> f32 {
    channel.saturating_sub(1) as f32
}

/// One DO_MOTOR_TEST: `channel` is the 1-based motor (board output), the pulse in us.
pub fn motor_test(sys: u8, comp: u8, channel: u32, pwm: Pwm, timeout_s: f32) -> MavMessage {
    MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        param1: ardusub_motor_index(channel),
        param2: MotorTestThrottleType::MOTOR_TEST_THROTTLE_PWM as u32 as f32,
        param3: f32::from(pwm.us()),
        param4: timeout_s,
        param5: 0.0,
        param6: MotorTestOrder::MOTOR_TEST_ORDER_BOARD as u32 as f32,
        param7: 0.0,
        command: MavCmd::MAV_CMD_DO_MOTOR_TEST,
        target_system: sys,
        target_component: comp,
        confirmation: 0,
    })
}
