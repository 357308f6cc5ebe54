//! The tty: the `serial:PATH[@BAUD]` argument, and the port opened raw, non-blocking and
//! exclusive, with poll, read and write.

use std::ffi::CString;
use std::io;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::time::{Duration, Instant};

use super::decoder::Decoder;
use super::protocol::DEFAULT_BAUD;
use crate::device::DeviceError;

/// How long a force packet may wait for room in the port's output buffer.
const WRITE_WAIT: Duration = Duration::from_millis(5);

/// Baud rates the port can be set to.
fn speed(baud: u32) -> Option<libc::speed_t> {
    Some(match baud {
        9600 => libc::B9600,
        19_200 => libc::B19200,
        38_400 => libc::B38400,
        57_600 => libc::B57600,
        115_200 => libc::B115200,
        230_400 => libc::B230400,
        #[cfg(any(target_os = "linux", target_os = "android"))]
        460_800 => libc::B460800,
        #[cfg(any(target_os = "linux", target_os = "android"))]
        500_000 => libc::B500000,
        #[cfg(any(target_os = "linux", target_os = "android"))]
        921_600 => libc::B921600,
        #[cfg(any(target_os = "linux", target_os = "android"))]
        1_000_000 => libc::B1000000,
        #[cfg(any(target_os = "linux", target_os = "android"))]
        2_000_000 => libc::B2000000,
        _ => return None,
    })
}

/// Splits the argument of `--device serial:ARG` into the path and the baud rate: `PATH` or
/// `PATH@BAUD`.
pub fn parse_serial_arg(arg: &str) -> Result<(&str, u32), DeviceError> {
    let bad = |why: String| DeviceError::BadSpec {
        given: format!("serial:{arg}"),
        why,
    };
    let (path, baud) = match arg.rsplit_once('@') {
        Some((_, "")) => return Err(bad("no baud rate after '@'".into())),
        Some((path, baud)) if baud.bytes().all(|c| c.is_ascii_digit()) => {
            let baud = baud
                .parse::<u32>()
                .map_err(|_| bad(format!("baud rate {baud} is too large")))?;
            (path, baud)
        }
        _ => (arg, DEFAULT_BAUD),
    };
    if path.is_empty() {
        return Err(bad("the serial device needs a path, e.g. serial:/dev/ttyACM0".into()));
    }
    if speed(baud).is_none() {
        return Err(bad(format!(
            "{baud} baud is not supported (9600, 19200, 38400, 57600, 115200, 230400; on Linux also 460800, 500000, 921600, 1000000, 2000000)"
        )));
    }
    Ok((path, baud))
}

/// The open port: raw, non-blocking, exclusive.
pub(super) struct Port {
    fd: OwnedFd,
    pub(super) device: String,
}

impl Port {
    pub(super) fn open(path: &str, baud: u32) -> Result<Port, DeviceError> {
        let device = format!("serial:{path}");
        let bad = |why: String| DeviceError::BadSpec {
            given: device.clone(),
            why,
        };
        let speed = speed(baud).ok_or_else(|| bad(format!("{baud} baud is not supported")))?;
        let cpath = CString::new(path).map_err(|_| bad("the path contains a NUL byte".into()))?;
        // SAFETY: a valid NUL-terminated path and plain flags.
        let raw = unsafe {
            libc::open(
                cpath.as_ptr(),
                libc::O_RDWR | libc::O_NOCTTY | libc::O_NONBLOCK | libc::O_CLOEXEC,
            )
        };
        if raw < 0 {
            return Err(DeviceError::Io {
                device,
                source: io::Error::last_os_error(),
            });
        }
        // SAFETY: `raw` is a file descriptor we just opened and own.
        let port = Port {
            fd: unsafe { OwnedFd::from_raw_fd(raw) },
            device,
        };
        port.configure(speed)?;
        Ok(port)
    }

    /// Raw mode at `speed`, no flow control, reads return at once; exclusive; stale bytes dropped.
    fn configure(&self, speed: libc::speed_t) -> Result<(), DeviceError> {
        let fd = self.fd.as_raw_fd();
        let step = |what: &str, rc: libc::c_int| {
            if rc == 0 {
                Ok(())
            } else {
                let e = io::Error::last_os_error();
                Err(self.io(io::Error::new(e.kind(), format!("{what}: {e}"))))
            }
        };
        // SAFETY: `t` is a plain C struct filled by tcgetattr before use; `fd` is open.
        unsafe {
            let mut t: libc::termios = std::mem::zeroed();
            step("not a terminal", libc::tcgetattr(fd, &mut t))?;
            libc::cfmakeraw(&mut t);
            // cfmakeraw leaves IXOFF: the driver would inject XON/XOFF bytes into the stream.
            t.c_iflag &= !(libc::IXOFF | libc::IXANY);
            t.c_cflag |= libc::CLOCAL | libc::CREAD;
            t.c_cflag &= !(libc::CRTSCTS | libc::CSTOPB | libc::PARENB);
            t.c_cc[libc::VMIN] = 0;
            t.c_cc[libc::VTIME] = 0;
            step("setting the input speed", libc::cfsetispeed(&mut t, speed))?;
            step("setting the output speed", libc::cfsetospeed(&mut t, speed))?;
            step("setting raw mode", libc::tcsetattr(fd, libc::TCSANOW, &t))?;
            step("taking the port exclusively", libc::ioctl(fd, libc::TIOCEXCL))?;
            step("flushing stale bytes", libc::tcflush(fd, libc::TCIOFLUSH))?;
        }
        Ok(())
    }

