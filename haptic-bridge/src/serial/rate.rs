//! The device cycle's rate, negotiated with a device and its link.

use super::port::parse_serial_arg;
use super::protocol::{EXCHANGE_BYTES, LINK_SHARE, MIN_RATE_HZ, exchange_wire_time, link_rate_limit_hz};
use crate::device::Device;

/// The device cycle's rate: `wanted` (`--rate-hz`), lowered to what the device declares and its
/// link carries ([`Device::max_rate_hz`]), never below [`MIN_RATE_HZ`]. `serial_arg` is the
/// `PATH[@BAUD]` of a serial device, to name the numbers. Returns the rate and, when it is below
/// `wanted`, why; refuses (with the numbers) a device that cannot carry the floor.
pub fn negotiate_rate(
    device: &dyn Device,
    serial_arg: Option<&str>,
    wanted: f64,
) -> Result<(f64, Option<String>), String> {
    let Some(limit) = device.max_rate_hz() else {
        return Ok((wanted, None));
    };
    let parsed = match serial_arg {
        Some(arg) => Some(parse_serial_arg(arg).map_err(|e| e.to_string())?),
        None => None,
    };
    let why = match parsed {
        Some((path, baud)) => {
            format!(
                "serial:{path} at {baud} baud: a {EXCHANGE_BYTES}-byte exchange takes {:.2} ms on the wire, so at most {:.0} Hz ({:.0} % of the link); the device declares {:.0} Hz",
                exchange_wire_time(baud).as_secs_f64() * 1e3,
                link_rate_limit_hz(baud),
                LINK_SHARE * 100.0,
                device.declared_rate_hz().unwrap_or(f64::NAN),
            )
        }
        None => format!("the device carries at most {limit:.0} Hz"),
    };
    if limit < MIN_RATE_HZ {
        let fix = match parsed {
            // The link is what limits it: a faster baud.
            Some((path, baud)) if link_rate_limit_hz(baud) < MIN_RATE_HZ => format!(
                ": open serial:{path}@1000000 with BAUD = 1000000 in the sketch, or use a board whose MCU speaks USB itself"
            ),
            // The device's own rate is what limits it.
            Some(_) => ": raise the control rate the device declares (its info packet) to at least 500 Hz".to_string(),
            None => String::new(),
        };
        return Err(format!(
            "{why}; the floor is {MIN_RATE_HZ:.0} Hz (the server declares the haptic link down when its newest handle sample is 5 ms old){fix}"
        ));
    }
    if limit < wanted {
        let rate = limit.floor();
        return Ok((
            rate,
            Some(format!("{why}: running at {rate:.0} Hz, below --rate-hz {wanted}")),
        ));
    }
    Ok((wanted, None))
}
