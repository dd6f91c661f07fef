//! Probe: how well the full-resolution mask logits of a fine-mask model separate tube pixels
//! from the background, against the bilinear stride-4 foreground logits.
//! `cargo run --release --manifest-path experiments/Cargo.toml --bin learned_fine_probe -- MODEL DATASET_DIR [LIMIT]`
#[path = "common/probe_args.rs"]
mod probe_args;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (model, imgs) = probe_args::model_and_images("learned_fine_probe", 10)?;
    let ts = [-1.0f32, 0.0, 1.0, 1.6, 2.2, 3.0];
    // Per threshold: (intersection, union) over tube-neighbourhood pixels, fine and coarse.
    let mut acc = vec![[0usize; 4]; ts.len()];
    for (i, img) in imgs.iter().enumerate() {
        let p = model.predict(&img.input, img.width, img.height)?;
        let Some(f) = &p.fine else { return Err("model has no fine branch".into()) };
        if let Ok(dir) = std::env::var("FINE_PROBE_DUMP") {
            // Raw little-endian f32 planes for inspection: fine logits, input, labels.
            let dump = |name: &str, v: &mut dyn Iterator<Item = f32>| std::fs::write(format!("{dir}/{i}_{name}.f32"), v.flat_map(f32::to_le_bytes).collect::<Vec<u8>>());
            dump("fine", &mut f.iter().copied())?;
            dump("input", &mut img.input.iter().copied())?;
            dump("labels", &mut img.labels.iter().map(|&l| l as f32))?;
            dump("coarse", &mut p.planes[..p.out_w * p.out_h].iter().copied())?;
        }
        let (w, ow) = (img.width, p.out_w);
        for y in 0..img.height {
            for x in 0..w {
                // Only pixels within 8 px of a tube pixel (the instance neighbourhood).
                let near = (y.saturating_sub(8)..(y + 9).min(img.height)).step_by(4).any(|yy| (x.saturating_sub(8)..(x + 9).min(w)).step_by(4).any(|xx| img.labels[yy * w + xx] != 0));
                if !near {
                    continue;
                }
                let gt = img.labels[y * w + x] != 0;
                let c = (y / 4).min(p.out_h - 1) * ow + (x / 4).min(ow - 1);
                for (k, &t) in ts.iter().enumerate() {
                    let fi = f[y * w + x] > t;
                    let co = p.planes[c] > t;
                    acc[k][0] += (fi && gt) as usize;
                    acc[k][1] += (fi || gt) as usize;
                    acc[k][2] += (co && gt) as usize;
                    acc[k][3] += (co || gt) as usize;
                }
            }
        }
    }
    for (k, t) in ts.iter().enumerate() {
        let r = acc[k];
        println!("logit > {t:5.1}: fine IoU {:.3}  stride-4 (nearest) IoU {:.3}", r[0] as f64 / r[1].max(1) as f64, r[2] as f64 / r[3].max(1) as f64);
    }
    Ok(())
}
