//! A single tube lying on flat ground, seen from a given camera pose: the fixture other crates
//! (template matching, pose refinement, stereo) use in their unit tests.
//!
//! Given `T_cam_tube`, the ground is the plane tangent to the tube's bottom whose normal bisects
//! the camera's up direction (−y) and the direction from the tube toward the camera, made
//! perpendicular to the tube axis: the tube lies on it and the camera looks down on it
//! obliquely, as a rover mast camera does. World frame: origin on the ground under the
//! tube centre, z = ground normal, so `T_world_tube` has the tube centre at height `r` (the
//! largest section radius).

use crate::heightfield::HeightField;
use crate::objects::{Objects, TubeInstance};
use crate::scene::{Scene, SceneConfig, TimeOfDay, TubeCase, TubeInfo};
use crate::sun::Sun;
use crate::terrain::{srgb_to_linear, TerrainKind, TerrainParams, REGOLITH_SRGB};
use crate::tube_shape::TubeShape;
use crate::SynthError;
use nalgebra::{Matrix3, Rotation3, Vector3};
use rayon::prelude::*;
use std::sync::Arc;
use tubeloc_core::{Plane, Pose, TubeModel};

/// Ground appearance of the single-tube fixture.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ground {
    /// Uniform regolith colour.
    Plain,
    /// Regolith with the benchmark's procedural albedo texture (seeded).
    Textured,
}

/// A scene with one parametric tube (the default model) on flat ground, and `T_world_cam`
/// such that the tube sits at `t_cam_tube` in the camera frame. `sun` sets the light.
/// Fails when the camera would be below the ground.
pub fn single_tube_scene(t_cam_tube: &Pose, ground: Ground, sun: Sun, seed: u64) -> Result<(Scene, Pose), SynthError> {
    single_tube_scene_with(t_cam_tube, ground, sun, seed, Arc::new(TubeShape::from_model(&TubeModel::default())))
}

/// As [`single_tube_scene`] with any tube geometry.
pub fn single_tube_scene_with(t_cam_tube: &Pose, ground: Ground, sun: Sun, seed: u64, shape: Arc<TubeShape>) -> Result<(Scene, Pose), SynthError> {
    let (_hl, r) = shape.bounds();
    let axis_cam = t_cam_tube.transform_vector(&Vector3::z());
    let toward_cam = -t_cam_tube.translation().normalize();
    let blend = (toward_cam - Vector3::y()).normalize();
    let mut n_cam = blend - axis_cam * axis_cam.dot(&blend);
    if n_cam.norm() < 1e-6 {
        n_cam = toward_cam - axis_cam * axis_cam.dot(&toward_cam);
    }
    if n_cam.norm() < 1e-6 {
        return Err(SynthError::Invalid("the camera looks along the tube axis: no ground to lay it on".into()));
    }
    let n_cam = n_cam.normalize();
    // World axes in the camera frame: z = ground normal, x = tube axis, y = z × x.
    let y_cam = n_cam.cross(&axis_cam);
    let r_cam_world = Matrix3::from_columns(&[axis_cam, y_cam, n_cam]);
    let centre_cam = t_cam_tube.translation();
    let origin_cam = centre_cam - n_cam * r;
    let t_cam_world = Pose::from_parts(Rotation3::from_matrix_unchecked(r_cam_world), origin_cam);
    let t_world_cam = t_cam_world.inverse();
    if t_world_cam.translation().z <= 0.0 {
        return Err(SynthError::Invalid("camera is below the ground the tube lies on".into()));
    }
    let t_world_tube = t_world_cam * *t_cam_tube;
    let mut config = SceneConfig::new(TerrainKind::Cfa6, TimeOfDay::Am, false);
    config.extent_m = 6.0;
    config.cell_m = 0.01;
    config.tubes = Some(1);
    config.tube_shape = shape.clone();
    let n = 601;
    let hf = HeightField::flat(n, n, 0.01, -3.0, -3.0, 0.0);
    let params = TerrainParams { kind: TerrainKind::Cfa6, seed: seed as u32, ditch: (0.0, 0.0), channels: Vec::new() };
    let plain = srgb_to_linear(REGOLITH_SRGB);
    let albedo: Vec<[u8; 4]> = (0..n * n)
        .into_par_iter()
        .map(|k| {
            let a = match ground {
                Ground::Plain => plain,
                Ground::Textured => params.sample(-3.0 + (k % n) as f64 * 0.01, -3.0 + (k / n) as f64 * 0.01).1,
            };
            let enc = crate::terrain::linear_to_srgb8;
            [enc(a[0]), enc(a[1]), enc(a[2]), 0]
        })
        .collect();
    let tube = TubeInstance { t_world_tube, shape, dust: 0.0, seed: seed as u32 };
    let mut objects = Objects::new(Vec::new(), vec![tube], Vec::new());
    objects.build_grid(-3.0, -3.0, 0.1, 60, 60);
    let mut scene = Scene {
        config,
        seed,
        sun,
        solar_hour: 12.0,
        day_of_year: 172.0,
        hf,
        albedo,
        objects,
        tube_info: vec![TubeInfo { case: TubeCase::Unoccluded, dust: 0.0, carries_tags: false }],
        mount: None,
        sky: Plane::new(1, 1),
        sky_cell: 0.02,
        stop_offset: 0.0,
        terrain: params,
    };
    scene.sky = scene.compute_sky();
    Ok((scene, t_world_cam))
}
