//! The server's encoders (server/src/encode.rs): JPEG quality and H.264 bit rate against PSNR,
//! on frames of the animated demo along a camera orbit, each encoded on one core. The error
//! plotted is the RMS error relative to full scale, `10^(−PSNR/20)`; the time is encode ms per
//! frame (the decode for PSNR is not timed).

use crate::accuracy::stats::Row;
use isoray_render::scenes::DemoScene;
use isoray_render::{Backend, Framebuffer, View};
use isoray_server::encode::{self, JpegEncoder};
use std::sync::Arc;
use std::time::Instant;

const WIDTH: u32 = 640;
const HEIGHT: u32 = 480;

/// One row per JPEG quality and per H.264 bit rate.
pub fn rows(backend: &Backend, frames: usize) -> Result<Vec<Row>, String> {
    let demo = DemoScene::ALL
        .iter()
        .copied()
        .find(|d| d.id() == "tornado-4k")
        .unwrap_or(DemoScene::Tornado4k);
    let images: Vec<Framebuffer> = (0..frames.max(1))
        .map(|i| {
            let scene = Arc::new(demo.state_at(1.0 + i as f64 / 30.0)).prepare();
            let camera = crate::stream::path_camera(demo, i);
            let view = View {
                width: WIDTH,
                height: HEIGHT,
                camera,
                isovalue: demo.default_isovalue(),
            };
            backend.render(&scene, &view)
        })
        .collect();
    let mut rows = Vec::new();
    for encoder in JpegEncoder::available() {
        for quality in [30u8, 50, 70, 85, 95] {
            let mut m = Measure::default();
            for fb in &images {
                let t = Instant::now();
                let bytes = encode::jpeg_rgb(&fb.rgb, fb.width, fb.height, quality, encoder)
                    .map_err(|e| e.to_string())?;
                let ms = t.elapsed().as_secs_f64() * 1e3;
                let decoded = image::load_from_memory(&bytes)
                    .map_err(|e| e.to_string())?
                    .to_rgb8();
                m.add(bytes.len(), ms, encode::psnr(&fb.rgb, decoded.as_raw()));
            }
            rows.push(m.row(
                demo,
                format!("JPEG ({}), quality", encoder.name()),
                format!("q{quality}"),
            ));
        }
    }
    rows.extend(h264(demo, &images)?);
    Ok(rows)
}

#[derive(Default)]
struct Measure {
    bytes: Vec<f64>,
    ms: Vec<f64>,
    psnr: Vec<f64>,
}

impl Measure {
    fn add(&mut self, bytes: usize, ms: f64, psnr: f64) {
        self.bytes.push(bytes as f64);
        self.ms.push(ms);
        if psnr.is_finite() {
            self.psnr.push(psnr);
        }
    }

    fn row(self, demo: DemoScene, family: String, setting: String) -> Row {
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
        Row {
            kind: "codecs",
            scene: format!("{} {WIDTH}x{HEIGHT}", demo.id()),
            family,
            setting,
            ms: crate::common::median(self.ms.clone()),
            rays: self.ms.len(),
            psnr_db: mean(&self.psnr),
            bytes: mean(&self.bytes),
            extent: 1.0,
            ..Row::default()
        }
    }
}

#[cfg(feature = "h264")]
fn h264(demo: DemoScene, images: &[Framebuffer]) -> Result<Vec<Row>, String> {
    let mut rows = Vec::new();
    // Bit rates at 30 fps for 640×480 (a quarter of the 1280×720 figures, about).
    for kbit in [250u32, 500, 1000, 2000, 4000] {
        let mut stream =
            encode::H264Stream::new(WIDTH, HEIGHT, kbit * 1000, 30.0).map_err(|e| e.to_string())?;
        let mut decoder = openh264::decoder::Decoder::new().map_err(|e| e.to_string())?;
        let mut rgb = vec![0u8; WIDTH as usize * HEIGHT as usize * 3];
        let mut m = Measure::default();
        for fb in images {
            let t = Instant::now();
            let frame = stream.encode(&fb.rgb).map_err(|e| e.to_string())?;
            let ms = t.elapsed().as_secs_f64() * 1e3;
            let psnr = match decoder.decode(&frame.bytes).map_err(|e| e.to_string())? {
                Some(yuv) => {
                    yuv.write_rgb8(&mut rgb);
                    encode::psnr(&fb.rgb, &rgb)
                }
                None => f64::NAN,
            };
            m.add(frame.bytes.len(), ms, psnr);
        }
        rows.push(m.row(
            demo,
            "H.264 (OpenH264), bit rate".into(),
            format!("{kbit} kbit/s"),
        ));
    }
    Ok(rows)
}

#[cfg(not(feature = "h264"))]
fn h264(_: DemoScene, _: &[Framebuffer]) -> Result<Vec<Row>, String> {
    Ok(Vec::new())
}
