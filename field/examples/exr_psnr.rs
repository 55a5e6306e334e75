//! PSNR (and max |difference|) between pairs of linear EXR images, data range = the
//! first image's maximum: `cargo run --release -p nelf-field --example exr_psnr --
//! A.exr B.exr [A2.exr B2.exr …]`. Used to compare `nelf render ASSET` (a bake) with
//! `nelf render --field` (the network) in `field/README.md`.

fn main() -> anyhow::Result<()> {
    let paths: Vec<String> = std::env::args().skip(1).collect();
    if paths.is_empty() || paths.len() % 2 != 0 {
        anyhow::bail!("usage: exr_psnr A.exr B.exr [A2.exr B2.exr …]");
    }
    let mut scores = Vec::new();
    for pair in paths.chunks(2) {
        let a = nelf_scene::envmap::load_envmap(&pair[0])?;
        let b = nelf_scene::envmap::load_envmap(&pair[1])?;
        anyhow::ensure!(
            (a.width(), a.height()) == (b.width(), b.height()),
            "{} and {} differ in size",
            pair[0],
            pair[1]
        );
        let range = f64::from(a.texels().iter().flatten().fold(0.0f32, |m, v| m.max(*v))).max(1e-9);
        let db = nelf_scene::metrics::psnr(a.texels(), b.texels(), range)?;
        let max_diff = a
            .texels()
            .iter()
            .flatten()
            .zip(b.texels().iter().flatten())
            .fold(0.0f32, |m, (x, y)| m.max((x - y).abs()));
        println!(
            "{} vs {}: PSNR {db:.2} dB (range {range:.4}, max |diff| {max_diff:.4})",
            pair[0], pair[1]
        );
        scores.push(db);
    }
    println!(
        "mean PSNR {:.2} dB",
        scores.iter().sum::<f64>() / scores.len() as f64
    );
    Ok(())
}
