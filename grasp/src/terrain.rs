//! The terrain around a tube from stereo points: a height map over the ground plane, each cell
//! that stands above the ground a cuboid column, all in one parry3d `Compound`.
//!
//! parry3d 0.25's `HeightField` answers no distance queries (it is not a composite shape there),
//! so the height map is a compound of cuboids, which parry queries through its bounding-volume
//! tree.

use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use parry3d_f64::shape::{Compound, SharedShape};
use serde::{Deserialize, Serialize};
use tubeloc_core::{GroundPlane, TubeAxisPose, TubeModel};

/// How stereo points become terrain columns.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TerrainSettings {
    /// Cell size of the height map, millimetres.
    pub cell_mm: f64,
    /// Least number of points in a cell for its height to count.
    pub min_points: usize,
    /// A cell is an obstacle when its median height above the ground exceeds this, millimetres
    /// (below it the ground plane already stands for it; stereo noise lives there).
    pub min_height_mm: f64,
    /// Points within a located tube's largest radius plus this margin of its axis segment are
    /// the tube's own surface, not terrain, millimetres.
    pub tube_margin_mm: f64,
    /// The same margin in pixels at the tube's distance, where that is wider (stereo matching
    /// spreads a tube's depth a few pixels onto the ground beside it).
    pub tube_margin_px: f64,
    /// Columns reach this far below the ground plane so that they are solid to it, millimetres.
    pub sink_mm: f64,
}

impl Default for TerrainSettings {
    fn default() -> Self {
        TerrainSettings { cell_mm: 8.0, min_points: 3, min_height_mm: 4.0, tube_margin_mm: 5.0, tube_margin_px: 8.0, sink_mm: 5.0 }
    }
}

/// Terrain columns near one tube (camera frame, metres).
#[derive(Clone)]
pub struct Terrain {
    /// Placement of the height-map frame in the camera frame (z along the ground's up normal).
    pub pose: Isometry3<f64>,
    /// The columns in the height-map frame; `None` when no cell stands above the ground.
    pub columns: Option<Compound>,
    /// Cells that had enough points to measure a height (columns or flat).
    pub measured_cells: usize,
    /// Cells that became columns.
    pub column_cells: usize,
    /// Height of the highest column's top in the height-map frame (above the ground), metres;
    /// 0 without columns.
    pub top: f64,
}

impl std::fmt::Debug for Terrain {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Terrain").field("measured_cells", &self.measured_cells).field("column_cells", &self.column_cells).finish()
    }
}

impl Terrain {
    /// The terrain within `radius` metres (measured in the ground plane) of `around`'s centre
    /// from `points` (camera frame, metres): points on any of `tubes` (the located tubes, the
    /// target included) are left out, the rest binned into square cells of the ground plane;
    /// each cell with at least `min_points` points has the median of their heights above
    /// `ground`, and a cell higher than `min_height_mm` becomes a cuboid column from `sink_mm`
    /// below the ground up to that height. `metres_per_px` is the size of a pixel at the tube's
    /// distance (for `tube_margin_px`; 0 without a camera).
    #[allow(clippy::too_many_arguments)]
    pub fn from_points(points: &[Point3<f64>], ground: &GroundPlane, around: &TubeAxisPose, radius: f64, tubes: &[TubeAxisPose], model: &TubeModel, settings: &TerrainSettings, metres_per_px: f64) -> Terrain {
        let n = ground.normal;
        // Height-map frame: origin under the tube centre on the ground, z up, x along the axis
        // as seen from above (any horizontal direction for a standing tube).
        let origin = around.centre - n * ground.height_of(&around.centre);
        let ax = around.axis - n * around.axis.dot(&n);
        let x = if ax.norm() > 1e-6 { ax.normalize() } else { tubeloc_core::tube_pose::tangent_basis(&n).0 };
        let y = n.cross(&x);
        let rot = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, n]));
        let pose = Isometry3::from_parts(Translation3::from(origin), UnitQuaternion::from_rotation_matrix(&rot));
        let cell = settings.cell_mm * 1e-3;
        let half_cells = (radius / cell).ceil().max(1.0) as i64;
        let side = 2 * half_cells;
        let margin = (settings.tube_margin_mm * 1e-3).max(settings.tube_margin_px * metres_per_px);
        let reach = model.max_radius() + margin;
        let half_len = model.length / 2.0 + margin;
        let on_a_tube = |p: &Vector3<f64>| {
            tubes.iter().any(|t| {
                let d = p - t.centre;
                let along = d.dot(&t.axis);
                along.abs() <= half_len && (d - t.axis * along).norm() <= reach
            })
        };
        // (cell index, height) pairs, sorted by cell then height: medians without a list per cell.
        let mut binned: Vec<(i64, f64)> = Vec::with_capacity(points.len());
        for p in points {
            let d = p.coords - origin;
            let (u, v, h) = (d.dot(&x), d.dot(&y), d.dot(&n));
            if !(u.is_finite() && v.is_finite() && h.is_finite()) || u.abs() >= radius || v.abs() >= radius || on_a_tube(&p.coords) {
                continue;
            }
            let (i, j) = ((u / cell).floor() as i64 + half_cells, (v / cell).floor() as i64 + half_cells);
            if (0..side).contains(&i) && (0..side).contains(&j) {
                binned.push((j * side + i, h));
            }
        }
        binned.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)));
        let (min_height, sink) = (settings.min_height_mm * 1e-3, settings.sink_mm * 1e-3);
        let mut columns = Vec::new();
        let mut measured_cells = 0;
        let mut top: f64 = 0.0;
        for run in binned.chunk_by(|a, b| a.0 == b.0) {
            if run.len() < settings.min_points.max(1) {
                continue;
            }
            measured_cells += 1;
            let h = run[run.len() / 2].1;
            if h > min_height {
                top = top.max(h);
                let (i, j) = (run[0].0 % side, run[0].0 / side);
                let (u, v) = (((i - half_cells) as f64 + 0.5) * cell, ((j - half_cells) as f64 + 0.5) * cell);
                let at = Isometry3::translation(u, v, 0.5 * (h - sink));
                columns.push((at, SharedShape::cuboid(cell / 2.0, cell / 2.0, 0.5 * (h + sink))));
            }
        }
        let column_cells = columns.len();
        Terrain { pose, columns: (!columns.is_empty()).then(|| Compound::new(columns)), measured_cells, column_cells, top }
    }
}
