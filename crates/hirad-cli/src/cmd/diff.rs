//! `hirad diff IMAGE REFERENCE`: CIELUV image error (`experiments.md` §3). Linear sRGB → XYZ →
//! CIELUV with the D65 white scaled to the reference's 99th-percentile luminance (nearest rank);
//! prints RMS ΔE*uv over pixels, max and mean ΔE, relative RMSE in linear RGB. `--heatmap`
//! writes a false-colour ΔE image (black = 0, pale yellow = `--heatmap-max`, default the 99th
//! percentile of ΔE by nearest rank, so that a few outliers do not darken the whole map).

use crate::Global;
use hirad::metrics::{
    compare_with_white, delta_e_map, heatmap, percentile_nearest_rank, white_luminance,
};
use hirad::render::Image;
use serde::Serialize;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Image to measure (`.exr` or `.png`; PNG is decoded to linear).
    pub image: PathBuf,
    /// Reference image (`.exr` or `.png`), same size.
    pub reference: PathBuf,
    /// Write a false-colour ΔE image (`.png` or `.exr`) [default: none].
    #[arg(long)]
    pub heatmap: Option<PathBuf>,
    /// ΔE shown at the top of the heatmap scale (default: the 99th percentile of ΔE).
    #[arg(long)]
    pub heatmap_max: Option<f32>,
    /// White luminance Yn [default: the reference's 99th percentile].
    #[arg(long)]
    pub white: Option<f64>,
}

#[derive(Serialize)]
struct Report {
    image: String,
    reference: String,
    #[serde(flatten)]
    error: hirad::metrics::ImageError,
    heatmap: Option<String>,
}

pub fn run(a: Args, g: &Global) -> anyhow::Result<()> {
    let img = Image::read(&a.image)?;
    let reference = Image::read(&a.reference)?;
    if img.width != reference.width || img.height != reference.height {
        anyhow::bail!(hirad::Error::Config(format!(
            "{} is {}x{} but {} is {}x{}",
            a.image.display(),
            img.width,
            img.height,
            a.reference.display(),
            reference.width,
            reference.height
        )));
    }
    let yn = match a.white {
        Some(w) => w,
        None => white_luminance(&reference),
    };
    let error = compare_with_white(&img, &reference, yn)?;
    let heat = match &a.heatmap {
        Some(path) => {
            let de = delta_e_map(&img, &reference, yn)?;
            let max = match a.heatmap_max {
                Some(m) => m,
                None => {
                    let v: Vec<f64> = de.iter().map(|&x| x as f64).collect();
                    percentile_nearest_rank(&v, 99).unwrap_or(0.0) as f32
                }
            };
            if !(max >= 0.0 && max.is_finite()) {
                anyhow::bail!(hirad::Error::Config(format!(
                    "heatmap maximum {max} must be finite and >= 0"
                )));
            }
            heatmap(&de, img.width, img.height, max)?.write(path, 0.0)?;
            Some(path.display().to_string())
        }
        None => None,
    };
    let r = Report {
        image: a.image.display().to_string(),
        reference: a.reference.display().to_string(),
        error,
        heatmap: heat,
    };
    if g.json {
        return super::print_json(&r);
    }
    let e = &r.error;
    println!("{} vs {} ({}x{})", r.image, r.reference, e.width, e.height);
    println!("RMS dE*uv   {:.4}", e.rms_delta_e);
    println!("max dE*uv   {:.4}", e.max_delta_e);
    println!("mean dE*uv  {:.4}", e.mean_delta_e);
    println!("rel RMSE    {:.6}", e.rel_rmse);
    println!("mean Y / ref {:.4}", e.mean_luminance_ratio);
    println!("white Yn    {:.6}", e.white_y);
    if let Some(h) = &r.heatmap {
        println!("wrote {h}");
    }
    Ok(())
}