    fn io(&self, source: io::Error) -> DeviceError {
        DeviceError::Io {
            device: self.device.clone(),
            source,
        }
    }

    /// A port that fails once open is a lost device (hang-up, EIO, ENXIO, ENODEV: an unplugged
    /// cable, a board reset, a vanished path).
    fn lost(&self, why: impl std::fmt::Display) -> DeviceError {
        DeviceError::Lost {
            device: self.device.clone(),
            why: why.to_string(),
        }
    }

    /// Waits up to `timeout` for `events`; returns the events that happened. A hang-up or an error
    /// on the port is [`DeviceError::Lost`].
    pub(super) fn poll(&self, events: libc::c_short, timeout: Duration) -> Result<libc::c_short, DeviceError> {
        let ms = timeout.as_micros().div_ceil(1000).min(libc::c_int::MAX as u128) as libc::c_int;
        let mut pfd = libc::pollfd {
            fd: self.fd.as_raw_fd(),
            events,
            revents: 0,
        };
        loop {
            // SAFETY: one valid pollfd.
            if unsafe { libc::poll(&mut pfd, 1, ms) } >= 0 {
                break;
            }
            let e = io::Error::last_os_error();
            if e.kind() != io::ErrorKind::Interrupted {
                return Err(self.lost(e));
            }
        }
        if pfd.revents & (libc::POLLERR | libc::POLLHUP | libc::POLLNVAL) != 0 {
            return Err(self.lost("the device hung up (unplugged?)"));
        }
        Ok(pfd.revents)
    }

    /// Reads everything available into `decoder`. (With VMIN = VTIME = 0 a read returns 0 when
    /// nothing is there; a hang-up shows in `poll` or as an error: [`DeviceError::Lost`].)
    pub(super) fn read_into(&self, decoder: &mut Decoder) -> Result<(), DeviceError> {
        let mut buf = [0u8; 512];
        loop {
            // SAFETY: `buf` is valid for `buf.len()` bytes.
            let n = unsafe { libc::read(self.fd.as_raw_fd(), buf.as_mut_ptr().cast(), buf.len()) };
            if n > 0 {
                decoder.push(&buf[..n as usize]);
                continue;
            }
            if n == 0 {
                return Ok(());
            }
            let e = io::Error::last_os_error();
            match e.kind() {
                io::ErrorKind::Interrupted => continue,
                io::ErrorKind::WouldBlock => return Ok(()),
                _ => return Err(self.lost(e)),
            }
        }
    }

    /// Writes all of `bytes`, waiting at most [`WRITE_WAIT`] for room.
    pub(super) fn write_all(&self, bytes: &[u8]) -> Result<(), DeviceError> {
        let deadline = Instant::now() + WRITE_WAIT;
        let mut done = 0;
        while done < bytes.len() {
            let rest = &bytes[done..];
            // SAFETY: `rest` is valid for `rest.len()` bytes.
            let n = unsafe { libc::write(self.fd.as_raw_fd(), rest.as_ptr().cast(), rest.len()) };
            if n > 0 {
                done += n as usize;
                continue;
            }
            if n < 0 {
                let e = io::Error::last_os_error();
                match e.kind() {
                    io::ErrorKind::Interrupted => continue,
                    io::ErrorKind::WouldBlock => {}
                    _ => return Err(self.lost(e)),
                }
            }
            let now = Instant::now();
            if now >= deadline {
                return Err(self.io(io::Error::new(
                    io::ErrorKind::TimedOut,
                    "the device does not take its input (output buffer full)",
                )));
            }
            self.poll(libc::POLLOUT, deadline - now)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_serial_argument_is_a_path_with_an_optional_baud_rate() {
        assert_eq!(parse_serial_arg("/dev/ttyACM0").unwrap(), ("/dev/ttyACM0", 1_000_000));
        assert_eq!(
            parse_serial_arg("/dev/ttyUSB0@1000000").unwrap(),
            ("/dev/ttyUSB0", 1_000_000)
        );
        assert_eq!(
            parse_serial_arg("/dev/by-id/a@b").unwrap(),
            ("/dev/by-id/a@b", 1_000_000)
        );
        let e = |a: &str| parse_serial_arg(a).unwrap_err().to_string();
        assert!(e("/dev/ttyUSB0@").contains("no baud rate after '@'"));
        assert!(e("/dev/ttyUSB0@12345").contains("12345 baud is not supported"));
        assert!(e("/dev/ttyUSB0@99999999999").contains("too large"));
        assert!(e("@115200").contains("needs a path"));
        assert!(e("/dev/ttyUSB0@12345").contains("\"serial:/dev/ttyUSB0@12345\""));
    }
}
