//! Probe: candle CPU matmul orientation for thin convolutions (W·cols vs cols·Wᵀ).
//! `RAYON_NUM_THREADS=2 cargo run --release --manifest-path experiments/Cargo.toml --bin learned_matmul_probe`.
use candle_core::{Device, Tensor};
use std::time::Instant;
fn median_ms(mut f: impl FnMut()) -> f64 {
    f();
    let mut t: Vec<f64> = (0..9).map(|_| { let s = Instant::now(); f(); s.elapsed().as_secs_f64() * 1e3 }).collect();
    t.sort_by(f64::total_cmp);
    t[4]
}
fn main() -> candle_core::Result<()> {
    if std::env::var("STEPS").is_ok() {
        return steps();
    }
    let d = Device::Cpu;
    for (k, m, n) in [(144usize, 16usize, 65536usize), (216, 8, 65536), (108, 12, 65536), (432, 24, 4096)] {
        let w = Tensor::randn(0f32, 1.0, (m, k), &d)?;
        let cols = Tensor::randn(0f32, 1.0, (1, k, n), &d)?;
        let a = median_ms(|| { w.broadcast_left(1).unwrap().matmul(&cols).unwrap(); });
        let colst = Tensor::randn(0f32, 1.0, (1, n, k), &d)?;
        let wt = Tensor::randn(0f32, 1.0, (k, m), &d)?;
        let b = median_ms(|| { colst.broadcast_matmul(&wt).unwrap(); });
        let c = median_ms(|| { colst.reshape((n, k)).unwrap().matmul(&wt).unwrap(); });
        // weight gradient shapes: (m, n) x (n, k)
        let g = Tensor::randn(0f32, 1.0, (m, n), &d)?;
        let e = median_ms(|| { g.matmul(&colst.reshape((n, k)).unwrap()).unwrap(); });
        let gt = Tensor::randn(0f32, 1.0, (n, m), &d)?;
        let f = median_ms(|| { colst.reshape((n, k)).unwrap().t().unwrap().matmul(&gt).unwrap(); });
        let gf = 2.0 * (k * m * n) as f64 / 1e9;
        println!("k{k} m{m} n{n}: W.cols {a:.2} ms ({:.1} GF/s) | cols.Wt batched {b:.2} | 2d {c:.2} ({:.1} GF/s) | grad g.cols {e:.2} | colsT.gT {f:.2}", gf / a * 1e3, gf / c * 1e3);
    }
    Ok(())
}

#[allow(dead_code)]
pub fn steps() -> candle_core::Result<()> {
    use candle_core::D;
    let d = Device::Cpu;
    let (b, c, h, w, k, cout) = (1usize, 16usize, 256usize, 256usize, 3usize, 16usize);
    let x = Tensor::randn(0f32, 1.0, (b, c, h, w), &d)?;
    let pw = w + 2;
    let t = |name: &str, f: &mut dyn FnMut()| println!("{name:30} {:8.2} ms", median_ms(f));
    t("pad w", &mut || { x.pad_with_zeros(D::Minus1, 1, 1).unwrap(); });
    let xw = x.pad_with_zeros(D::Minus1, 1, 1)?;
    t("pad h", &mut || { xw.pad_with_zeros(2, 1, 2).unwrap(); });
    let xp = xw.pad_with_zeros(2, 1, 2)?;
    let flat = xp.reshape((b, c, (h + k) * pw))?;
    t("cat 9 shifts", &mut || {
        let s: Vec<Tensor> = (0..9).map(|i| flat.narrow(2, (i / 3) * pw + i % 3, h * pw).unwrap()).collect();
        Tensor::cat(&s, 1).unwrap();
    });
    let s: Vec<Tensor> = (0..9).map(|i| flat.narrow(2, (i / 3) * pw + i % 3, h * pw).unwrap()).collect();
    let cols = Tensor::cat(&s, 1)?;
    let wm = Tensor::randn(0f32, 1.0, (cout, 9 * c), &d)?;
    t("matmul", &mut || { wm.broadcast_left(b).unwrap().matmul(&cols).unwrap(); });
    let y = wm.broadcast_left(b)?.matmul(&cols)?;
    let bias = Tensor::randn(0f32, 1.0, (1, cout, 1), &d)?;
    t("bias", &mut || { y.broadcast_add(&bias).unwrap(); });
    t("narrow+relu", &mut || { y.reshape((b, cout, h, pw)).unwrap().narrow(3, 0, w).unwrap().relu().unwrap(); });
    t("relu contiguous", &mut || { y.relu().unwrap(); });
    t("maxpool", &mut || { x.max_pool2d(2).unwrap(); });
    let xs = x.max_pool2d(2)?;
    t("upsample", &mut || { xs.upsample_nearest2d(h, w).unwrap(); });
    Ok(())
}
