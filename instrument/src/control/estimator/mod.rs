//! The particle-position feedback `H_xy` of Eq 19 (Sec 3, Fig 6):
//!
//! ```text
//! H_xy = (x_s, y_s)   if t ≤ t*     (the particle has not left its place on the substrate)
//!        (x°, y°)     otherwise     (the settling position, estimated from the model)
//! ```
//!
//! Only the instrument's measurements enter: the stage position and the deflection reading.
//! `t*`, the particle-substrate separation, is the peak of `ζ_z` (detected in real time: the
//! smoothed reading falls from its running maximum by more than a noise-proof margin). After
//! `t*` the particle trails the tip by the settled offset `δ° = s − y` that the pushing model
//! predicts (Fig 7); when the model's motion is periodic (stick-slip) the mean over its period
//! is used, as the paper says. Before `t*` the particle sits where the contact found it (in our
//! frame the tip moves over a fixed substrate, so "the stage position" of the paper, whose stage
//! carries the particle, becomes "no displacement").

mod prediction;

pub use prediction::*;

/// Samples in the detector's moving mean.
const WINDOW: usize = 4;

/// Real-time detection of `t*` as the peak of the deflection reading.
#[derive(Debug, Clone, PartialEq)]
pub struct PeakDetector {
    window: [f64; WINDOW],
    filled: usize,
    next: usize,
    max: f64,
    max_t: f64,
    margin: f64,
    /// The detected `t*` (s) and the peak reading (deflection side, V).
    pub peak: Option<(f64, f64)>,
}

impl PeakDetector {
    /// A detector that declares the peak once the 4-sample moving mean of the deflection
    /// signal (V, positive = the push's side) falls `margin` (V) below its running maximum.
    pub fn new(margin: f64) -> PeakDetector {
        PeakDetector {
            window: [0.0; WINDOW],
            filled: 0,
            next: 0,
            max: f64::NEG_INFINITY,
            max_t: 0.0,
            margin,
            peak: None,
        }
    }

    /// The moving mean now (V).
    pub fn mean(&self) -> f64 {
        self.window.iter().sum::<f64>() / WINDOW as f64
    }

    /// Feeds one sample; returns `t*` when this sample reveals the peak.
    pub fn feed(&mut self, t: f64, signal: f64) -> Option<f64> {
        if self.peak.is_some() {
            return None;
        }
        if self.filled == 0 {
            // The push starts from the contact search's stop: its level is the first maximum.
            self.window = [signal; WINDOW];
        }
        self.window[self.next] = signal;
        self.next = (self.next + 1) % WINDOW;
        self.filled = (self.filled + 1).min(WINDOW);
        let mean = self.window.iter().sum::<f64>() / self.window.len() as f64;
        if mean > self.max {
            self.max = mean;
            // The moving mean lags the samples by half its window.
            self.max_t = t;
        } else if mean < self.max - self.margin {
            self.peak = Some((self.max_t, self.max));
            return Some(self.max_t);
        }
        None
    }
}

/// The estimator of Eq 19 during one push.
#[derive(Debug, Clone, PartialEq)]
pub struct Hxy {
    /// The model's prediction.
    pub prediction: PushPrediction,
    /// Tip travel from the first touch to where the contact search stopped (m): the model's
    /// travel to the set point.
    pub travel_at_contact: f64,
    /// The `t*` detector.
    pub detector: PeakDetector,
    /// The settled reading the model predicts, as a deflection signal (V).
    pub settled_signal: f64,
}

impl Hxy {
    /// An estimator for a push whose contact search stopped at the set point.
    /// `gain` (V/m, magnitude) turns the model's settled deflection into a reading.
    pub fn new(prediction: PushPrediction, margin: f64, gain: f64) -> Hxy {
        Hxy {
            travel_at_contact: prediction.travel_to_deflection.unwrap_or(0.0),
            settled_signal: prediction.settled_deflection * gain.abs(),
            prediction,
            detector: PeakDetector::new(margin),
        }
    }

