//! The adaptive controller: from the pool time frames cost, the bandwidth the client
//! receives and the session's frame rate, the size, codec and JPEG quality of the next frame.

use crate::input::{Settings, StreamSettings};
use crate::schedule::JobCost;
use isoray_protocol::Codec;

/// Share of its own frame interval that tracing and encoding one interactive frame may take
/// on the pool. Below 1 so that an input waits for less than a frame interval behind the
/// frame already in progress; it is what holds a lone viewer's frames down.
const FRAME_SHARE: f64 = 0.6;

/// Share of the measured bandwidth interactive frames may use.
const BANDWIDTH_SHARE: f64 = 0.8;

/// Lowest JPEG quality the controller goes to before it lowers the resolution for bandwidth.
const MIN_JPEG_QUALITY: u8 = 30;

/// Consecutive interactive frames after which motion counts as sustained and a client that
/// decodes H.264 gets it.
pub const H264_AFTER_FRAMES: u32 = 12;

/// H.264 bits per pixel and frame when bandwidth is plentiful.
const H264_BITS_PER_PIXEL: f64 = 0.12;

/// Lowest H.264 bit rate: small frames need more bits per pixel than large ones.
const H264_MIN_BITRATE_BPS: f64 = 400_000.0;

/// An H.264 stream keeps its size until the controller's size differs by more than this
/// fraction (a new size costs a keyframe).
const H264_RESIZE_HYSTERESIS: f64 = 0.15;

/// How a frame is made: fast while the view changes, lossless once it settles.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Quality {
    /// JPEG or H.264 at the controller's size and quality.
    Interactive,
    /// PNG at full size, bit-exact to the renderer's output, flagged `FLAG_STILL`.
    Still,
}

/// The adaptive controller of one session: picks the size and JPEG quality of interactive
/// frames from what the previous frames cost and the bandwidth the client receives.
///
/// - Time: a frame may take `min(pool_share / sessions competing, FRAME_SHARE) / fps` of
///   pool time: the sessions' frames together plan to keep the pool `pool_share` busy
///   (`--pool-share`), and a lone viewer's frame takes at most [`FRAME_SHARE`] of its interval.
///   The controller learns the pool time per pixel from every interactive frame and picks the
///   scale whose pixel count fits, moving halfway there each frame (steady under noise, quick
///   to follow a change in load).
/// - Bandwidth: a frame may take `BANDWIDTH_SHARE × bandwidth / fps` bytes. Over it, JPEG
///   quality drops in steps of 10 down to [`MIN_JPEG_QUALITY`], then the scale drops too; well
///   under it, quality climbs back in steps of 5 up to `--jpeg-quality`.
#[derive(Debug)]
pub struct Controller {
    pub scale: f64,
    pub quality: u8,
    pub max_quality: u8,
    pub min_scale: f64,
    /// Share of the pool all sessions' interactive frames are sized to use (`--pool-share`).
    pub pool_share: f64,
    /// Pool seconds per pixel of recent interactive frames.
    pub pool_s_per_pixel: Option<f64>,
    /// Scale the bandwidth allows (1 when it does not limit).
    pub bandwidth_scale: f64,
    /// Consecutive interactive frames since the last still frame.
    pub motion_frames: u32,
    /// The per-pixel cost came from other sessions ([`Controller::starting_from`]) and no
    /// frame has been planned yet: the first plan takes the size it gives at once.
    seeded: bool,
}

impl Controller {
    pub fn new(max_quality: u8, min_scale: f64, pool_share: f64) -> Controller {
        Controller {
            scale: 1.0,
            quality: max_quality,
            max_quality,
            min_scale,
            pool_share,
            pool_s_per_pixel: None,
            bandwidth_scale: 1.0,
            motion_frames: 0,
            seeded: false,
        }
    }

    /// Starts from the pool seconds per pixel other sessions of the scene measured, if any:
    /// a viewer who joins a busy server then gets a first frame that fits its share, instead
    /// of a full-size one that every other session's frames wait behind (sixteen viewers
    /// opening a 1280×720 view of `scattered-1k` at once queued a second of full-size frames).
    pub fn starting_from(mut self, pool_s_per_pixel: Option<f64>) -> Controller {
        if let Some(cost) = pool_s_per_pixel.filter(|c| *c > 0.0 && c.is_finite()) {
            self.pool_s_per_pixel = Some(cost);
            self.seeded = true;
        }
        self
    }

