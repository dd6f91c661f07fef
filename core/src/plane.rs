//! `Plane<T>`: a contiguous single-channel image buffer, row-major, stride = width.
//!
//! Hot loops across tubeloc work on planes rather than `image` crate types so that they
//! vectorize and rayon can split rows (`data.par_chunks(width)`).

/// A single-channel image of `width * height` values stored row by row.
#[derive(Clone, Debug, PartialEq)]
pub struct Plane<T> {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Row-major pixel values, `data[y * width + x]`.
    pub data: Vec<T>,
}

impl<T: Copy + Default> Plane<T> {
    /// A plane filled with `T::default()`.
    pub fn new(width: usize, height: usize) -> Self {
        Plane { width, height, data: vec![T::default(); width * height] }
    }
    /// A plane filled with `value`.
    pub fn filled(width: usize, height: usize, value: T) -> Self {
        Plane { width, height, data: vec![value; width * height] }
    }
    /// Wraps an existing buffer; panics if `data.len() != width * height` (programming error).
    pub fn from_vec(width: usize, height: usize, data: Vec<T>) -> Self {
        assert_eq!(data.len(), width * height, "plane buffer size mismatch");
        Plane { width, height, data }
    }
    /// Pixel at column `x`, row `y` (panics when out of bounds).
    #[inline]
    pub fn get(&self, x: usize, y: usize) -> T {
        self.data[y * self.width + x]
    }
    /// Mutable pixel at column `x`, row `y`.
    #[inline]
    pub fn get_mut(&mut self, x: usize, y: usize) -> &mut T {
        &mut self.data[y * self.width + x]
    }
    /// Row `y` as a slice.
    #[inline]
    pub fn row(&self, y: usize) -> &[T] {
        &self.data[y * self.width..(y + 1) * self.width]
    }
}

impl Plane<f32> {
    /// Bilinear sample at sub-pixel position (pixel centres at integers), clamped to the border.
    pub fn sample_bilinear(&self, x: f32, y: f32) -> f32 {
        let xm = (self.width - 1) as f32;
        let ym = (self.height - 1) as f32;
        let x = x.clamp(0.0, xm);
        let y = y.clamp(0.0, ym);
        let x0 = x.floor() as usize;
        let y0 = y.floor() as usize;
        let x1 = (x0 + 1).min(self.width - 1);
        let y1 = (y0 + 1).min(self.height - 1);
        let fx = x - x0 as f32;
        let fy = y - y0 as f32;
        let a = self.get(x0, y0) * (1.0 - fx) + self.get(x1, y0) * fx;
        let b = self.get(x0, y1) * (1.0 - fx) + self.get(x1, y1) * fx;
        a * (1.0 - fy) + b * fy
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn bilinear_interpolates_between_centres() {
        let p = Plane::from_vec(2, 2, vec![0.0f32, 1.0, 2.0, 3.0]);
        assert_eq!(p.sample_bilinear(0.5, 0.0), 0.5);
        assert_eq!(p.sample_bilinear(0.5, 0.5), 1.5);
        assert_eq!(p.sample_bilinear(5.0, 5.0), 3.0);
    }
}