    /// Feeds a reading; `travel` is the stage's travel along the push since the contact search
    /// stopped (m). Returns the estimated particle displacement along the push (m): 0 up to `t*`,
    /// then the travel since the first touch less the settled lag `δ°`.
    ///
    /// When the contact search stopped past the peak (a fast search: the whole stick phase fits
    /// in a tick or two), no peak is left to see; then `t*` is taken where the travel since the
    /// touch has passed the model's travel to the peak (plus 10 nm) and the reading has settled
    /// within the margin of the model's settled level.
    pub fn update(&mut self, t: f64, signal: f64, travel: f64) -> f64 {
        if self.detector.feed(t, signal).is_none() && self.detector.peak.is_none() {
            let past_peak = self.travel_at_contact + travel > self.prediction.travel_to_peak + 10e-9;
            let settled = (self.detector.mean() - self.settled_signal).abs() < self.detector.margin;
            if past_peak && settled && self.detector.filled >= WINDOW {
                self.detector.peak = Some((t, signal));
            }
        }
        self.estimate(travel)
    }

    /// The estimated displacement (m) at which the push must stop so that the particle ends
    /// `distance` from its start once the tip has retracted.
    pub fn stop_at(&self, distance: f64) -> f64 {
        distance - self.prediction.retract_shift
    }

    /// The estimate for a travel (m), without feeding a sample.
    pub fn estimate(&self, travel: f64) -> f64 {
        if self.detector.peak.is_none() {
            return 0.0;
        }
        (self.travel_at_contact + travel - self.prediction.settle_offset).max(0.0)
    }