    /// The scale for the next interactive frame at `fps` with `sessions` competing. Before any
    /// measurement (the scene's first viewers since the server started), the frame takes its
    /// share of the pixels: full size alone, a sixteenth of them among sixteen sessions, so
    /// that viewers arriving together cost the pool what one full-size viewer would.
    pub fn plan_scale(&mut self, full: (u32, u32), fps: f64, sessions: usize) -> f64 {
        if self.pool_s_per_pixel.is_none() {
            self.scale = self.scale.min((1.0 / sessions.max(1) as f64).sqrt());
        }
        if let Some(per_pixel) = self.pool_s_per_pixel {
            let budget_s = (self.pool_share / sessions.max(1) as f64).min(FRAME_SHARE) / fps;
            let full_pixels = full.0 as f64 * full.1 as f64;
            let wanted = (budget_s / (per_pixel * full_pixels)).sqrt();
            self.scale = if std::mem::take(&mut self.seeded) {
                wanted
            } else {
                0.5 * self.scale + 0.5 * wanted
            };
        }
        self.scale = self
            .scale
            .min(self.bandwidth_scale)
            .clamp(self.min_scale, 1.0);
        self.scale
    }

    /// Learns from an interactive frame of `pixels` that cost `cost` and weighed `bytes`.
    pub fn observe(
        &mut self,
        pixels: u64,
        cost: JobCost,
        bytes: usize,
        codec: Codec,
        bandwidth: Option<f64>,
        fps: f64,
    ) {
        let per_pixel = cost.pool_s / pixels.max(1) as f64;
        self.pool_s_per_pixel = Some(match self.pool_s_per_pixel {
            Some(old) => 0.5 * old + 0.5 * per_pixel,
            None => per_pixel,
        });
        let Some(bandwidth) = bandwidth else {
            return;
        };
        let budget = BANDWIDTH_SHARE * bandwidth / fps;
        let bytes = bytes as f64;
        if bytes > budget {
            if codec == Codec::Jpeg && self.quality > MIN_JPEG_QUALITY {
                self.quality = self.quality.saturating_sub(10).max(MIN_JPEG_QUALITY);
            } else {
                self.bandwidth_scale = (self.scale * (budget / bytes).sqrt()).max(self.min_scale);
            }
        } else if bytes < 0.5 * budget {
            if self.bandwidth_scale < 1.0 {
                self.bandwidth_scale = (self.bandwidth_scale * 1.1).min(1.0);
            } else if codec == Codec::Jpeg {
                self.quality = (self.quality + 5).min(self.max_quality);
            }
        }
    }

    /// The codec of the next frame.
    pub fn codec(&self, quality: Quality, stream: &StreamSettings) -> Codec {
        match quality {
            Quality::Still if stream.accepts(Codec::Png) => Codec::Png,
            Quality::Still => Codec::Jpeg,
            Quality::Interactive => {
                let sustained = self.motion_frames >= H264_AFTER_FRAMES;
                if stream.accepts(Codec::H264) && (sustained || !stream.accepts(Codec::Jpeg)) {
                    Codec::H264
                } else if stream.accepts(Codec::Jpeg) {
                    Codec::Jpeg
                } else {
                    Codec::Png
                }
            }
        }
    }
}

/// Everything a render job needs, decided on the async side.
#[derive(Clone, Copy, Debug)]
pub struct FramePlan {
    pub sequence: u64,
    pub quality: Quality,
    pub codec: Codec,
    pub size: (u32, u32),
    pub jpeg_quality: u8,
    pub depth: bool,
    pub time: f64,
    pub fps: f64,
    /// Bit rate for a new H.264 stream.
    pub h264_bitrate_bps: u32,
    /// Start the H.264 stream over with a keyframe.
    pub h264_restart: bool,
    /// Time of the live state this session showed last: a live view takes a newer built
    /// state without waiting for the one in flight.
    pub seen: Option<f64>,
}

