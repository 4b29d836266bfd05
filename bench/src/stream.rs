//! `isoray-bench stream`: what streaming costs and what it delivers.
//!
//! `codecs`: the 1,000-ball animated scene (`scattered-1k`) along a fixed camera path (an
//! orbit of 2° and 1/30 s of scene time per frame, like a steady drag) at 1280×720 and
//! 1920×1080. Each frame is rendered once; then every codec and quality setting encodes the
//! same frames on one core (the bench's main thread), and the result is decoded again and
//! compared with the uncompressed frame. The table gives bytes per frame, the bandwidth at
//! 30 fps, the median encode ms and the mean PSNR (dB, RGB). H.264 encodes the path as one
//! stream (first frame a keyframe), so its bytes include the keyframe.
//!

use crate::common::{median, write_json, Machine};
use isoray_render::scenes::DemoScene;
use isoray_render::{Camera, CpuBackend, Framebuffer, View};
use isoray_server::encode::{self, JpegEncoder};
use serde::Serialize;
use std::sync::Arc;
use std::time::Instant;

#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    part: Option<Part>,
}

#[derive(clap::Subcommand)]
enum Part {
    /// Bytes per frame, encode ms and PSNR of each codec along a camera path.
    Codecs(CodecArgs),
}

#[derive(clap::Args, Clone)]
struct CodecArgs {
    /// Frames along the camera path.
    #[arg(long, default_value_t = 24)]
    frames: usize,
    /// Frame sizes, `WxH`, comma-separated.
    #[arg(long, value_delimiter = ',', default_values_t = ["1280x720".to_string(), "1920x1080".to_string()])]
    sizes: Vec<String>,
    /// Scene id.
    #[arg(long, default_value = "scattered-1k")]
    scene: String,
    /// Also write the rows as JSON to this file.
    #[arg(long)]
    json: Option<std::path::PathBuf>,
}

pub fn run(args: Args) -> Result<(), String> {
    match args.part {
        Some(Part::Codecs(a)) => codecs(&a),
        None => codecs(&CodecArgs {
            frames: 24,
            sizes: vec!["1280x720".into(), "1920x1080".into()],
            scene: "scattered-1k".into(),
            json: None,
        }),
    }
}

pub(crate) fn demo(id: &str) -> Result<DemoScene, String> {
    DemoScene::ALL
        .iter()
        .find(|d| d.id() == id)
        .copied()
        .ok_or_else(|| format!("unknown scene {id:?}"))
}

pub(crate) fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let parsed = s
        .split_once('x')
        .and_then(|(w, h)| Some((w.parse().ok()?, h.parse().ok()?)));
    match parsed {
        Some((w, h)) if w > 0 && h > 0 => Ok((w, h)),
        _ => Err(format!("size {s:?} is not WIDTHxHEIGHT")),
    }
}

/// The camera of frame `i` of the path: an orbit around the default camera's target.
pub(crate) fn path_camera(demo: DemoScene, i: usize) -> Camera {
    let base = demo.default_camera();
    let offset = base.eye - base.target;
    let angle = (i as f32 * 2.0).to_radians();
    let rotation = glam::Quat::from_rotation_y(angle);
    Camera {
        eye: base.target + rotation * offset,
        ..base
    }
}

#[derive(Serialize)]
struct CodecRow {
    size: String,
    codec: String,
    setting: String,
    bytes_per_frame: f64,
    mbit_per_s_at_30fps: f64,
    encode_ms: f64,
    psnr_db: f64,
}

fn codecs(args: &CodecArgs) -> Result<(), String> {
    let demo = demo(&args.scene)?;
    let backend = CpuBackend::new(0).map_err(|e| e.to_string())?;
    println!("## isoray-bench stream codecs\n");
    println!("machine: {}", Machine::here().line());
    println!(
        "scene {} ({} balls), {} frames orbiting 2° per frame, 1/30 s of scene time per frame; \
         encode on one core; PSNR against the uncompressed frame\n",
        demo.id(),
        demo.ball_count(),
        args.frames
    );
    println!("| size | codec | setting | bytes/frame | Mbit/s at 30 fps | encode ms (median) | PSNR dB |");
    println!("|---|---|---|---:|---:|---:|---:|");
    let mut rows = Vec::new();
    for size in &args.sizes {
        let (width, height) = parse_size(size)?;
        let started = Instant::now();
        let frames: Vec<(Framebuffer, Camera)> = (0..args.frames.max(1))
            .map(|i| {
                let scene = Arc::new(demo.state_at(1.0 + i as f64 / 30.0)).prepare();
                let camera = path_camera(demo, i);
                let view = View {
                    width,
                    height,
                    camera,
                    isovalue: demo.default_isovalue(),
                };
                (backend.render(&scene, &view), camera)
            })
            .collect();
        eprintln!(
            "rendered {} frames of {size} in {:.1} s",
            frames.len(),
            started.elapsed().as_secs_f64()
        );
        for encoder in JpegEncoder::available() {
            for quality in [50u8, 70, 85, 95] {
                let row = measure(&frames, |fb| {
                    let t = Instant::now();
                    let bytes = encode::jpeg_rgb(&fb.rgb, fb.width, fb.height, quality, encoder)
                        .expect("jpeg");
                    let ms = t.elapsed().as_secs_f64() * 1e3;
                    let decoded = image::load_from_memory(&bytes).expect("decodes").to_rgb8();
                    (bytes.len(), ms, encode::psnr(&fb.rgb, decoded.as_raw()))
                });
                rows.push(row.named(
                    size,
                    &format!("JPEG ({})", encoder.name()),
                    &format!("q{quality}"),
                ));
            }
        }
        let row = measure(&frames, |fb| {
            let t = Instant::now();
            let bytes = encode::png(fb).expect("png");
            let ms = t.elapsed().as_secs_f64() * 1e3;
            let decoded = image::load_from_memory(&bytes).expect("decodes").to_rgb8();
            (bytes.len(), ms, encode::psnr(&fb.rgb, decoded.as_raw()))
        });
        rows.push(row.named(size, "PNG (lossless still)", "fast"));
        rows.extend(h264_rows(&frames, size, width, height));
        for factor in [4u32, 2] {
            let row = measure(&frames, |fb| {
                let camera = frames[0].1;
                let t = Instant::now();
                let bytes = encode::depth_block(fb, &camera, factor).expect("depth");
                (bytes.len(), t.elapsed().as_secs_f64() * 1e3, f64::NAN)
            });
            rows.push(row.named(
                size,
                "depth channel (16-bit PNG)",
                &format!("1/{factor} size"),
            ));
        }
    }
    for r in &rows {
        let psnr = if r.psnr_db.is_infinite() {
            "lossless".to_string()
        } else if r.psnr_db.is_nan() {
            "–".to_string()
        } else {
            format!("{:.1}", r.psnr_db)
        };
        println!(
            "| {} | {} | {} | {:.0} | {:.2} | {:.2} | {psnr} |",
            r.size, r.codec, r.setting, r.bytes_per_frame, r.mbit_per_s_at_30fps, r.encode_ms
        );
    }
    if let Some(path) = &args.json {
        write_json(path, &rows)?;
    }
    Ok(())
}

