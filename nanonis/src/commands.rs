//! The commands nanopush sends, each with its body as the vendor's protocol manual lays it out
//! (big-endian; booleans `u32`; `ZCtrl.StatusGet` answers a `u16`, `Scan.Action` sends its action
//! as a `u16`). Every function is one call on one connection.

use std::time::Duration;

use nanopush_instrument::afm::MicroscopeError;
use nanopush_proto::nanonis::{BodyReader, BodyWriter, FrameError};

use crate::client::Connection;

/// The most signals a controller names (`Signals.NamesGet`).
pub const MAX_SIGNALS: usize = 128;
/// The largest image side `Scan.FrameDataGrab` is read with (pixels).
pub const MAX_PIXELS: usize = 8192;

fn none(_: &mut BodyReader<'_>) -> Result<(), FrameError> {
    Ok(())
}

fn body(f: impl FnOnce(&mut BodyWriter)) -> Vec<u8> {
    let mut w = BodyWriter::new();
    f(&mut w);
    w.into_bytes()
}

/// `FolMe.XYPosSet`: moves the tip to `(x, y)` (m); returns at once unless `wait`.
pub fn xy_pos_set(c: &mut Connection, x: f64, y: f64, wait: bool) -> Result<(), MicroscopeError> {
    let b = body(|w| {
        w.f64(x).f64(y).u32(wait.into());
    });
    c.call("FolMe.XYPosSet", &b, None, none)
}

/// `FolMe.XYPosGet`: the tip's `(x, y)` (m).
pub fn xy_pos_get(c: &mut Connection) -> Result<(f64, f64), MicroscopeError> {
    let b = body(|w| {
        w.u32(0);
    });
    c.call("FolMe.XYPosGet", &b, None, |r| Ok((r.f64("X (m)")?, r.f64("Y (m)")?)))
}

/// `FolMe.SpeedSet`: the Follow Me speed (m/s), as a custom speed.
pub fn speed_set(c: &mut Connection, speed: f64) -> Result<(), MicroscopeError> {
    let b = body(|w| {
        w.f32(speed as f32).u32(1);
    });
    c.call("FolMe.SpeedSet", &b, None, none)
}

/// `FolMe.Stop`: stops a Follow Me motion.
pub fn folme_stop(c: &mut Connection) -> Result<(), MicroscopeError> {
    c.call("FolMe.Stop", &[], None, none)
}

/// `ZCtrl.OnOffSet`: the Z controller on or off.
pub fn z_on_off_set(c: &mut Connection, on: bool) -> Result<(), MicroscopeError> {
    let b = body(|w| {
        w.u32(on.into());
    });
    c.call("ZCtrl.OnOffSet", &b, None, none)
}

/// `ZCtrl.SetpntSet`: the Z controller's set point (the units of its signal: V of deflection).
pub fn setpoint_set(c: &mut Connection, setpoint: f64) -> Result<(), MicroscopeError> {
    let b = body(|w| {
        w.f32(setpoint as f32);
    });
    c.call("ZCtrl.SetpntSet", &b, None, none)
}

/// `ZCtrl.Withdraw`: switches the Z controller off and retracts the tip, waiting up to
/// `timeout` for it to finish.
pub fn withdraw(c: &mut Connection, timeout: Duration) -> Result<(), MicroscopeError> {
    let ms = timeout.as_millis().min(i32::MAX as u128) as i32;
    let b = body(|w| {
        w.u32(1).i32(ms);
    });
    c.call("ZCtrl.Withdraw", &b, Some(timeout + Duration::from_secs(1)), none)
}

/// The Z controller's state, as `ZCtrl.StatusGet` reports it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ZStatus {
    /// 1: off.
    Off,
    /// 2: on, holding the set point.
    On,
    /// 3: holding Z.
    Hold,
    /// 4: switching off.
    SwitchingOff,
    /// 5: a safe-tip event.
    SafeTip,
    /// 6: withdrawing.
    Withdrawing,
}

