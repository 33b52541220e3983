//! Textures and skies from the real assets of `scripts/fetch-assets.sh`. Runs only when
//! `<repo>/assets` (or `$PICKER_ASSETS`) exists; prints SKIPPED otherwise — everything works
//! without assets.

use std::path::{Path, PathBuf};
use std::time::Instant;

use picker_nets::conventions::ENVMAP_MAX_RADIANCE;
use picker_synth::assets::AssetLibrary;
use picker_synth::sky::{hdri_sky, random_sky, SkyKind};
use picker_synth::textures::{photo_texture, random_texture, TextureFamily};
use picker_tensor::Rng;

/// `<repo>/assets`, or the folder named by `PICKER_ASSETS`.
fn assets_dir() -> Option<PathBuf> {
    let dir = std::env::var_os("PICKER_ASSETS")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets"));
    (dir.join("textures").is_dir() || dir.join("hdri").is_dir()).then_some(dir)
}

fn library() -> Option<AssetLibrary> {
    let Some(dir) = assets_dir() else {
        eprintln!("SKIPPED: no assets/ folder (run scripts/fetch-assets.sh to fetch them)");
        return None;
    };
    let lib = AssetLibrary::scan(&dir).expect("scanning assets/");
    eprintln!(
        "assets: {} photos, {} HDRIs under {}",
        lib.photos.len(),
        lib.hdris.len(),
        dir.display()
    );
    Some(lib)
}

#[test]
fn real_photos_become_tileable_textures() {
    let Some(lib) = library() else { return };
    if lib.photos.is_empty() {
        eprintln!("SKIPPED: assets/ has no photos");
        return;
    }
    for (i, photo) in lib.photos.iter().enumerate() {
        let start = Instant::now();
        let (t, info) = photo_texture(&mut Rng::new(i as u64), 64, &lib, photo)
            .unwrap_or_else(|e| panic!("{e}"));
        let ms = start.elapsed().as_secs_f64() * 1e3;
        assert!(
            photo.licence.is_some(),
            "{} has no licence file",
            photo.path.display()
        );
        assert_eq!((t.width, t.height), (64, 64));
        assert!(t
            .data
            .iter()
            .all(|c| c.is_finite() && c.min_element() >= 0.0 && c.max_element() <= 1.0));
        let seam = t.seam();
        eprintln!(
            "{}: {:?} seam worst {:.3} mean {:.3} ({ms:.1} ms)",
            photo.path.file_name().unwrap().to_string_lossy(),
            info.params,
            seam.worst_ratio(),
            seam.mean_ratio()
        );
        assert!(
            seam.worst_ratio() <= 1.5,
            "{}: {seam:?}",
            photo.path.display()
        );
    }
    let photos = (0..20)
        .filter(|&s| {
            let (_, info) = random_texture(&mut Rng::new(s), 32, Some(&lib)).unwrap();
            info.family == TextureFamily::Photo
        })
        .count();
    eprintln!("random_texture chose a photo {photos} times in 20");
    assert!(photos > 0);
}

#[test]
fn real_hdris_become_skies() {
    let Some(lib) = library() else { return };
    if lib.hdris.is_empty() {
        eprintln!("SKIPPED: assets/ has no HDRIs");
        return;
    }
    for (i, hdri) in lib.hdris.iter().enumerate() {
        let start = Instant::now();
        let (env, info) =
            hdri_sky(&mut Rng::new(i as u64), 64, 32, &lib, hdri).unwrap_or_else(|e| panic!("{e}"));
        let ms = start.elapsed().as_secs_f64() * 1e3;
        assert!(
            hdri.licence.is_some(),
            "{} has no licence file",
            hdri.path.display()
        );
        assert_eq!((env.width(), env.height()), (64, 32));
        assert!(env
            .data()
            .iter()
            .all(|c| c.is_finite() && c.min_element() >= 0.0));
        assert!(info.max_radiance <= ENVMAP_MAX_RADIANCE);
        eprintln!(
            "{}: scale {:.3}, max {:.1}, mean {:.3}, clamped {} ({ms:.0} ms)",
            hdri.path.file_name().unwrap().to_string_lossy(),
            info.scale,
            info.max_radiance,
            env.mean().max_element(),
            info.clamped
        );
    }
    let hdris = (0..12)
        .filter(|&s| {
            let (_, info) = random_sky(&mut Rng::new(s), 16, 8, Some(&lib)).unwrap();
            info.kind == SkyKind::Hdri
        })
        .count();
    eprintln!("random_sky chose an HDRI {hdris} times in 12");
    assert!(hdris > 0);
}

/// A contact sheet of procedural textures (one row per family) and skies, for a look:
/// `cargo test --release -p picker-synth --test textures -- --ignored contact_sheet`
/// writes `<target>/tmp/textures_contact.png`.
#[test]
#[ignore = "writes an image for a look"]
fn contact_sheet() {
    use picker_nets::conventions::srgb_encode;
    let (tile, per_row) = std::env::var("SHEET_TILE")
        .ok()
        .and_then(|s| s.parse().ok())
        .map_or((128usize, 8usize), |t| (t, 1024 / t));
    let lib = library();
    let families = TextureFamily::PROCEDURAL;
    let rows = families.len() + 2;
    let mut img = image::RgbImage::new((tile * per_row) as u32, (tile * rows) as u32);
    let mut put = |r: usize, c: usize, f: &dyn Fn(usize, usize) -> glam::Vec3| {
        for y in 0..tile {
            for x in 0..tile {
                let v = f(x, y);
                let px = image::Rgb(v.to_array().map(|k| (srgb_encode(k) * 255.0).round() as u8));
                img.put_pixel((c * tile + x) as u32, (r * tile + y) as u32, px);
            }
        }
    };
    for (r, family) in families.iter().enumerate() {
        for c in 0..per_row {
            let (t, _) = picker_synth::textures::random_texture_of(
                *family,
                &mut Rng::new(c as u64 * 31 + r as u64),
                tile / 2,
                None,
            )
            .unwrap();
            // 2×2 repeats show the seams.
            put(r, c, &|x, y| {
                t.sample(x as f32 / (tile / 2) as f32, y as f32 / (tile / 2) as f32)
            });
        }
    }
    for c in 0..per_row {
        // Photos (procedural when there are no assets).
        let (t, _) = picker_synth::textures::random_texture_of(
            TextureFamily::Photo,
            &mut Rng::new(c as u64 + 100),
            tile / 2,
            lib.as_ref(),
        )
        .unwrap();
        put(families.len(), c, &|x, y| {
            t.sample(x as f32 / (tile / 2) as f32, y as f32 / (tile / 2) as f32)
        });
    }
    // Skies, tone-mapped c/(1+c) at 2 × exposure, 2 per tile (128×64 each).
    for c in 0..per_row {
        let maps: Vec<_> = (0..2)
            .map(|k| {
                random_sky(
                    &mut Rng::new((c * 2 + k) as u64),
                    tile,
                    tile / 2,
                    lib.as_ref(),
                )
                .unwrap()
                .0
            })
            .collect();
        put(families.len() + 1, c, &|x, y| {
            let m = &maps[y / (tile / 2)];
            let v = m.get(y % (tile / 2), x) * 2.0;
            v / (glam::Vec3::ONE + v)
        });
    }
    let path = Path::new(env!("CARGO_TARGET_TMPDIR")).join("textures_contact.png");
    img.save(&path).unwrap();
    eprintln!("wrote {}", path.display());
}