/// Decides size, codec, quality and depth of the next frame.
#[allow(clippy::too_many_arguments)]
pub fn plan_frame(
    controller: &mut Controller,
    settings: &Settings,
    quality: Quality,
    sequence: u64,
    time: f64,
    sessions: usize,
    bandwidth: Option<f64>,
    video: Option<((u32, u32), u32)>,
) -> FramePlan {
    let full = (settings.width, settings.height);
    let fps = settings.stream.fps;
    let codec = controller.codec(quality, &settings.stream);
    let mut plan = FramePlan {
        sequence,
        quality,
        codec,
        size: full,
        jpeg_quality: match (quality, codec) {
            (Quality::Still, _) => 100,
            (Quality::Interactive, _) => controller.quality,
        },
        depth: settings.stream.depth && quality == Quality::Interactive,
        time,
        fps,
        h264_bitrate_bps: 0,
        h264_restart: false,
        seen: None,
    };
    if quality == Quality::Still {
        return plan;
    }
    let scale = controller.plan_scale(full, fps, sessions);
    plan.size = scaled_size(full.0, full.1, scale);
    if codec == Codec::H264 {
        // Even sizes, at least 16 px; keep the stream's size unless the controller's moved far.
        let even = |v: u32| (v & !1).max(16);
        let wanted = (even(plan.size.0), even(plan.size.1));
        let pixels = wanted.0 as f64 * wanted.1 as f64;
        let ceiling = pixels * fps * H264_BITS_PER_PIXEL;
        let bitrate = bandwidth.map_or(ceiling, |b| ceiling.min(BANDWIDTH_SHARE * b * 8.0));
        plan.h264_bitrate_bps = bitrate.clamp(H264_MIN_BITRATE_BPS, 50_000_000.0) as u32;
        plan.size = wanted;
        match video {
            Some((size, current_bps)) => {
                let drift = (wanted.0 as f64 / size.0 as f64 - 1.0).abs();
                let rate_drift = plan.h264_bitrate_bps as f64 / current_bps.max(1) as f64;
                if drift <= H264_RESIZE_HYSTERESIS && (0.5..=2.0).contains(&rate_drift) {
                    plan.size = size;
                    plan.h264_bitrate_bps = current_bps;
                    // Each run of sustained motion starts with a keyframe: the client's
                    // decoder may have been reset since the last run.
                    plan.h264_restart = controller.motion_frames == H264_AFTER_FRAMES;
                } else {
                    plan.h264_restart = true;
                }
            }
            None => plan.h264_restart = true,
        }
    }
    plan
}

