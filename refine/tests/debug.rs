mod common;
use common::*;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use tubeloc_core::tube_pose::axis_angle;
use tubeloc_refine::{AxisState, RefineConfig, RefineInput, Refiner, Scene as FitScene, Seed};

fn save_pgm(path: &str, img: &tubeloc_core::Plane<f32>, marks: &[nalgebra::Point2<f64>]) {
    let mut bytes = format!("P5\n{} {}\n255\n", img.width, img.height).into_bytes();
    let mut px: Vec<u8> = img.data.iter().map(|v| (v * 255.0) as u8).collect();
    for m in marks {
        let (x, y) = (m.x.round() as i64, m.y.round() as i64);
        if x >= 0 && y >= 0 && (x as usize) < img.width && (y as usize) < img.height {
            px[y as usize * img.width + x as usize] = 0;
        }
    }
    bytes.extend(px);
    std::fs::write(path, bytes).unwrap();
}

#[test]
#[ignore]
fn debug_one() {
    let model = default_model();
    let refiner = Refiner::new(&tubeloc_core::TubeModel::default(), RefineConfig { decide_end: false, max_levels: std::env::var("LV").map(|v| v.parse().unwrap()).unwrap_or(4), ..Default::default() }).unwrap();
    let cam = camera(false);
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let (truth, up, gd) = random_truth(&mut rng, &model, &cam, (0.8, 1.6));
    let sc = render(&model, &cam, truth, up, gd, None, 11000, 0.01);
    let input = RefineInput { image: &sc.image, camera: &sc.camera, ground: None, scene: FitScene::default() };
    for (name, st) in [("truth", AxisState { c: truth.centre, a: truth.axis }), ("off", AxisState { c: truth.centre + nalgebra::Vector3::new(0.005, -0.003, 0.01), a: truth.axis })] {
        let p = refiner.refine_seed(&input, &Seed { state: st, end_known: true }, 0, 1.0, None);
        eprintln!("{name}: err {:.2} mm, {:.3} deg, conv {} {:?} stats {:?}", (p.centre - truth.centre).norm() * 1e3, axis_angle(&p.axis, &truth.axis).to_degrees(), p.converged, p.failure, p.residuals);
        let mut pts = refiner.contour_pixels(&cam, &p, 2.0);
        if name == "truthX" {
            let tp = tubeloc_core::TubeAxisPose::new(0, 1.0, truth.centre, truth.axis, 1.0).unwrap();
            pts = refiner.contour_pixels(&cam, &tp, 2.0);
        }
        save_pgm(&format!("/tmp/refine_{name}.pgm"), &sc.image, &pts);
    }
}
