//! Linear RGB images and their files: EXR (linear, 32-bit float) and PNG (8-bit sRGB transfer,
//! exposure in stops, clamped). Both are written atomically and can be read back (PNG decoded to
//! linear with the inverse sRGB transfer) for `hirad diff`.

use glam::Vec3;
use hirad_core::{Error, Result};
use std::path::Path;

/// Largest image read (pixels; 8192 × 4096, 400 MB as linear RGB).
pub const MAX_PIXELS: usize = 1 << 25;

/// A linear RGB image, row-major, top row first. Pixels are radiance (W/(m²·sr)) when the image
/// comes from the rasteriser or the path tracer.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// `width · height` pixels, index `y · width + x`.
    pub pixels: Vec<Vec3>,
}

/// Image file formats, chosen from the file extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageFormat {
    /// OpenEXR, linear 32-bit float RGB.
    Exr,
    /// PNG, 8-bit sRGB.
    Png,
}

impl ImageFormat {
    /// Format of a path by its extension (`.exr`, `.png`, case-insensitive).
    pub fn from_path(path: &Path) -> Result<ImageFormat> {
        match path
            .extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase())
            .as_deref()
        {
            Some("exr") => Ok(ImageFormat::Exr),
            Some("png") => Ok(ImageFormat::Png),
            _ => Err(Error::input(
                path,
                "unknown image type (expected .exr or .png)",
            )),
        }
    }
}

impl Image {
    /// A `width × height` image filled with `value`.
    pub fn new(width: u32, height: u32, value: Vec3) -> Image {
        Image {
            width,
            height,
            pixels: vec![value; width as usize * height as usize],
        }
    }

    /// Number of pixels.
    pub fn len(&self) -> usize {
        self.pixels.len()
    }

    /// True for a 0-pixel image.
    pub fn is_empty(&self) -> bool {
        self.pixels.is_empty()
    }

    /// Pixel at column `x`, row `y` (row 0 at the top).
    #[inline]
    pub fn get(&self, x: u32, y: u32) -> Vec3 {
        self.pixels[(y * self.width + x) as usize]
    }

    /// Set the pixel at column `x`, row `y`.
    #[inline]
    pub fn set(&mut self, x: u32, y: u32, v: Vec3) {
        self.pixels[(y * self.width + x) as usize] = v;
    }

    /// Mean pixel value (f64 sums).
    pub fn mean(&self) -> Vec3 {
        let mut s = glam::DVec3::ZERO;
        for p in &self.pixels {
            s += p.as_dvec3();
        }
        (s / self.pixels.len().max(1) as f64).as_vec3()
    }

    /// Write the image; the format follows the extension. `exposure` (stops) only affects PNG.
    pub fn write(&self, path: &Path, exposure: f32) -> Result<()> {
        match ImageFormat::from_path(path)? {
            ImageFormat::Exr => self.write_exr(path),
            ImageFormat::Png => self.write_png(path, exposure),
        }
    }

    /// Read an EXR or PNG image (PNG is converted to linear RGB).
    pub fn read(path: &Path) -> Result<Image> {
        match ImageFormat::from_path(path)? {
            ImageFormat::Exr => Image::read_exr(path),
            ImageFormat::Png => Image::read_png(path),
        }
    }

    /// Write linear 32-bit float RGB OpenEXR, atomically.
    pub fn write_exr(&self, path: &Path) -> Result<()> {
        use exr::prelude::{SpecificChannels, Vec2, WritableImage};
        let w = self.width as usize;
        let channels = SpecificChannels::rgb(|Vec2(x, y): Vec2<usize>| {
            let p = self.pixels[y * w + x];
            (p.x, p.y, p.z)
        });
        let img = exr::image::Image::from_channels((w, self.height as usize), channels);
        let mut buf = std::io::Cursor::new(Vec::new());
        img.write()
            .to_buffered(&mut buf)
            .map_err(|e| Error::input(path, format!("cannot encode EXR: {e}")))?;
        hirad_core::io::write_bytes_atomic(path, buf.get_ref())
    }

    /// Read the first RGB(A) layer of an OpenEXR file (alpha ignored).
    pub fn read_exr(path: &Path) -> Result<Image> {
        use exr::prelude::{read_first_rgba_layer_from_file, Vec2};
        // The pixels are allocated from the header's size before any data is read: a few
        // bytes claiming 65536 × 65536 must be an error, not a 50 GB allocation.
        let meta = exr::meta::MetaData::read_from_file(path, false).map_err(|e| match e {
            exr::error::Error::Io(io) => Error::io(path, io),
            other => Error::input(path, format!("cannot read EXR: {other}")),
        })?;
        for h in &meta.headers {
            let (w, ht) = (h.layer_size.width(), h.layer_size.height());
            if w.saturating_mul(ht) > MAX_PIXELS {
                return Err(Error::input(
                    path,
                    format!("EXR of {w} x {ht} pixels: more than {MAX_PIXELS} pixels"),
                ));
            }
        }
        let img = read_first_rgba_layer_from_file(
            path,
            |res: Vec2<usize>, _| Image::new(res.width() as u32, res.height() as u32, Vec3::ZERO),
            |img: &mut Image, pos: Vec2<usize>, (r, g, b, _a): (f32, f32, f32, f32)| {
                img.set(pos.x() as u32, pos.y() as u32, Vec3::new(r, g, b))
            },
        )
        .map_err(|e| match e {
            exr::error::Error::Io(io) => Error::io(path, io),
            other => Error::input(path, format!("cannot read EXR: {other}")),
        })?;
        Ok(img.layer_data.channel_data.pixels)
    }

