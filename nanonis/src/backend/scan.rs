//! Scans through the controller's scan engine: the frame and buffer set (and given back to the
//! operator after), the tip landed when it was withdrawn, the wait for the end in slices a stop
//! can cut, and the grabbed image checked against what was asked.

use std::time::{Duration, Instant};

use nanopush_instrument::afm::{Microscope, MicroscopeError, ScanFrame};
use nanopush_instrument::scan::HeightImage;

use super::NanonisMicroscope;
use crate::commands::{self as cmd, Buffer, Frame};

impl NanonisMicroscope {
    pub(super) fn frame_to_scan(f: &Frame, b: &Buffer) -> ScanFrame {
        ScanFrame {
            centre_x: f.centre_x,
            centre_y: f.centre_y,
            width: f.width,
            height: f.height,
            pixels: b.pixels,
            lines: b.lines,
        }
    }

    /// The scan, and the operator's frame and buffer to give back when they were changed (the
    /// caller gives them back once the tip is safe).
    #[allow(clippy::type_complexity)]
    pub(super) fn scan_inner(
        &mut self,
        frame: Option<&ScanFrame>,
    ) -> (Result<HeightImage, MicroscopeError>, Option<(Frame, Buffer)>) {
        let buffer0 = match self.call("Scan.BufferGet", cmd::buffer_get) {
            Ok(b) => b,
            Err(e) => return (Err(e), None),
        };
        let frame0 = match self.call("Scan.FrameGet", cmd::frame_get) {
            Ok(f) => f,
            Err(e) => return (Err(e), None),
        };
        let (mut buffer, mut f) = (buffer0.clone(), frame0);
        if let Some(want) = frame {
            if let Err(e) = self.refuse_if_read_only("Scan.FrameSet") {
                return (Err(e), None);
            }
            f = Frame {
                centre_x: want.centre_x,
                centre_y: want.centre_y,
                width: want.width,
                height: want.height,
                angle_deg: 0.0,
            };
            buffer.pixels = want.pixels;
            buffer.lines = want.lines;
        }
        if f.angle_deg.is_nan() || f.angle_deg.abs() > 1e-6 {
            let e = MicroscopeError::Unsupported {
                backend: "nanopush".into(),
                what: format!(
                    "image a frame rotated by {:.2}°: set the angle to 0 at the controller, or give a frame",
                    f.angle_deg
                ),
            };
            return (Err(e), None);
        }
        if !buffer.channels.contains(&(self.idx.z as i32)) {
            if let Err(e) = self.refuse_if_read_only("Scan.BufferSet") {
                return (Err(e), None);
            }
            buffer.channels.push(self.idx.z as i32);
        }
        let changed = (frame.is_some() || buffer != buffer0) && !self.opts.read_only;
        let restore = changed.then_some((frame0, buffer0));
        let result = self.scan_engine(frame.map(|_| &f), &buffer).and_then(|grab| {
            let sf = Self::frame_to_scan(&f, &buffer);
            self.image_of(grab, &sf, &buffer)
        });
        (result, restore)
    }

    /// Ends the scan early when a stop or a shutdown asked: checked before each step.
    fn unless_cancelled(&mut self, started: bool) -> Result<(), MicroscopeError> {
        if !self.cancelled() {
            return Ok(());
        }
        if started {
            let _ = self.call("Scan.Action", |c| cmd::scan_action(c, 1, true));
        }
        Err(MicroscopeError::Cancelled("the scan".into()))
    }

