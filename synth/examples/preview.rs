//! Renders one 1024x1024 half-resolution crop per terrain, condition and height for a quick
//! look (and the contact sheet, see scripts/contact_sheet.py):
//! `cargo run --release -p tubeloc-synth --example preview -- OUTDIR`.
use tubeloc_synth::{render, rig, RenderOptions, Scene, SceneConfig, TerrainKind, TimeOfDay};

fn main() {
    let out = std::env::args().nth(1).unwrap_or_else(|| "/tmp/preview".into());
    std::fs::create_dir_all(&out).unwrap();
    let rig = rig::paper_rig();
    let cases = [
        (TerrainKind::Flagstone, TimeOfDay::Am, true, 1.0),
        (TerrainKind::Flagstone, TimeOfDay::Pm, false, 2.0),
        (TerrainKind::Cfa6, TimeOfDay::Am, false, 1.0),
        (TerrainKind::Cfa6, TimeOfDay::Pm, true, 2.0),
        (TerrainKind::Cfa2, TimeOfDay::Am, true, 2.0),
        (TerrainKind::Cfa2, TimeOfDay::Pm, true, 1.0),
        (TerrainKind::Ditch, TimeOfDay::Am, false, 2.0),
        (TerrainKind::Ditch, TimeOfDay::Pm, false, 1.0),
        (TerrainKind::Riverbed, TimeOfDay::Am, false, 1.0),
        (TerrainKind::Riverbed, TimeOfDay::Pm, false, 2.0),
    ];
    for (k, &(terrain, time, tags, height)) in cases.iter().enumerate() {
        let t0 = std::time::Instant::now();
        let scene = Scene::generate(&SceneConfig::new(terrain, time, tags), k as u64 + 1).unwrap();
        let t1 = std::time::Instant::now();
        let t_world_rig = rig::stop_pose(&nalgebra::Point3::origin(), rig::STOP_RADIUS_M, height, k, 8, scene.stop_offset).unwrap();
        let cam = &rig.cameras[1];
        let crop = cam.model.scaled(0.5).cropped(856, if height > 1.5 { 400 } else { 500 }, 1024, 1024);
        let r = render(&scene, &crop, &(t_world_rig * cam.t_rig_cam), &RenderOptions::default());
        let t2 = std::time::Instant::now();
        eprintln!("{} {}: scene {:.2}s render {:.2}s, sun el {:.1} az {:.1}, rocks {}", terrain.name(), time.name(), (t1 - t0).as_secs_f64(), (t2 - t1).as_secs_f64(), scene.sun.elevation_deg, scene.sun.azimuth_deg, scene.objects.rocks.len());
        let name = format!("{k:02}_{}_{}_{}_h{height}.png", terrain.name(), time.name(), if tags { "with-tags" } else { "no-tags" });
        image::save_buffer(format!("{out}/{name}"), &r.rgb, 1024, 1024, image::ExtendedColorType::Rgb8).unwrap();
    }
}
