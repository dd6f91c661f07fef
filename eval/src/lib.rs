//! tubeloc-eval (see the README for what this crate owns).
//!
//! COCO evaluation ([`coco_eval`], pycocotools-identical) and per-attribute breakdowns
//! ([`breakdown`]):
//!
//! ```
//! use tubeloc_core::{CocoDataset, CocoResult};
//! use tubeloc_eval::coco_eval::{CocoEvaluator, IouType};
//!
//! let gt: CocoDataset = serde_json::from_str(r#"{
//!   "images": [{"id": 1, "width": 64, "height": 48, "file_name": "a.png"}],
//!   "annotations": [{"id": 1, "image_id": 1, "category_id": 1, "area": 200, "bbox": [10, 10, 20, 10]}],
//!   "categories": [{"id": 1, "name": "tube"}]}"#).unwrap();
//! let dt: Vec<CocoResult> = serde_json::from_str(
//!   r#"[{"image_id": 1, "category_id": 1, "score": 0.9, "bbox": [11, 10, 20, 10]}]"#).unwrap();
//! let result = CocoEvaluator::new(&gt, &dt, IouType::Bbox)?.evaluate();
//! print!("{}", result.summary_text());       // the 12 lines pycocotools prints
//! let ap50 = result.stats[1];                  // IoU 190/210 = 0.90 >= 0.5: AP50 = 1
//! assert!((ap50 - 1.0).abs() < 1e-9);
//! for t in 0..result.iou_thrs.len() {          // PR curves for plotting, IoU 0.50 ... 0.95
//!     let curve: [f64; 101] = result.pr_curve(t); // precision at recall 0.00, 0.01, ..., 1.00
//!     assert!(curve.iter().all(|&p| p == -1.0 || (0.0..=1.0).contains(&p)));
//! }
//! # Ok::<(), tubeloc_eval::coco_eval::EvalError>(())
//! ```
#![warn(missing_docs)]
pub mod bootstrap;
pub mod breakdown;
pub mod calibration;
pub mod coco_eval;
pub mod negative_cuts;
pub mod plot;
pub mod plot_bar;
pub mod plot_hist;
pub mod plot_pr;
pub mod pose;
pub mod pose_bop;
pub mod pose_evidence_fit;
pub mod pose_match;
pub mod pose_summary;
pub mod report;