    /// Sets the frame (when given) and the buffer, lands the tip if it is withdrawn, scans and
    /// waits, and grabs the height channel; or, read-only, grabs what the controller has.
    fn scan_engine(&mut self, frame: Option<&Frame>, buffer: &Buffer) -> Result<cmd::Grab, MicroscopeError> {
        self.unless_cancelled(false)?;
        if !self.opts.read_only {
            if let Some(f) = frame {
                self.call("Scan.FrameSet", |c| cmd::frame_set(c, f))?;
            }
            let b = buffer.clone();
            self.call("Scan.BufferSet", |c| cmd::buffer_set(c, &b))?;
        }
        // A scan needs the Z feedback on: with the tip withdrawn, the controller's own set point
        // lands it, and the tip is withdrawn again after the image.
        let mut landed_here = false;
        self.unless_cancelled(false)?;
        if !self.opts.read_only && self.call("ZCtrl.StatusGet", cmd::z_status)? == cmd::ZStatus::Off {
            self.unless_cancelled(false)?;
            self.call("ZCtrl.OnOffSet", |c| cmd::z_on_off_set(c, true))?;
            landed_here = true;
        }
        if !self.opts.read_only {
            self.unless_cancelled(false)?;
            self.call("Scan.Action", |c| cmd::scan_action(c, 0, true))?;
            // Waited for in slices, so that a stop is heard within one.
            let (timeout, began) = (self.opts.scan_timeout, Instant::now());
            let slice = Duration::from_millis(500).min(timeout);
            loop {
                self.unless_cancelled(true)?;
                let asked = Instant::now();
                if self.call("Scan.WaitEndOfScan", |c| cmd::wait_end_of_scan(c, slice))? {
                    break;
                }
                if began.elapsed() >= timeout {
                    return Err(MicroscopeError::Link {
                        command: "Scan.WaitEndOfScan".into(),
                        message: format!("the scan did not end within {:.0} s", timeout.as_secs_f64()),
                    });
                }
                // `WaitEndOfScan` waits for the next end: a scan that ended between two slices is
                // seen by the engine's status instead.
                if !self.call("Scan.StatusGet", cmd::scan_running)? {
                    break;
                }
                // A controller that says "timed out" at once is not asked again at once.
                std::thread::sleep(slice.saturating_sub(asked.elapsed()));
            }
        }
        let z = self.idx.z;
        let grab = self.call("Scan.FrameDataGrab", |c| cmd::frame_data_grab(c, z))?;
        if landed_here {
            self.withdraw()?;
        }
        Ok(grab)
    }

    /// The grabbed image as heights, checked against what was asked: its size the buffer's, its
    /// channel the height signal, every height a number inside the Z range.
    fn image_of(&self, grab: cmd::Grab, sf: &ScanFrame, buffer: &Buffer) -> Result<HeightImage, MicroscopeError> {
        let bad = |message: String| MicroscopeError::Controller {
            command: "Scan.FrameDataGrab".into(),
            message,
        };
        if grab.rows == 0 || grab.cols == 0 {
            return Err(bad(format!(
                "an empty image of {} × {} (has the controller scanned yet?)",
                grab.cols, grab.rows
            )));
        }
        if (grab.cols, grab.rows) != (buffer.pixels, buffer.lines) {
            return Err(bad(format!(
                "an image of {} × {} pixels; the scan buffer is {} × {}",
                grab.cols, grab.rows, buffer.pixels, buffer.lines
            )));
        }
        let want = &self.names[self.idx.z];
        if !grab.channel.trim().eq_ignore_ascii_case(want.trim()) {
            return Err(bad(format!(
                "the channel {:?}; the height signal is {want:?}",
                grab.channel
            )));
        }
        let [low, high] = self.limits.z;
        let span = high - low;
        let outside = grab
            .data
            .iter()
            .filter(|v| {
                let v = f64::from(**v);
                !(v.is_finite() && v >= low - span && v <= high + span)
            })
            .count();
        if outside > 0 {
            return Err(bad(format!(
                "{outside} of {} pixels are not heights inside the Z range [{:.4}, {:.4}] µm (an unfinished scan, or another signal?)",
                grab.data.len(),
                low * 1e6,
                high * 1e6
            )));
        }
        // Row 0 is the bottom line (lowest y) of a scan that went up; the image keeps rows in y.
        let mut data: Vec<f64> = Vec::with_capacity(grab.data.len());
        for row in 0..grab.rows {
            let r = if grab.up { row } else { grab.rows - 1 - row };
            data.extend(
                grab.data[r * grab.cols..(r + 1) * grab.cols]
                    .iter()
                    .map(|&v| f64::from(v)),
            );
        }
        Ok(HeightImage {
            xres: grab.cols,
            yres: grab.rows,
            x_real: sf.width,
            y_real: sf.height,
            x_offset: sf.centre_x - 0.5 * sf.width,
            y_offset: sf.centre_y - 0.5 * sf.height,
            data,
        })
    }
}
