//! Inputs at the edges of what the public API's types admit (found by a
//! fuzz campaign of the library APIs): refused with an error, or a
//! documented panic with a message, never an index out of bounds.

use glam::Vec3;
use picker_render::render::{compare, error_heatmap, preview_tile};
use picker_render::{EnvMap, Image, PhongMaterial, Quality, Shader};

fn rgb(h: usize, w: usize) -> Image {
    Image::new(3, h, w, vec![0.5; 3 * h * w]).unwrap()
}

#[test]
fn comparisons_refuse_malformed_references() {
    let r = rgb(2, 2);
    let no_channels = Image::new(0, 2, 2, vec![]).unwrap();
    for reference in [
        no_channels,
        Image {
            channels: 3,
            height: 2,
            width: 2,
            data: vec![0.0; 5],
        },
    ] {
        assert!(compare(&r, &reference, None).is_err());
        assert!(error_heatmap(&r, &reference, None).is_err());
    }
    assert!(compare(&r, &Image::new(1, 2, 2, vec![0.5; 4]).unwrap(), None).is_ok());
}

#[test]
fn sizes_that_overflow_are_refused() {
    assert!(Image::new(3, 1 << 32, 1 << 32, vec![]).is_err());
    assert!(EnvMap::new(1 << 32, 1 << 32, vec![]).is_err());
    assert!(std::panic::catch_unwind(|| Image::zeros(3, 1 << 32, 1 << 32)).is_err());
    let env = EnvMap::uniform(4, 2, Vec3::ONE);
    assert!(env.resample(1 << 32, 1 << 32).is_err());
    let r = std::panic::catch_unwind(|| env.get(2, 0));
    let msg = r.unwrap_err();
    let msg = msg.downcast_ref::<String>().cloned().unwrap_or_default();
    assert!(msg.contains("outside the 2x4 map"), "{msg}");
}

#[test]
fn huge_but_finite_radiance_is_refused_and_the_largest_allowed_shades_finitely() {
    let e = EnvMap::new(2, 1, vec![Vec3::splat(f32::MAX); 2]).unwrap_err();
    assert!(e.to_string().contains("magnitude"), "{e}");
    let env = EnvMap::new(
        8,
        4,
        vec![Vec3::splat(picker_render::envmap::MAX_RADIANCE); 32],
    )
    .unwrap();
    let m = PhongMaterial {
        diffuse: Vec3::splat(0.5),
        specular: Vec3::splat(0.5),
        exponent: 20.0,
    };
    for q in [Quality::Fast, Quality::Exact] {
        let c = Shader::new(&env, q).shade(Vec3::Z, Vec3::Z, &m);
        assert!(c.is_finite() && c.max_element() > 0.0, "{q:?}: {c}");
    }
}

#[test]
#[should_panic(expected = "preview texture")]
fn a_preview_texture_without_channels_panics_with_a_message() {
    let m = PhongMaterial {
        diffuse: Vec3::splat(0.5),
        specular: Vec3::ZERO,
        exponent: 1.0,
    };
    let env = EnvMap::uniform(8, 4, Vec3::ONE);
    preview_tile(&m, &env, 8, Some(&Image::new(0, 2, 2, vec![]).unwrap()));
}