struct Measured {
    bytes: f64,
    encode_ms: f64,
    psnr: f64,
}

impl Measured {
    fn named(self, size: &str, codec: &str, setting: &str) -> CodecRow {
        CodecRow {
            size: size.into(),
            codec: codec.into(),
            setting: setting.into(),
            bytes_per_frame: self.bytes,
            mbit_per_s_at_30fps: self.bytes * 8.0 * 30.0 / 1e6,
            encode_ms: self.encode_ms,
            psnr_db: self.psnr,
        }
    }
}

/// Runs `f` on every frame: (bytes, ms, psnr) → means of bytes and PSNR, median of ms.
fn measure(
    frames: &[(Framebuffer, Camera)],
    mut f: impl FnMut(&Framebuffer) -> (usize, f64, f64),
) -> Measured {
    let results: Vec<(usize, f64, f64)> = frames.iter().map(|(fb, _)| f(fb)).collect();
    let n = results.len() as f64;
    Measured {
        bytes: results.iter().map(|r| r.0 as f64).sum::<f64>() / n,
        encode_ms: median(results.iter().map(|r| r.1).collect()),
        psnr: mean_psnr(results.iter().map(|r| r.2)),
    }
}

/// Mean PSNR; infinite only when every frame was bit-exact, NaN when no frame has one (the
/// depth channel, printed as `–`).
fn mean_psnr(values: impl Iterator<Item = f64>) -> f64 {
    let v: Vec<f64> = values.collect();
    if v.iter().all(|p| p.is_nan()) {
        return f64::NAN;
    }
    if v.iter().all(|p| p.is_infinite()) {
        return f64::INFINITY;
    }
    v.iter().filter(|p| p.is_finite()).sum::<f64>()
        / v.iter().filter(|p| p.is_finite()).count().max(1) as f64
}

#[cfg(feature = "h264")]
fn h264_rows(
    frames: &[(Framebuffer, Camera)],
    size: &str,
    width: u32,
    height: u32,
) -> Vec<CodecRow> {
    // Bit rates for 1280×720, scaled by the pixel count for other sizes.
    let scale = (width as f64 * height as f64) / (1280.0 * 720.0);
    [1.0f64, 2.0, 4.0, 8.0]
        .into_iter()
        .map(|mbit| {
            let bps = (mbit * 1e6 * scale) as u32;
            let mut stream = encode::H264Stream::new(width, height, bps, 30.0).expect("encoder");
            let mut decoder = openh264::decoder::Decoder::new().expect("decoder");
            let mut rgb = vec![0u8; width as usize * height as usize * 3];
            let row = measure(frames, |fb| {
                let t = Instant::now();
                let frame = stream.encode(&fb.rgb).expect("h264");
                let ms = t.elapsed().as_secs_f64() * 1e3;
                let psnr = match decoder.decode(&frame.bytes).expect("decodes") {
                    Some(yuv) => {
                        yuv.write_rgb8(&mut rgb);
                        encode::psnr(&fb.rgb, &rgb)
                    }
                    None => f64::NAN,
                };
                (frame.bytes.len(), ms, psnr)
            });
            row.named(
                size,
                "H.264 (OpenH264, baseline)",
                &format!("{:.1} Mbit/s target", bps as f64 / 1e6),
            )
        })
        .collect()
}

#[cfg(not(feature = "h264"))]
fn h264_rows(_: &[(Framebuffer, Camera)], _: &str, _: u32, _: u32) -> Vec<CodecRow> {
    Vec::new()
}
