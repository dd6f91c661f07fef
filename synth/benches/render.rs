//! Rendering throughput: a 1024x1024 crop at half resolution with shadows, sensor model
//! included, for two terrains. Run `cargo bench -p tubeloc-synth --bench render`; the
//! megapixels per second are 1.048576 / median seconds.

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::Point3;
use tubeloc_synth::{render, rig, RenderOptions, Scene, SceneConfig, TerrainKind, TimeOfDay};

fn bench_render(c: &mut Criterion) {
    let mut group = c.benchmark_group("render_1024_crop_shadows");
    group.sample_size(10);
    let rig = rig::paper_rig();
    for terrain in [TerrainKind::Cfa6, TerrainKind::Riverbed] {
        let scene = Scene::generate(&SceneConfig::new(terrain, TimeOfDay::Pm, false), 11).unwrap();
        let t_world_rig = rig::stop_pose(&Point3::origin(), rig::STOP_RADIUS_M, 1.0, 2, 8, scene.stop_offset).unwrap();
        let cam = &rig.cameras[1];
        let crop = cam.model.scaled(0.5).cropped(856, 400, 1024, 1024);
        let pose = t_world_rig * cam.t_rig_cam;
        group.bench_function(terrain.name(), |b| b.iter(|| render(&scene, &crop, &pose, &RenderOptions::default())));
    }
    group.finish();
    let mut g2 = c.benchmark_group("scene_generate");
    g2.sample_size(10);
    g2.bench_function("cfa6_8m_5mm", |b| b.iter(|| Scene::generate(&SceneConfig::new(TerrainKind::Cfa6, TimeOfDay::Am, true), 3).unwrap()));
    g2.finish();
}

criterion_group!(benches, bench_render);
criterion_main!(benches);
