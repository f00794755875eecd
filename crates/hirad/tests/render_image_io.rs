//! EXR and PNG round trips, exposure, and errors on bad files.

use glam::Vec3;
use hirad::render::image::{decode_srgb, encode_srgb8};
use hirad::render::Image;

fn test_image() -> Image {
    let (w, h) = (37u32, 23u32);
    let mut img = Image::new(w, h, Vec3::ZERO);
    for y in 0..h {
        for x in 0..w {
            let v = Vec3::new(
                x as f32 / w as f32,
                y as f32 / h as f32,
                0.001 * (x * y) as f32,
            );
            img.set(x, y, v);
        }
    }
    // HDR values and a tiny one survive EXR exactly.
    img.set(0, 0, Vec3::new(1234.5, 1e-7, 3.0));
    img
}

#[test]
fn exr_round_trip_is_exact() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("a.exr");
    let img = test_image();
    img.write(&p, 0.0).unwrap();
    let back = Image::read(&p).unwrap();
    assert_eq!(back, img);
}

#[test]
fn png_round_trip_within_quantisation() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("a.png");
    let mut img = test_image();
    img.set(0, 0, Vec3::new(0.5, 0.25, 0.125));
    img.write(&p, 0.0).unwrap();
    let back = Image::read(&p).unwrap();
    assert_eq!((back.width, back.height), (img.width, img.height));
    for (a, b) in img.pixels.iter().zip(&back.pixels) {
        for c in 0..3 {
            let (a, b) = (a[c].min(1.0), b[c]);
            // Exactly the decoded 8-bit code of the value.
            assert_eq!(b, decode_srgb(encode_srgb8(a) as f32 / 255.0));
            // Half a code step in the encoded domain.
            let step = (decode_srgb((encode_srgb8(a) as f32 + 0.5) / 255.0) - b).abs();
            assert!((a - b).abs() <= step + 1e-6, "{a} {b}");
        }
    }
}

#[test]
fn png_exposure_and_clamp() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("e.png");
    let img = Image::new(2, 1, Vec3::new(0.25, 4.0, -1.0));
    img.write(&p, 1.0).unwrap(); // ×2: 0.5, 8 → 1, −2 → 0
    let back = Image::read(&p).unwrap();
    let px = back.get(1, 0);
    assert!((px.x - 0.5).abs() < 0.004, "{px}"); // half an 8-bit step
    assert_eq!(px.y, 1.0);
    assert_eq!(px.z, 0.0);
    assert_eq!(img.to_srgb8(1.0)[0], 188); // sRGB(0.5) = 0.7354 → 187.5 → 188
}

#[test]
fn bad_files_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let img = Image::new(4, 4, Vec3::ONE);
    assert!(img.write(&dir.path().join("a.jpg"), 0.0).is_err());
    assert!(Image::read(&dir.path().join("missing.exr")).is_err());
    let junk = dir.path().join("junk.exr");
    std::fs::write(&junk, b"not an exr file").unwrap();
    let e = Image::read(&junk).unwrap_err();
    assert!(e.is_input(), "{e}");
    let junk = dir.path().join("junk.png");
    std::fs::write(&junk, b"\x89PNG garbage").unwrap();
    assert!(Image::read(&junk).is_err());
    // Nothing half-written is left behind by failures.
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    assert!(names.iter().all(|n| n.starts_with("junk")), "{names:?}");
}

#[test]
fn downsample_box_filter() {
    let mut img = Image::new(4, 2, Vec3::ZERO);
    img.set(0, 0, Vec3::splat(4.0));
    img.set(3, 1, Vec3::splat(8.0));
    let d = img.downsample(2).unwrap();
    assert!(img.downsample(3).is_err());
    assert!(img.downsample(0).is_err());
    assert_eq!((d.width, d.height), (2, 1));
    assert_eq!(d.get(0, 0), Vec3::ONE);
    assert_eq!(d.get(1, 0), Vec3::splat(2.0));
    assert_eq!(d.mean(), img.mean());
}
