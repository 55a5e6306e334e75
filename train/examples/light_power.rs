//! How bright are a dataset's lightings? For every head: the mean radiance
//! `Σ_k Ω_k·L_k / 4π` (mean over RGB) of its source lighting A and its novel
//! lighting B, and the mean linear foreground colour of its source view 0 and of its
//! two targets. Prints one line per head and the spread (geometric standard
//! deviation) of each column.
//!
//! The network sees only the source images, whose brightness is albedo × shading ×
//! the power of A: a head twice as bright under a light half as strong gives the same
//! images and a target half as bright. The spread of A's power is the spread of
//! brightness no network can infer from the images alone.
//!
//! `cargo run --release -p nelf-train --example light_power -- DATA [train|val]`

use std::path::PathBuf;

use nelf_train::data::Dataset;

type Failure = Box<dyn std::error::Error>;

/// Mean of the colour (mean over RGB) where coverage exceeds ½.
fn foreground_mean(image: &[[f32; 3]], alpha: &[f32]) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for (c, a) in image.iter().zip(alpha) {
        if *a > 0.5 {
            sum += f64::from(c[0] + c[1] + c[2]) / 3.0;
            n += 1;
        }
    }
    sum / n.max(1) as f64
}

/// Geometric standard deviation of positive values.
fn geometric_spread(values: &[f64]) -> f64 {
    let logs: Vec<f64> = values.iter().filter(|v| **v > 0.0).map(|v| v.ln()).collect();
    let n = logs.len().max(1) as f64;
    let mean = logs.iter().sum::<f64>() / n;
    (logs.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / n)
        .sqrt()
        .exp()
}

fn main() -> Result<(), Failure> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (data, split) = match args.as_slice() {
        [d] => (d.clone(), "train".to_string()),
        [d, s] => (d.clone(), s.clone()),
        _ => return Err("usage: light_power DATA [train|val]".into()),
    };
    let dataset = Dataset::open(&PathBuf::from(&data))?;
    let ids = if split == "val" {
        dataset.val_ids()
    } else {
        dataset.train_ids()
    };
    println!("head,power_a,power_b,source0_fg,self_rotation_fg,novel_light_fg");
    let mut columns: [Vec<f64>; 5] = Default::default();
    for id in ids {
        let sample = dataset.load(id)?;
        let row = [
            sample.source_light.mean_radiance(),
            sample.targets.get(1).map_or(0.0, |t| t.light.mean_radiance()),
            foreground_mean(&sample.source_images[0], &sample.source_masks[0]),
            sample
                .targets
                .first()
                .map_or(0.0, |t| foreground_mean(&t.image, &t.alpha)),
            sample
                .targets
                .get(1)
                .map_or(0.0, |t| foreground_mean(&t.image, &t.alpha)),
        ];
        println!(
            "{id},{:.4},{:.4},{:.4},{:.4},{:.4}",
            row[0], row[1], row[2], row[3], row[4]
        );
        for (c, v) in columns.iter_mut().zip(row) {
            c.push(v);
        }
    }
    let names = ["power A", "power B", "source 0", "self-rotation", "novel light"];
    for (name, c) in names.iter().zip(&columns) {
        println!("# geometric spread of {name}: ×{:.2}", geometric_spread(c));
    }
    let ratio: Vec<f64> = columns[2].iter().zip(&columns[0]).map(|(s, p)| s / p).collect();
    println!(
        "# geometric spread of source 0 / power A (albedo × shading): ×{:.2}",
        geometric_spread(&ratio)
    );
    Ok(())
}
