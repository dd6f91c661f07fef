//! The nominal ground (`Scene::nominal_ground_height`, the datasets' `ground_height_m`): the
//! median terrain height within the capture stops. Tubes rest on the terrain, so the plane at
//! that height must lie nearer their resting heights than the height field's datum z = 0,
//! which on flagstone is the bottom of the cracks between the slabs.

use tubeloc_synth::rig::STOP_RADIUS_M;
use tubeloc_synth::{Scene, SceneConfig, TerrainKind, TimeOfDay};

/// Heights (world z, metres) of the tubes' lowest body points: centre minus the radius it
/// rests on (the generator sets the centre 0.92 r_max above the ground under it).
fn tube_rest_heights(scene: &Scene) -> Vec<f64> {
    let r_max = 0.0115;
    scene.tube_poses().iter().map(|p| p.translation().z - 0.92 * r_max).collect()
}

fn mean_abs(v: impl Iterator<Item = f64>) -> f64 {
    let v: Vec<f64> = v.collect();
    v.iter().map(|x| x.abs()).sum::<f64>() / v.len() as f64
}

#[test]
fn flagstone_ground_lies_on_the_slabs_where_the_tubes_rest() {
    for seed in [3u64, 8] {
        let scene = Scene::generate(&SceneConfig::new(TerrainKind::Flagstone, TimeOfDay::Am, false), seed).unwrap();
        let h = scene.nominal_ground_height(STOP_RADIUS_M);
        assert!((0.01..0.04).contains(&h), "seed {seed}: flagstone slabs stand 1.2-3.6 cm proud, nominal ground at {h} m");
        let rest = tube_rest_heights(&scene);
        assert!(rest.len() >= 5, "seed {seed}: {} tubes", rest.len());
        let off_nominal = mean_abs(rest.iter().map(|z| z - h));
        let off_datum = mean_abs(rest.iter().copied());
        assert!(off_nominal < 0.5 * off_datum, "seed {seed}: tubes {off_nominal} m from the nominal ground, {off_datum} m from z = 0");
    }
}

#[test]
fn rolling_regolith_keeps_its_ground_near_the_datum_and_is_deterministic() {
    let cfg = SceneConfig::new(TerrainKind::Cfa6, TimeOfDay::Pm, false);
    let scene = Scene::generate(&cfg, 5).unwrap();
    let h = scene.nominal_ground_height(STOP_RADIUS_M);
    assert!(h.abs() < 0.01, "regolith relief is centred on z = 0, nominal ground at {h} m");
    assert!(mean_abs(tube_rest_heights(&scene).into_iter().map(|z| z - h)) < 0.015);
    assert_eq!(h, Scene::generate(&cfg, 5).unwrap().nominal_ground_height(STOP_RADIUS_M));
    // A disc too small to hold a vertex falls back to the height at the origin.
    assert_eq!(scene.nominal_ground_height(1e-6), scene.hf.height(0.0, 0.0));
}
