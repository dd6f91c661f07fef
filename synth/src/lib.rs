//! tubeloc-synth: the Mars-yard scene generator and ray-cast renderer behind tubeloc's benchmark.
//!
//! Typical use:
//!
//! ```no_run
//! use tubeloc_synth::{render, RenderOptions, Scene, SceneConfig, TerrainKind, TimeOfDay, rig};
//! let scene = Scene::generate(&SceneConfig::new(TerrainKind::Cfa6, TimeOfDay::Am, false), 42).unwrap();
//! let rig = rig::paper_rig();
//! let t_world_rig = rig::stop_pose(&nalgebra::Point3::origin(), rig::STOP_RADIUS_M, 1.0, 0, 8, scene.stop_offset).unwrap();
//! let cam = &rig.cameras[1];
//! let t_world_cam = t_world_rig * cam.t_rig_cam;
//! let crop = cam.model.scaled(0.5).cropped(856, 400, 1024, 1024);
//! let out = render(&scene, &crop, &t_world_cam, &RenderOptions::default());
//! // out.rgb (sRGB bytes), out.instance (tube i + 1 per pixel), out.depth (camera z, m)
//! ```
//!
//! Frames follow the workspace conventions: world x east, y north, z up (metres); cameras are
//! OpenCV frames; `T_a_b` maps frame-b points into frame a; the tube frame has +z toward the seal.
#![warn(missing_docs)]

pub mod calib_set;
pub mod composite;
pub mod dataset;
pub mod error;
pub mod heightfield;
pub mod mount;
pub mod noise;
pub mod objects;
pub mod ray;
pub mod real_frames;
pub mod real_set;
pub mod render;
pub mod rig;
pub mod rock;
pub mod scene;
pub mod sensor;
pub mod single;
pub mod stereo_set;
pub mod sun;
pub mod tags;
pub mod terrain;
pub mod truth;
pub mod tube_shape;

pub use dataset::{write_dataset, DatasetSpec, DatasetSummary};
pub use error::SynthError;
pub use render::{render, RenderOptions, RenderOutput, SurfaceKind};
pub use scene::{Scene, SceneConfig, TimeOfDay, TubeCase, TubeInfo};
pub use sensor::SensorOptions;
pub use sun::Sun;
pub use terrain::TerrainKind;
pub use truth::{tube_truth, Occlusion, TubeTruth};
pub use tube_shape::TubeShape;
