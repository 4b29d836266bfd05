//! The bandwidth a client receives, estimated from the acknowledgements of the frames sent.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

/// Estimates the bandwidth to the client from acknowledgements.
///
/// Each acknowledged frame gives a service time: from when the link could start on it (its
/// send, or the previous acknowledgement if it was sent before that) to its own
/// acknowledgement. A link of `B` bytes per second with a fixed latency `L` (round trip plus
/// the client's decoding before it acknowledges) serves a frame of `b` bytes in `L + b / B`,
/// so the estimate is the slope of a least-squares line through the (bytes, service time)
/// samples of the last two seconds, frames differ in size enough for that (the camera
/// moves, the controller changes quality). Only a clear fit counts (correlation at least
/// [`BANDWIDTH_MIN_CORRELATION`], positive slope): when service time does not grow with
/// frame size, the client is limited by latency or by its own pace, smaller frames would not
/// help, and bandwidth limits nothing. A clear fit holds for two windows, since frames of a
/// settled controller are too alike in size for a new one.
#[derive(Default)]
pub struct Bandwidth {
    in_flight: VecDeque<(u64, usize, Instant)>,
    last_ack_at: Option<Instant>,
    /// (acknowledged at, bytes, service seconds)
    samples: VecDeque<(Instant, f64, f64)>,
    /// The last clear fit and when it was made: it holds while frames are too alike in size
    /// for a new one (as they are once the controller has settled).
    last_clear: Option<(Instant, f64)>,
}

/// How long a bandwidth sample counts.
const BANDWIDTH_WINDOW: Duration = Duration::from_secs(2);

/// Samples needed before the estimate limits anything.
const BANDWIDTH_MIN_SAMPLES: usize = 6;

/// Correlation of service time with frame size below which size is not what limits.
const BANDWIDTH_MIN_CORRELATION: f64 = 0.7;

/// Most a fit's transfer time of the mean frame may be, as a share of the mean service time:
/// 1 for a link without latency and without noise; above it, the fit's latency would be
/// negative.
const BANDWIDTH_MAX_TRANSFER_SHARE: f64 = 1.5;

impl Bandwidth {
    pub fn sent(&mut self, sequence: u64, bytes: usize, at: Instant) {
        // Bounded: the renderer keeps at most FRAME_WINDOW frames unacknowledged.
        if self.in_flight.len() >= 64 {
            self.in_flight.pop_front();
        }
        self.in_flight.push_back((sequence, bytes, at));
    }

    pub fn acked(&mut self, sequence: u64, at: Instant) {
        let mut delivered = 0usize;
        let mut first_sent = None;
        while let Some(&(seq, bytes, sent)) = self.in_flight.front() {
            if seq > sequence {
                break;
            }
            self.in_flight.pop_front();
            delivered += bytes;
            first_sent.get_or_insert(sent);
        }
        let Some(first_sent) = first_sent else {
            return;
        };
        let start = self.last_ack_at.map_or(first_sent, |a| a.max(first_sent));
        self.last_ack_at = Some(at);
        self.samples
            .push_back((at, delivered as f64, (at - start).as_secs_f64()));
        while self
            .samples
            .front()
            .is_some_and(|(t, _, _)| at - *t > BANDWIDTH_WINDOW)
        {
            self.samples.pop_front();
        }
        if let Some(fit) = self.fit() {
            self.last_clear = Some((at, fit));
        }
    }

    /// Bytes per second: the last clear fit of the last two bandwidth windows.
    pub fn estimate(&self) -> Option<f64> {
        let (at, fit) = self.last_clear?;
        let newest = self.samples.back().map_or(at, |s| s.0);
        (newest - at <= 2 * BANDWIDTH_WINDOW).then_some(fit)
    }

    /// The slope fit of the current samples, when it is clear.
    pub fn fit(&self) -> Option<f64> {
        let n = self.samples.len();
        if n < BANDWIDTH_MIN_SAMPLES {
            return None;
        }
        let mean_b = self.samples.iter().map(|s| s.1).sum::<f64>() / n as f64;
        let mean_s = self.samples.iter().map(|s| s.2).sum::<f64>() / n as f64;
        let (mut var_b, mut var_s, mut cov) = (0.0, 0.0, 0.0);
        for &(_, b, s) in &self.samples {
            var_b += (b - mean_b) * (b - mean_b);
            var_s += (s - mean_s) * (s - mean_s);
            cov += (b - mean_b) * (s - mean_s);
        }
        if var_b <= 0.0 || var_s <= 0.0 || cov <= 0.0 {
            return None;
        }
        let correlation = cov / (var_b * var_s).sqrt();
        if correlation < BANDWIDTH_MIN_CORRELATION {
            return None;
        }
        // A link serves a frame in `L + b / B` with `L >= 0`, so the mean frame's transfer time
        // cannot exceed the mean service time. A steep slope through small, noisy service
        // times (a busy machine on loopback) breaks that: its line would cross zero service
        // time at a positive frame size. Such a fit is noise, not a link.
        let bytes_per_s = var_b / cov;
        (mean_b / bytes_per_s <= BANDWIDTH_MAX_TRANSFER_SHARE * mean_s).then_some(bytes_per_s)
    }
}
#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bandwidth_is_the_slope_of_service_time_over_frame_size() {
        let mut bw = Bandwidth::default();
        let t0 = Instant::now();
        // A 1 MB/s link with 30 ms of latency; frames of 10 to 60 kB, one at a time.
        let mut at = t0;
        for i in 0..10u64 {
            let bytes = 10_000 + (i as usize % 6) * 10_000;
            bw.sent(i + 1, bytes, at);
            at += Duration::from_secs_f64(0.030 + bytes as f64 / 1.0e6);
            bw.acked(i + 1, at);
            at += Duration::from_millis(5);
        }
        let e = bw.estimate().expect("a clear fit");
        assert!((e / 1.0e6 - 1.0).abs() < 0.01, "{e}");

        // A client whose acknowledgements take 40 ms whatever the size: not a bandwidth limit.
        let mut bw = Bandwidth::default();
        let mut at = t0;
        for i in 0..10u64 {
            let bytes = 10_000 + (i as usize % 6) * 10_000;
            bw.sent(i + 1, bytes, at);
            at += Duration::from_millis(40 + (i % 3));
            bw.acked(i + 1, at);
        }
        assert_eq!(bw.estimate(), None);

        // Service times of 1 to 3 ms that happen to grow with size (a busy machine on
        // loopback): the line through them would serve a 0-byte frame in negative time.
        let mut noise = Bandwidth::default();
        let mut at = t0;
        for i in 0..10u64 {
            let bytes = 5_000 + (i as usize % 6) * 500;
            noise.sent(i + 1, bytes, at);
            at += Duration::from_micros(1_000 + (i % 6) * 400);
            noise.acked(i + 1, at);
            at += Duration::from_millis(30);
        }
        assert_eq!(noise.estimate(), None);
        // Two seconds later the old samples are gone.
        bw.sent(11, 1_000, at + Duration::from_secs(3));
        bw.acked(11, at + Duration::from_secs(3));
        assert_eq!(bw.samples.len(), 1);
        assert_eq!(bw.fit(), None);
        assert_eq!(bw.in_flight.len(), 0);
    }
}