    /// Whether `t*` has been detected.
    pub fn separated(&self) -> bool {
        self.detector.peak.is_some()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn peak_detector_finds_the_peak_of_a_noisy_rise_and_fall() {
        // A ramp to 1 V at t = 50 ms, then a drop to 0.5 V, with ±5 mV alternating "noise".
        let mut d = PeakDetector::new(0.05);
        let mut found = None;
        for k in 0..200 {
            let t = k as f64 * 1e-3;
            let s = if k <= 50 { k as f64 / 50.0 } else { 0.5 } + if k % 2 == 0 { 0.005 } else { -0.005 };
            if let Some(ts) = d.feed(t, s) {
                found = Some((k, ts));
                break;
            }
        }
        let (k, ts) = found.expect("peak found");
        // Declared within a window after the drop; t* at the top of the ramp (moving mean).
        assert!((51..=60).contains(&k), "declared at sample {k}");
        assert!((ts - 0.051).abs() <= 0.004, "t* = {ts}");
    }

    /// docs/manipulation.md's `t*` detector ("Manipulation: `nanopush push` (Sec 2.1 strategy,
    /// Sec 3 force control)"): "a 4-sample mean falling [the margin] below its running
    /// maximum". From a level of 1 V with a margin of 0.25 V, one sample 0.99 V lower moves a
    /// 4-sample mean by 0.2475 V (no peak), one 1.01 V lower by 0.2525 V (the peak, dated at the
    /// level's first sample, where the running maximum was first reached); a 3-sample mean would
    /// fire on the first, a 5-sample one on neither.
    #[test]
    fn the_t_star_detector_is_a_short_mean_falling_below_its_maximum() {
        assert_eq!(WINDOW, 4);
        for (drop, fires) in [(0.99, false), (1.01, true)] {
            let mut d = PeakDetector::new(0.25);
            for k in 0..10 {
                assert_eq!(d.feed(k as f64 * 1e-3, 1.0), None);
            }
            assert_eq!(d.feed(10e-3, 1.0 - drop).is_some(), fires, "a drop of {drop} V");
            if fires {
                assert_eq!(d.peak, Some((0.0, 1.0)), "t* at the first sample of the level");
            }
        }
    }

    #[test]
    fn no_peak_on_a_monotone_rise() {
        let mut d = PeakDetector::new(0.05);
        for k in 0..500 {
            assert!(d.feed(k as f64 * 1e-3, k as f64 * 1e-3).is_none());
        }
    }

    /// A prediction whose settled reading is 0.5 V at a gain of 5e8 V/m, with its peak 20 nm
    /// after the first touch and the contact search stopped 2 nm after it.
    fn fallback_prediction() -> PushPrediction {
        PushPrediction {
            settle_offset: 1e-9,
            periodic_amplitude: 0.0,
            travel_to_deflection: Some(2e-9),
            peak_deflection: 3e-9,
            travel_to_peak: 20e-9,
            settled_deflection: 1e-9,
            phase: "roll",
            retract_shift: 0.0,
            release_lift: Some(0.0),
            travel: 40e-9,
            side: super::ContactSide::Push,
            settled: true,
        }
    }

    /// A fast contact search that stopped past the peak leaves no peak to see: `t*` is taken
    /// once the travel since the touch is past the model's peak plus 10 nm, the 4-sample mean
    /// is within the margin of the settled level, and the window is full; each part of this
    /// fallback and the detector's mean is checked.
    #[test]
    fn a_search_stopped_past_the_peak_separates_once_settled() {
        let (margin, gain) = (0.05, 5e8);
        // Past the peak from the first sample, at the settled level: the fourth sample fills
        // the window, and only then is t* taken.
        let mut h = Hxy::new(fallback_prediction(), margin, gain);
        assert_eq!(h.settled_signal, 0.5);
        for k in 0..4 {
            let t = k as f64 * 1e-3;
            let estimate = h.update(t, 0.5, 40e-9);
            assert_eq!(h.separated(), k == 3, "sample {k}");
            if k == 3 {
                assert_eq!(h.detector.peak, Some((t, 0.5)));
                assert_eq!(h.detector.mean(), 0.5);
                assert!((estimate - (2e-9 + 40e-9 - 1e-9)).abs() < 1e-18, "{estimate:e}");
            } else {
                assert_eq!(estimate, 0.0, "no displacement before t*");
            }
        }
        // Settled, travel rising 1 nm a sample from 0.5 nm: 2 + 28.5 nm is the first past
        // 20 + 10 nm.
        let mut h = Hxy::new(fallback_prediction(), margin, gain);
        let first = (0..60)
            .find(|&k| {
                h.update(k as f64 * 1e-3, 0.5, (k as f64 + 0.5) * 1e-9);
                h.separated()
            })
            .expect("separates");
        assert_eq!(first, 28);
        // Past the peak but not settled (0.1 V off the settled level, twice the margin): no t*.
        let mut h = Hxy::new(fallback_prediction(), margin, gain);
        for k in 0..20 {
            h.update(k as f64 * 1e-3, 0.6, 40e-9);
        }
        assert!(!h.separated(), "0.6 V is not within 0.05 V of 0.5 V");
    }

    /// A peak the detector saw is t*, and later settled samples past the model's peak do not
    /// move it.
    #[test]
    fn a_detected_peak_is_kept_while_the_push_goes_on() {
        let mut h = Hxy::new(fallback_prediction(), 0.05, 5e8);
        for k in 0..4 {
            h.update(k as f64 * 1e-3, 1.0, 0.0);
        }
        assert!(!h.separated());
        h.update(4e-3, 0.5, 40e-9);
        assert_eq!(h.detector.peak, Some((0.0, 1.0)), "the mean fell 0.125 V below 1.0 V");
        for k in 5..20 {
            h.update(k as f64 * 1e-3, 0.5, 40e-9);
        }
        assert_eq!(h.detector.peak, Some((0.0, 1.0)));
        // A fall that lands the (then frozen) mean inside the settled band at once: 3 × 1.0
        // and −0.9 V average 0.525 V, within 0.05 V of 0.5 V, past the model's peak. The
        // fallback must not take t* again (its guard is a conjunction).
        let mut h = Hxy::new(fallback_prediction(), 0.05, 5e8);
        for k in 0..4 {
            h.update(k as f64 * 1e-3, 1.0, 0.0);
        }
        h.update(4e-3, -0.9, 40e-9);
        assert_eq!(h.detector.peak, Some((0.0, 1.0)));
        assert!((h.detector.mean() - 0.525).abs() < 1e-12);
        for k in 5..10 {
            h.update(k as f64 * 1e-3, 0.5, 40e-9);
        }
        assert_eq!(h.detector.peak, Some((0.0, 1.0)), "t* is where the peak was");
    }

    /// "Falls by more than the margin": a mean exactly the margin below the maximum is not yet
    /// the peak.
    #[test]
    fn a_fall_of_exactly_the_margin_is_not_the_peak() {
        let mut d = PeakDetector::new(0.25);
        assert_eq!(d.feed(0.0, 1.0), None);
        for k in 1..=4 {
            // Means 0.9375, 0.875, 0.8125, 0.75: exact in binary.
            assert_eq!(d.feed(k as f64 * 1e-3, 0.75), None, "sample {k}");
        }
        assert_eq!(d.mean(), 0.75);
        assert_eq!(d.feed(5e-3, 0.75), None, "still exactly the margin below");
        assert!(d.feed(6e-3, 0.74).is_some(), "the mean 2.5 mV further down");
    }
}
