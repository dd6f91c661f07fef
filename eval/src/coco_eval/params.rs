//! Evaluation parameters: pycocotools' `Params` for `segm`/`bbox`, bit for bit.

/// Which geometry the IoU is computed on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum IouType {
    /// Mask IoU on COCO RLE.
    Segm,
    /// Box IoU on `[x, y, w, h]`.
    Bbox,
}

impl IouType {
    /// `"segm"` or `"bbox"`, as pycocotools names it.
    pub fn name(self) -> &'static str {
        match self {
            IouType::Segm => "segm",
            IouType::Bbox => "bbox",
        }
    }
}

impl std::str::FromStr for IouType {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "segm" => Ok(IouType::Segm),
            "bbox" => Ok(IouType::Bbox),
            _ => Err(format!("unknown IoU type {s:?} (expected segm or bbox)")),
        }
    }
}

/// Number of IoU thresholds (0.50:0.05:0.95).
pub const NUM_IOU_THRS: usize = 10;
/// Number of recall thresholds (0:0.01:1).
pub const NUM_REC_THRS: usize = 101;
/// Detections per image considered: 1, 10, 100 (the last also caps IoU computation).
pub const MAX_DETS: [usize; 3] = [1, 10, 100];
/// Area ranges in pixels² `[min, max]`, both inclusive: all, small, medium, large.
pub const AREA_RNGS: [[f64; 2]; 4] = [[0.0, 1e10], [0.0, 1024.0], [1024.0, 9216.0], [9216.0, 1e10]];
/// Labels of [`AREA_RNGS`].
pub const AREA_LABELS: [&str; 4] = ["all", "small", "medium", "large"];

/// IoU thresholds exactly as `np.linspace(.5, 0.95, 10)`: `t_i = i * (0.45 / 9) + 0.5`, last = 0.95.
pub fn iou_thresholds() -> [f64; NUM_IOU_THRS] {
    linspace(0.5, 0.95)
}

/// Recall thresholds exactly as `np.linspace(0, 1, 101)`.
pub fn recall_thresholds() -> [f64; NUM_REC_THRS] {
    linspace(0.0, 1.0)
}

fn linspace<const N: usize>(start: f64, stop: f64) -> [f64; N] {
    let step = (stop - start) / (N - 1) as f64;
    let mut out = [0.0; N];
    for (i, v) in out.iter_mut().enumerate() {
        *v = i as f64 * step + start;
    }
    out[N - 1] = stop;
    out
}
