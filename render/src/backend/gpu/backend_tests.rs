//! The GPU backend's own behaviour, on lavapipe in CI: double-buffered frame buffers, the
//! memory budget, and the device's stage times reported with each frame.

use crate::backend::accumulator::{self, TracePasses};
use crate::backend::cpu::CpuBackend;
use crate::backend::gpu::agreement_tests::{gpu, setup};
use crate::backend::gpu::backend::{GpuBackend, SLOTS};
use crate::backend::gpu::device::AdapterChoice;
use crate::effects::toggles::Effects;
use crate::scenes::DemoScene;
use crate::view::View;

/// While one buffer set is busy (a frame tracing or reading back on it), the next frame
/// does not wait for it: it uploads into and traces on the other set, with the same image.
#[test]
fn a_frame_traces_on_the_other_buffer_set_while_one_is_busy() {
    assert_eq!(SLOTS, 2);
    let gpu = gpu();
    let (scene, view) = setup(DemoScene::Blobs);
    let (alone, _) = gpu.render_primary(&scene, &view);
    let first = gpu.allocations();
    {
        // Set 0 is held as a frame tracing on it would hold it: this thread would wait
        // forever if the next frame needed it.
        let _busy = gpu.hold_slot(0);
        let (beside, times) = gpu.render_primary(&scene, &view);
        assert!(beside == alone, "the other set traces the same image");
        assert_eq!(times.passes, 1, "on the device");
    }
    assert!(
        gpu.allocations() > first,
        "the second set got its own buffers ({first} -> {})",
        gpu.allocations()
    );
    // Two threads tracing two scenes at once get each its own image.
    let (tets, tets_view) = setup(DemoScene::TetGyroid);
    let (tets_alone, _) = gpu.render_primary(&tets, &tets_view);
    let (a, b) = std::thread::scope(|s| {
        let a = s.spawn(|| gpu.render_primary(&scene, &view).0);
        let b = s.spawn(|| gpu.render_primary(&tets, &tets_view).0);
        (a.join().expect("thread"), b.join().expect("thread"))
    });
    assert!(
        a == alone && b == tets_alone,
        "concurrent frames keep their images"
    );
    assert_eq!(gpu.frames(), (5, 0));
}

/// A scene whose arrays do not fit the memory budget is refused for the GPU before anything
/// is allocated for it, and the CPU traces it (same image), with the reason kept; a scene
/// that fits goes on tracing on the device.
#[test]
fn a_scene_over_the_memory_budget_is_traced_on_the_cpu() {
    // 1 MiB per buffer set: the 48 blobs fit, the 100,000 scattered balls do not.
    let gpu = GpuBackend::new(2, AdapterChoice::Any, 2 << 20).expect("a Vulkan adapter");
    let cpu = CpuBackend::new(2).expect("pool");
    let small = |demo| {
        let (scene, view) = setup(demo);
        let view = View {
            width: 40,
            height: 30,
            ..view
        };
        (scene, view)
    };
    let (blobs, blobs_view) = small(DemoScene::Blobs);
    gpu.render_primary(&blobs, &blobs_view);
    assert_eq!(gpu.frames(), (1, 0), "the small scene fits");
    let allocated = gpu.allocations();

    let (big, big_view) = small(DemoScene::Scattered100k);
    let (image, times) = gpu.render_primary(&big, &big_view);
    assert_eq!(gpu.frames(), (1, 1), "the large scene went to the CPU");
    assert_eq!(times.passes, 0);
    assert!(
        image == cpu.render_primary(&big, &big_view).0,
        "the CPU's image"
    );
    let why = gpu.last_fallback().expect("a reason");
    assert!(why.contains("budget") && why.contains("MiB"), "{why}");
    assert_eq!(gpu.allocations(), allocated, "nothing allocated for it");
    // The same state again is refused from what was learnt, and effects frames too.
    let (_, rays) = accumulator::render_effects(&gpu, &big, &big_view, &Effects::default());
    assert_eq!(rays.device.passes, 0);
    assert_eq!(gpu.frames(), (1, 2));
    assert!(!gpu.has_failed(), "a refusal is not a failure");

    gpu.render_primary(&blobs, &blobs_view);
    assert_eq!(
        gpu.frames(),
        (2, 2),
        "the small scene still traces on the device"
    );
}

/// The device's stage times come back with each frame it traced (the server puts them in
/// the frame header and /metrics), and nothing for the CPU's frames.
#[test]
fn device_stage_times_come_with_each_frame() {
    let gpu = gpu();
    let cpu = CpuBackend::new(2).expect("pool");
    let (scene, view) = setup(DemoScene::Blobs);
    let effects = Effects::default();
    let (_, rays) = accumulator::render_effects(&gpu, &scene, &view, &effects);
    let d = rays.device;
    assert_eq!(d.passes, 1, "{d:?}");
    assert!(d.upload_us + d.trace_us + d.readback_us > 0, "{d:?}");
    let (_, rays) = accumulator::render_effects(&cpu, &scene, &view, &effects);
    assert_eq!(
        rays.device,
        Default::default(),
        "the CPU reports no device time"
    );
}