    /// The 8-bit sRGB encoding used for PNG: `v · 2^exposure`, clamped to [0, 1], sRGB transfer,
    /// rounded to nearest.
    pub fn to_srgb8(&self, exposure: f32) -> Vec<u8> {
        let k = exposure.exp2();
        let mut out = Vec::with_capacity(self.pixels.len() * 3);
        for p in &self.pixels {
            for c in p.to_array() {
                out.push(encode_srgb8(c * k));
            }
        }
        out
    }

    /// Write an 8-bit sRGB PNG (`exposure` in stops), atomically.
    pub fn write_png(&self, path: &Path, exposure: f32) -> Result<()> {
        let bytes = self.to_srgb8(exposure);
        let mut buf = std::io::Cursor::new(Vec::new());
        image::write_buffer_with_format(
            &mut buf,
            &bytes,
            self.width,
            self.height,
            image::ExtendedColorType::Rgb8,
            image::ImageFormat::Png,
        )
        .map_err(|e| Error::input(path, format!("cannot encode PNG: {e}")))?;
        hirad_core::io::write_bytes_atomic(path, buf.get_ref())
    }

    /// Read a PNG (8 or 16 bit, any colour type) and convert it to linear RGB with the inverse
    /// sRGB transfer. Alpha is ignored.
    pub fn read_png(path: &Path) -> Result<Image> {
        let reader = image::ImageReader::open(path)
            .map_err(|e| Error::io(path, e))?
            .with_guessed_format()
            .map_err(|e| Error::io(path, e))?;
        let dynimg = reader
            .decode()
            .map_err(|e| Error::input(path, format!("cannot read PNG: {e}")))?;
        let rgb = dynimg.to_rgb32f();
        let (w, h) = rgb.dimensions();
        let pixels = rgb
            .pixels()
            .map(|p| Vec3::new(decode_srgb(p[0]), decode_srgb(p[1]), decode_srgb(p[2])))
            .collect();
        Ok(Image {
            width: w,
            height: h,
            pixels,
        })
    }

    /// Box-filter down by an integer factor `f` (`width` and `height` must be multiples of it).
    pub fn downsample(&self, f: u32) -> Result<Image> {
        if f == 0 || !self.width.is_multiple_of(f) || !self.height.is_multiple_of(f) {
            return Err(Error::Config(format!(
                "cannot downsample {}x{} by {f}",
                self.width, self.height
            )));
        }
        let (w, h) = (self.width / f, self.height / f);
        let mut out = Image::new(w, h, Vec3::ZERO);
        let inv = 1.0 / (f * f) as f32;
        for y in 0..h {
            for x in 0..w {
                let mut s = Vec3::ZERO;
                for j in 0..f {
                    for i in 0..f {
                        s += self.get(x * f + i, y * f + j);
                    }
                }
                out.set(x, y, s * inv);
            }
        }
        Ok(out)
    }
}

/// sRGB transfer (linear → encoded), for values in [0, 1].
#[inline]
pub fn srgb_encode(v: f32) -> f32 {
    if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// Inverse sRGB transfer (encoded → linear), for values in [0, 1].
#[inline]
pub fn decode_srgb(e: f32) -> f32 {
    if e <= 0.040_45 {
        e / 12.92
    } else {
        ((e + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear value → 8-bit sRGB code (clamped; NaN maps to 0).
#[inline]
pub fn encode_srgb8(v: f32) -> u8 {
    let v = if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) };
    (srgb_encode(v) * 255.0 + 0.5) as u8
}

/// Fill `pixels` (rows of `width`) in parallel, a row at a time: `pixel(x, y, counts)` per
/// pixel, one `C` of counts per row (returned in row order), progress by rows;
/// `Error::Interrupted` when `cancel` is set meanwhile.
pub(crate) fn render_rows<P, C, F>(
    pixels: &mut [P],
    width: usize,
    label: &str,
    progress: &dyn hirad_core::progress::Progress,
    cancel: Option<&std::sync::atomic::AtomicBool>,
    pixel: F,
) -> Result<Vec<C>>
where
    P: Send,
    C: Default + Send,
    F: Fn(usize, usize, &mut C) -> P + Sync,
{
    use rayon::prelude::*;
    use std::sync::atomic::Ordering;
    progress.start(label, pixels.len().div_ceil(width.max(1)) as u64);
    let counts: Vec<C> = pixels
        .par_chunks_mut(width.max(1))
        .enumerate()
        .map(|(y, row)| {
            let mut cnt = C::default();
            if cancel.is_some_and(|c| c.load(Ordering::Relaxed)) {
                return cnt;
            }
            for (x, px) in row.iter_mut().enumerate() {
                *px = pixel(x, y, &mut cnt);
            }
            progress.inc(1);
            cnt
        })
        .collect();
    progress.finish();
    if cancel.is_some_and(|c| c.load(Ordering::Relaxed)) {
        return Err(Error::Interrupted);
    }
    Ok(counts)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_transfer_inverts() {
        for i in 0..=255u32 {
            let e = i as f32 / 255.0;
            assert_eq!(encode_srgb8(decode_srgb(e)), i as u8);
        }
        assert_eq!(encode_srgb8(2.0), 255);
        assert_eq!(encode_srgb8(-1.0), 0);
        assert_eq!(encode_srgb8(f32::NAN), 0);
        // 18% grey encodes to 118 (0.4613 · 255 = 117.6).
        assert_eq!(encode_srgb8(0.18), 118);
    }

    #[test]
    fn format_from_extension() {
        assert_eq!(
            ImageFormat::from_path(Path::new("a/b.EXR")).unwrap(),
            ImageFormat::Exr
        );
        assert_eq!(
            ImageFormat::from_path(Path::new("b.png")).unwrap(),
            ImageFormat::Png
        );
        assert!(ImageFormat::from_path(Path::new("b.jpg")).is_err());
    }
}