/// `ZCtrl.StatusGet`.
pub fn z_status(c: &mut Connection) -> Result<ZStatus, MicroscopeError> {
    let code = c.call("ZCtrl.StatusGet", &[], None, |r| r.u16("Z-controller status"))?;
    Ok(match code {
        1 => ZStatus::Off,
        2 => ZStatus::On,
        3 => ZStatus::Hold,
        4 => ZStatus::SwitchingOff,
        5 => ZStatus::SafeTip,
        6 => ZStatus::Withdrawing,
        other => {
            return Err(MicroscopeError::Controller {
                command: "ZCtrl.StatusGet".into(),
                message: format!("status {other} is not one of the protocol's 1-6"),
            });
        }
    })
}

/// `ZCtrl.LimitsGet`: the Z range `[low, high]` (m).
pub fn z_limits(c: &mut Connection) -> Result<[f64; 2], MicroscopeError> {
    let (high, low) = c.call("ZCtrl.LimitsGet", &[], None, |r| {
        Ok((r.f32("Z high limit (m)")?, r.f32("Z low limit (m)")?))
    })?;
    Ok([f64::from(low), f64::from(high)])
}

/// `Signals.NamesGet`: every signal's name, its index its place.
pub fn signal_names(c: &mut Connection) -> Result<Vec<String>, MicroscopeError> {
    c.call("Signals.NamesGet", &[], None, |r| {
        let _bytes = r.count("signal names size", nanopush_proto::nanonis::MAX_BODY_BYTES)?;
        let n = r.count("signal names count", MAX_SIGNALS)?;
        r.strings("signal name", n)
    })
}

/// `Signals.ValsGet`: several signals' values now.
pub fn signal_values(c: &mut Connection, indexes: &[usize]) -> Result<Vec<f64>, MicroscopeError> {
    let idx: Vec<i32> = indexes.iter().map(|&i| i as i32).collect();
    let b = body(|w| {
        w.i32(idx.len() as i32).i32s(&idx).u32(0);
    });
    let values = c.call("Signals.ValsGet", &b, None, |r| {
        let n = r.count("values count", MAX_SIGNALS)?;
        r.f32s("values", n)
    })?;
    if values.len() != indexes.len() {
        return Err(MicroscopeError::Controller {
            command: "Signals.ValsGet".into(),
            message: format!("{} values for {} signals asked", values.len(), indexes.len()),
        });
    }
    Ok(values.into_iter().map(f64::from).collect())
}

/// A scan frame as the scan engine holds it (m, degrees).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    /// Centre x (m).
    pub centre_x: f64,
    /// Centre y (m).
    pub centre_y: f64,
    /// Width (m).
    pub width: f64,
    /// Height (m).
    pub height: f64,
    /// Rotation (degrees, clockwise).
    pub angle_deg: f64,
}

/// `Scan.FrameSet`.
pub fn frame_set(c: &mut Connection, f: &Frame) -> Result<(), MicroscopeError> {
    let b = body(|w| {
        w.f32(f.centre_x as f32)
            .f32(f.centre_y as f32)
            .f32(f.width as f32)
            .f32(f.height as f32)
            .f32(f.angle_deg as f32);
    });
    c.call("Scan.FrameSet", &b, None, none)
}

/// `Scan.FrameGet`.
pub fn frame_get(c: &mut Connection) -> Result<Frame, MicroscopeError> {
    c.call("Scan.FrameGet", &[], None, |r| {
        Ok(Frame {
            centre_x: f64::from(r.f32("centre x (m)")?),
            centre_y: f64::from(r.f32("centre y (m)")?),
            width: f64::from(r.f32("width (m)")?),
            height: f64::from(r.f32("height (m)")?),
            angle_deg: f64::from(r.f32("angle (deg)")?),
        })
    })
}

/// The scan buffer: recorded channels and pixels.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Buffer {
    /// Signal indexes recorded.
    pub channels: Vec<i32>,
    /// Pixels per line.
    pub pixels: usize,
    /// Lines.
    pub lines: usize,
}

/// `Scan.BufferSet`.
pub fn buffer_set(c: &mut Connection, b: &Buffer) -> Result<(), MicroscopeError> {
    let bytes = body(|w| {
        w.i32(b.channels.len() as i32)
            .i32s(&b.channels)
            .i32(b.pixels as i32)
            .i32(b.lines as i32);
    });
    c.call("Scan.BufferSet", &bytes, None, none)
}

