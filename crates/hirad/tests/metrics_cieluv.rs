//! CIELUV image metric: published values, agreement with `palette`, invariants of `diff`.

use glam::{DVec3, Vec3};
use hirad::metrics::{
    compare, compare_with_white, delta_e_map, heatmap, white_luminance, xyz_to_luv, LuvConverter,
    D65,
};
use hirad::render::Image;
use hirad::rng::SplitMix64;
use palette::{white_point, FromColor, LinSrgb, Luv, Xyz};
use proptest::prelude::*;

fn palette_luv(rgb: Vec3) -> DVec3 {
    let lin = LinSrgb::<f64>::new(rgb.x as f64, rgb.y as f64, rgb.z as f64);
    let xyz: Xyz<white_point::D65, f64> = Xyz::from_color(lin);
    let luv: Luv<white_point::D65, f64> = Luv::from_color(xyz);
    DVec3::new(luv.l, luv.u, luv.v)
}

#[test]
fn published_srgb_primaries_in_cieluv() {
    // sRGB primaries and white under D65 (Yn = 1), e.g. Lindbloom's calculator / Wikipedia
    // "CIELUV": red (53.24, 175.01, 37.76), green (87.73, −83.08, 107.40),
    // blue (32.30, −9.40, −130.34), white (100, 0, 0).
    let c = LuvConverter::new(1.0);
    let cases = [
        (Vec3::X, DVec3::new(53.24, 175.01, 37.76)),
        (Vec3::Y, DVec3::new(87.73, -83.08, 107.40)),
        (Vec3::Z, DVec3::new(32.30, -9.40, -130.34)),
        (Vec3::ONE, DVec3::new(100.0, 0.0, 0.0)),
        (Vec3::ZERO, DVec3::ZERO),
    ];
    for (rgb, want) in cases {
        let got = c.luv(rgb);
        assert!(
            (got - want).abs().max_element() < 0.01,
            "{rgb}: {got} vs {want}"
        );
    }
    // 18% grey: L* = 116·0.18^⅓ − 16 = 49.496.
    assert!((c.luv(Vec3::splat(0.18)).x - 49.4961).abs() < 1e-3);
    // Below the linear threshold: L* = (29/3)³ · Y.
    let y = 0.004;
    assert!((c.luv(Vec3::splat(y)).x - 24389.0 / 27.0 * y as f64).abs() < 1e-3);
}

#[test]
fn white_scaling_is_relative_luminance() {
    // Scaling both the colour and the white by k leaves L*u*v* unchanged.
    let m = hirad::metrics::srgb_to_xyz_matrix();
    let xyz = m * DVec3::new(0.3, 0.6, 0.1);
    let a = xyz_to_luv(xyz, D65);
    let b = xyz_to_luv(xyz * 37.0, D65 * 37.0);
    assert!((a - b).abs().max_element() < 1e-9);
}

proptest! {
    #[test]
    fn matches_palette(r in 0.0f32..1.0, g in 0.0f32..1.0, b in 0.0f32..1.0, k in 0.05f32..4.0) {
        // With Yn = k the converter equals palette on the colour divided by k.
        let rgb = Vec3::new(r, g, b);
        let ours = LuvConverter::new(k as f64).luv(rgb * k);
        let theirs = palette_luv(rgb);
        prop_assert!((ours - theirs).abs().max_element() < 1e-4, "{ours} vs {theirs}");
    }
}

fn random_image(w: u32, h: u32, seed: u64) -> Image {
    let mut rng = SplitMix64::new(seed);
    let mut img = Image::new(w, h, Vec3::ZERO);
    for p in &mut img.pixels {
        *p = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0;
    }
    img
}

#[test]
fn diff_of_an_image_with_itself_is_zero() {
    let a = random_image(40, 30, 1);
    let e = compare(&a, &a).unwrap();
    assert_eq!(e.rms_delta_e, 0.0);
    assert_eq!(e.max_delta_e, 0.0);
    assert_eq!(e.rel_rmse, 0.0);
}

#[test]
fn symmetry_holds_for_a_fixed_white_only() {
    let a = random_image(32, 16, 2);
    let mut b = random_image(32, 16, 3);
    // Per-pixel ΔE with the same white is a distance: symmetric.
    let ab = compare_with_white(&a, &b, 1.7).unwrap();
    let ba = compare_with_white(&b, &a, 1.7).unwrap();
    assert!((ab.rms_delta_e - ba.rms_delta_e).abs() < 1e-12);
    assert_eq!(ab.max_delta_e, ba.max_delta_e);
    // With the white taken from the reference, it differs once the references' 99th
    // percentile luminances differ: b = 3a.
    for (p, q) in b.pixels.iter_mut().zip(&a.pixels) {
        *p = *q * 3.0;
    }
    let ab = compare(&a, &b).unwrap();
    let ba = compare(&b, &a).unwrap();
    assert!((ab.white_y / ba.white_y - 3.0).abs() < 1e-6);
    assert!((ab.rms_delta_e - ba.rms_delta_e).abs() > 1.0);
}