/// The requested size scaled by `scale`, keeping the aspect ratio, never below 8 pixels.
pub fn scaled_size(width: u32, height: u32, scale: f64) -> (u32, u32) {
    if scale >= 1.0 {
        return (width, height);
    }
    let s = |v: u32| ((v as f64 * scale).round() as u32).clamp(8.min(v), v);
    (s(width), s(height))
}
#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn controller_lowers_quality_then_scale_when_bandwidth_is_short() {
        let mut c = Controller::new(80, 0.25, 0.6);
        let cost = JobCost {
            pool_s: 0.001,
            ..JobCost::default()
        };
        // 40 kB frames on a 300 kB/s link at 30 fps: 8 kB per frame allowed.
        for _ in 0..5 {
            c.observe(100_000, cost, 40_000, Codec::Jpeg, Some(300_000.0), 30.0);
        }
        assert_eq!(c.quality, MIN_JPEG_QUALITY);
        c.observe(100_000, cost, 40_000, Codec::Jpeg, Some(300_000.0), 30.0);
        let scale = c.plan_scale((1000, 1000), 30.0, 1);
        assert!(scale < 0.5, "scale follows the byte budget: {scale}");
        // Plenty of bandwidth again: the scale recovers before the quality does.
        for _ in 0..40 {
            c.observe(100_000, cost, 1_000, Codec::Jpeg, Some(1.0e9), 30.0);
        }
        assert_eq!(c.bandwidth_scale, 1.0);
        assert_eq!(c.quality, 80);
    }

    #[test]
    fn controller_scale_fits_the_pools_share_of_the_frame_interval() {
        // 1 µs of pool time per pixel; scales after twenty frames of a million-pixel view at
        // 30 fps among `sessions`, with the pool share `share`.
        let settle = |share: f64, sessions: usize| {
            let mut c = Controller::new(80, 0.01, share);
            let cost = JobCost {
                pool_s: 0.1,
                ..JobCost::default()
            };
            c.observe(100_000, cost, 1, Codec::Jpeg, None, 30.0);
            let mut scale = 0.0;
            for _ in 0..20 {
                scale = c.plan_scale((1000, 1000), 30.0, sessions);
            }
            scale
        };
        // Alone: 0.6 of 33.3 ms, 20,000 pixels → 0.1414, whatever the pool share.
        for share in [0.6, 0.85] {
            let alone = settle(share, 1);
            assert!((alone - 0.1414).abs() < 0.001, "alone at {share}: {alone}");
        }
        // Four sessions share 0.6 of the pool: 5 ms a frame, half the lone viewer's scale.
        let four = settle(0.6, 4);
        assert!((four - 0.0707).abs() < 0.001, "four at 0.6: {four}");
        // At 0.85: 7.08 ms, 7,083 pixels → 0.0842; two sessions 0.425 of the interval each,
        // still under a lone frame's 0.6: 14,167 pixels → 0.1190.
        let four = settle(0.85, 4);
        assert!((four - 0.0842).abs() < 0.001, "four at 0.85: {four}");
        let two = settle(0.85, 2);
        assert!((two - 0.1190).abs() < 0.001, "two at 0.85: {two}");
    }

    #[test]
    fn a_controller_seeded_by_other_sessions_plans_its_first_frame_to_fit() {
        // 1 µs of pool time per pixel, sixteen sessions at 10 fps sharing 0.6 of the pool:
        // 3.75 ms a frame, 3,750 pixels of a million: scale 0.061.
        let wanted = (0.6f64 / (10.0 * 16.0) / 1e-6 / 1e6).sqrt();
        let mut seeded = Controller::new(80, 0.01, 0.6).starting_from(Some(1e-6));
        let first = seeded.plan_scale((1000, 1000), 10.0, 16);
        assert!((first - wanted).abs() < 1e-9, "{first} against {wanted}");
        // Later frames move halfway, as every controller does.
        seeded.observe(
            10_000,
            JobCost {
                pool_s: 0.04,
                ..JobCost::default()
            },
            1,
            Codec::Jpeg,
            None,
            10.0,
        );
        let second = seeded.plan_scale((1000, 1000), 10.0, 16);
        assert!(second < first && second > 0.5 * first, "{second}");
        // Without a measurement to start from, the first frame takes its share of the pixels:
        // full size alone, a quarter of the width among sixteen; a cost that is no cost seeds
        // nothing.
        let mut alone = Controller::new(80, 0.01, 0.6).starting_from(None);
        assert_eq!(alone.plan_scale((1000, 1000), 10.0, 1), 1.0);
        let mut fresh = Controller::new(80, 0.01, 0.6).starting_from(None);
        assert_eq!(fresh.plan_scale((1000, 1000), 10.0, 16), 0.25);
        let mut zero = Controller::new(80, 0.01, 0.6).starting_from(Some(0.0));
        assert_eq!(zero.plan_scale((1000, 1000), 10.0, 16), 0.25);
    }

    #[test]
    fn codec_follows_the_clients_list_and_sustained_motion() {
        let mut c = Controller::new(80, 0.25, 0.6);
        let all = StreamSettings::new(&Codec::ALL, 30.0);
        assert_eq!(c.codec(Quality::Still, &all), Codec::Png);
        assert_eq!(c.codec(Quality::Interactive, &all), Codec::Jpeg);
        c.motion_frames = H264_AFTER_FRAMES;
        assert_eq!(c.codec(Quality::Interactive, &all), Codec::H264);
        let images = StreamSettings::new(&[Codec::Jpeg, Codec::Png], 30.0);
        assert_eq!(c.codec(Quality::Interactive, &images), Codec::Jpeg);
        let jpeg_only = StreamSettings::new(&[Codec::Jpeg], 30.0);
        assert_eq!(c.codec(Quality::Still, &jpeg_only), Codec::Jpeg);
    }
}
