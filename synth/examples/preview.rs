//! Renders one crop per terrain for a quick look: `cargo run --release -p tubeloc-synth --example preview -- OUTDIR`.
use tubeloc_synth::{render, rig, RenderOptions, Scene, SceneConfig, TerrainKind, TimeOfDay};

fn main() {
    let out = std::env::args().nth(1).unwrap_or_else(|| "/tmp/preview".into());
    std::fs::create_dir_all(&out).unwrap();
    let rig = rig::paper_rig();
    for (k, terrain) in [TerrainKind::Flagstone, TerrainKind::Cfa6, TerrainKind::Cfa2, TerrainKind::Ditch, TerrainKind::Riverbed].into_iter().enumerate() {
        let t0 = std::time::Instant::now();
        let cfg = SceneConfig::new(terrain, if k % 2 == 0 { TimeOfDay::Am } else { TimeOfDay::Pm }, k == 0);
        let scene = Scene::generate(&cfg, k as u64 + 1).unwrap();
        let t1 = std::time::Instant::now();
        let height = if k % 2 == 0 { 1.0 } else { 2.0 };
        let t_world_rig = rig::stop_pose(&nalgebra::Point3::origin(), rig::STOP_RADIUS_M, height, k, 8, scene.stop_offset).unwrap();
        let cam = &rig.cameras[1];
        let crop = cam.model.scaled(0.5).cropped(856, 400, 1024, 1024);
        let r = render(&scene, &crop, &(t_world_rig * cam.t_rig_cam), &RenderOptions::default());
        let t2 = std::time::Instant::now();
        eprintln!("{}: scene {:.2}s render {:.2}s, sun el {:.1} az {:.1}, rocks {}", terrain.name(), (t1 - t0).as_secs_f64(), (t2 - t1).as_secs_f64(), scene.sun.elevation_deg, scene.sun.azimuth_deg, scene.objects.rocks.len());
        image::save_buffer(format!("{out}/{}.png", terrain.name()), &r.rgb, 1024, 1024, image::ExtendedColorType::Rgb8).unwrap();
    }
}