/// `Scan.BufferGet`.
pub fn buffer_get(c: &mut Connection) -> Result<Buffer, MicroscopeError> {
    c.call("Scan.BufferGet", &[], None, |r| {
        let n = r.count("buffer channels count", MAX_SIGNALS)?;
        let channels = r.i32s("buffer channels", n)?;
        let pixels = r.count("pixels", MAX_PIXELS)?;
        let lines = r.count("lines", MAX_PIXELS)?;
        Ok(Buffer {
            channels,
            pixels,
            lines,
        })
    })
}

/// `Scan.Action`: 0 start, 1 stop; `up` the direction.
pub fn scan_action(c: &mut Connection, action: u16, up: bool) -> Result<(), MicroscopeError> {
    let b = body(|w| {
        w.u16(action).u32(up.into());
    });
    c.call("Scan.Action", &b, None, none)
}

/// `Scan.StatusGet`: whether the scan engine is scanning.
pub fn scan_running(c: &mut Connection) -> Result<bool, MicroscopeError> {
    c.call("Scan.StatusGet", &[], None, |r| Ok(r.u32("scan running")? == 1))
}

/// `Scan.WaitEndOfScan`: whether the scan ended within `timeout`.
pub fn wait_end_of_scan(c: &mut Connection, timeout: Duration) -> Result<bool, MicroscopeError> {
    let ms = timeout.as_millis().min(i32::MAX as u128) as i32;
    let b = body(|w| {
        w.i32(ms);
    });
    let timed_out = c.call("Scan.WaitEndOfScan", &b, Some(timeout + Duration::from_secs(2)), |r| {
        let timed_out = r.u32("timed out")?;
        let n = r.u32("file path size")? as usize;
        r.bytes("file path", n)?;
        Ok(timed_out)
    })?;
    Ok(timed_out == 0)
}

/// An image the scan engine recorded: `rows` lines of `cols` values (the channel's unit).
#[derive(Debug, Clone, PartialEq)]
pub struct Grab {
    /// The channel's name.
    pub channel: String,
    /// Lines.
    pub rows: usize,
    /// Pixels per line.
    pub cols: usize,
    /// Values, line by line.
    pub data: Vec<f32>,
    /// The scan went up.
    pub up: bool,
}

/// `Scan.FrameDataGrab`: the forward image of channel `index`.
pub fn frame_data_grab(c: &mut Connection, index: usize) -> Result<Grab, MicroscopeError> {
    let b = body(|w| {
        w.u32(index as u32).u32(1);
    });
    c.call("Scan.FrameDataGrab", &b, None, |r| {
        let channel = r.string("channel name")?;
        let rows = r.count("rows", MAX_PIXELS)?;
        let cols = r.count("cols", MAX_PIXELS)?;
        let data = r.f32s("data", rows * cols)?;
        let up = r.u32("scan direction")? == 1;
        Ok(Grab {
            channel,
            rows,
            cols,
            data,
            up,
        })
    })
}

/// `Util.AcqPeriodSet`: the period over which polled reads are averaged (s).
pub fn acq_period_set(c: &mut Connection, period: f64) -> Result<(), MicroscopeError> {
    let b = body(|w| {
        w.f32(period as f32);
    });
    c.call("Util.AcqPeriodSet", &b, None, none)
}

/// `TCPLog.ChsSet`: the signals the logger streams, in order (with their count, as the manual
/// lays it out).
pub fn log_channels_set(c: &mut Connection, indexes: &[usize]) -> Result<(), MicroscopeError> {
    let idx: Vec<i32> = indexes.iter().map(|&i| i as i32).collect();
    let b = body(|w| {
        w.i32(idx.len() as i32).i32s(&idx);
    });
    c.call("TCPLog.ChsSet", &b, None, none)
}

/// `TCPLog.Start`.
pub fn log_start(c: &mut Connection) -> Result<(), MicroscopeError> {
    c.call("TCPLog.Start", &[], None, none)
}