#[test]
fn uniform_scaling_error_is_analytic() {
    // Reference grey g, image grey g/2; Yn = Y(g): ΔE = L*(1) − L*(1/2) = 100 − 116·0.5^⅓ + 16.
    let r = Image::new(8, 8, Vec3::splat(0.6));
    let a = Image::new(8, 8, Vec3::splat(0.3));
    let e = compare(&a, &r).unwrap();
    let want = 116.0 - 116.0 * 0.5f64.cbrt();
    assert!(
        (e.rms_delta_e - want).abs() < 1e-4,
        "{} vs {want}",
        e.rms_delta_e
    );
    assert!((e.max_delta_e - want).abs() < 1e-4);
    assert!((e.rel_rmse - 0.5).abs() < 1e-6);
    assert!((e.white_y - 0.6).abs() < 1e-6);
}

#[test]
fn white_is_the_99th_percentile_of_reference_luminance() {
    // 200 pixels of grey levels 1..=200 (×0.01): nearest rank ⌈198⌉ → level 198.
    let mut r = Image::new(20, 10, Vec3::ZERO);
    for (i, p) in r.pixels.iter_mut().enumerate() {
        *p = Vec3::splat((200 - i) as f32 * 0.01);
    }
    assert!((white_luminance(&r) - 1.98).abs() < 1e-6);
    assert_eq!(white_luminance(&Image::new(3, 3, Vec3::ZERO)), 1.0);
}

fn upsample(img: &Image, f: u32) -> Image {
    let mut out = Image::new(img.width * f, img.height * f, Vec3::ZERO);
    for y in 0..out.height {
        for x in 0..out.width {
            out.set(x, y, img.get(x / f, y / f));
        }
    }
    out
}

#[test]
fn resolution_independent() {
    let a = random_image(23, 17, 4);
    let r = random_image(23, 17, 5);
    let e1 = compare(&a, &r).unwrap();
    for f in [2, 3] {
        let e2 = compare(&upsample(&a, f), &upsample(&r, f)).unwrap();
        assert_eq!(e1.white_y, e2.white_y);
        assert!((e1.rms_delta_e - e2.rms_delta_e).abs() < 1e-9 * e1.rms_delta_e);
        assert!((e1.rel_rmse - e2.rel_rmse).abs() < 1e-9);
        assert_eq!(e1.max_delta_e, e2.max_delta_e);
    }
}

#[test]
fn thread_count_does_not_change_the_result() {
    let a = random_image(300, 200, 6);
    let r = random_image(300, 200, 7);
    let run = |n| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap()
            .install(|| compare(&a, &r).unwrap())
    };
    assert_eq!(run(1), run(2));
}

#[test]
fn mismatched_or_invalid_images_are_errors() {
    let a = random_image(4, 4, 1);
    let b = random_image(4, 5, 1);
    assert!(compare(&a, &b).is_err());
    let mut c = a.clone();
    c.pixels[3] = Vec3::new(f32::NAN, 0.0, 0.0);
    assert!(compare(&c, &a).is_err());
    assert!(compare(&a, &c).is_err());
    assert!(compare_with_white(&a, &a, 0.0).is_err());
}

#[test]
fn heatmap_scale() {
    let r = random_image(16, 8, 8);
    let a = random_image(16, 8, 9);
    let yn = white_luminance(&r);
    let de = delta_e_map(&a, &r, yn).unwrap();
    let max = de.iter().cloned().fold(0.0f32, f32::max);
    let h = heatmap(&de, 16, 8, max).unwrap();
    // Brightness of the false colour grows with ΔE.
    let (imin, imax) = (
        de.iter()
            .enumerate()
            .min_by(|x, y| x.1.total_cmp(y.1))
            .unwrap()
            .0,
        de.iter()
            .enumerate()
            .max_by(|x, y| x.1.total_cmp(y.1))
            .unwrap()
            .0,
    );
    let lum = |v: Vec3| v.x + v.y + v.z;
    assert!(lum(h.pixels[imax]) > lum(h.pixels[imin]));
    assert_eq!(h.pixels[imax], hirad::metrics::heat_color(1.0));
    assert!(heatmap(&de, 3, 3, 1.0).is_err());
}
