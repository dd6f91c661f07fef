//! Writes a preset dataset through the library, as `tubeloc synth --preset P --out DIR` does:
//! `cargo run --release -p tubeloc-synth --example dataset -- paper /tmp/paper`.
fn main() {
    let mut args = std::env::args().skip(1);
    let preset = args.next().unwrap_or_else(|| "tiny".into());
    let out = args.next().unwrap_or_else(|| "/tmp/synth_dataset".into());
    let spec = tubeloc_synth::DatasetSpec::preset(&preset, 0).expect("preset");
    let t0 = std::time::Instant::now();
    let s = tubeloc_synth::write_dataset(&spec, std::path::Path::new(&out), (0, 1), true, &|_, _| {}).expect("dataset");
    println!("{}: {} images, {} annotations in {:.1} s", s.out.display(), s.images, s.annotations, t0.elapsed().as_secs_f64());
}
