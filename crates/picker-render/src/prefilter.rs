//! The fast path: eq. 3.7 evaluated from precomputed data, tested against
//! [`shade_exact`](crate::shade_exact).
//!
//! - **Diffuse**: the irradiance `E(N) = Σ_i L_i max(0, ω_i·N) ΔΩ_i` is
//!   computed exactly on a 32 × 64 grid of normals (from the map area-averaged
//!   to at most 64 × 128) and looked up bilinearly: `ρd/π · E(N)`.
//! - **Specular**: the same quadrature as the exact path, but over a map
//!   pre-averaged to the lobe's scale and only over the lobe's support. A
//!   chain of area-correct downsamplings of the map (rows `8·2^(j/2)`, up to
//!   the map itself) is built once; for exponent `n` the coarsest one whose
//!   pixel spacing `π/H` is at most 2/3 of the lobe width `1/√n` is used, and
//!   only its pixels within the cone where the lobe `cosⁿα` exceeds `10⁻³` of
//!   its peak are summed (about 100–200 pixels for any `n`). The cosine
//!   `max(0, ω·N)`, the horizon and the exponent are exact.
//!
//! Where the map cannot resolve a lobe (`n` above
//! [`resolved_exponent`](crate::phong::resolved_exponent)) the finest level is
//! the map itself, so the fast path aliases exactly as the exact quadrature does:
//! a narrow lobe falls between pixel centres, and a glossy sphere shows the
//! map's pixel grid as dark lines. [`PrefilteredEnv::resolving`] instead reads
//! the map as the continuous function its bilinear sampling
//! ([`EnvMap::sample`]) makes of it: levels finer than the map, its bilinear
//! upsamplings, are made when a lobe first needs them (up to
//! [`MAX_RESOLVING_ROWS`] rows, pixel spacing at most one lobe width), so
//! every exponent up to the conventions' largest is resolved. Products shown
//! to people (previews, re-renders of a photo) and `picker synth`'s images
//! use it; the eq. 3.7 reference renders keep the map as it is.

use std::sync::OnceLock;

use glam::{DVec3, Vec3};
use picker_nets::conventions as conv;
use rayon::prelude::*;

use crate::envmap::EnvMap;
use crate::phong::{unit, PhongMaterial};

/// Rows of the irradiance grid (columns are twice as many).
pub const IRRADIANCE_ROWS: usize = 32;
/// Rows of the coarsest specular level.
pub const MIN_LEVEL_ROWS: usize = 16;
/// Lobe weights below this fraction of the peak are skipped.
pub const LOBE_CUTOFF: f64 = 1e-3;
/// Rows of the finest level [`PrefilteredEnv::resolving`] makes: enough
/// for the conventions' largest exponent, 8192 (`π·√8192` = 284 at one
/// lobe width per pixel; 427 at the map's own levels' 2/3).
pub const MAX_RESOLVING_ROWS: usize = 512;
/// Largest ratio of pixel spacing to lobe width `1/√n` in the chosen level
/// finer than the map ([`PrefilteredEnv::resolving`]): the map's bilinear
/// upsampling is smooth between its own pixels, so samples one lobe width
/// apart sum the lobe to within about `exp(−2π²)` ≈ 3·10⁻⁹ of its integral
/// (Poisson summation of the near-Gaussian lobe), with 0.44× the pixels of
/// the map's own levels' spacing.
const FINER_SPACING_PER_LOBE_WIDTH: f64 = 1.0;
/// Largest ratio of pixel spacing to lobe width `1/√n` in the chosen level.
const SPACING_PER_LOBE_WIDTH: f64 = 2.0 / 3.0;

/// One level of the specular chain: directions and `L·ΔΩ` of every pixel.
#[derive(Clone, Debug)]
struct Level {
    rows: usize,
    cols: usize,
    dirs: Vec<Vec3>,
    weighted: Vec<Vec3>,
    lat: Vec<f64>,
}

impl Level {
    fn new(env: &EnvMap) -> Self {
        let (h, w) = (env.height(), env.width());
        let mut dirs = Vec::with_capacity(h * w);
        let mut weighted = Vec::with_capacity(h * w);
        for row in 0..h {
            let sa = conv::pixel_solid_angle(row, h, w) as f32;
            for col in 0..w {
                dirs.push(env.direction(row, col));
                weighted.push(env.get(row, col) * sa);
            }
        }
        Self {
            rows: h,
            cols: w,
            dirs,
            weighted,
            lat: (0..h).map(|r| conv::envmap_row_latitude(r, h)).collect(),
        }
    }

    /// `Σ L_i ΔΩ_i cosⁿ(ω_i·R) max(0, ω_i·N)` over the lobe's support around
    /// unit `r`; with `fast`, `cosⁿ` and the sum are `f32` (a quarter of the
    /// time of the `f64` power, within 10⁻⁵ relative over a lobe's support:
    /// the levels finer than the map, whose bits nothing older fixed).
    fn lobe_sum(&self, r: DVec3, n: DVec3, exponent: f64, fast: bool) -> DVec3 {
        use std::f64::consts::{FRAC_PI_2, PI};
        let c_min = LOBE_CUTOFF.powf(1.0 / exponent.max(1e-3));
        let alpha = c_min.clamp(-1.0, 1.0).acos();
        let lat_r = r.y.clamp(-1.0, 1.0).asin();
        let margin = PI / self.rows as f64;
        let (sw, rf, nf) = (self.cols, r.as_vec3(), n.as_vec3());
        let span = if lat_r.abs() + alpha + margin >= FRAC_PI_2 {
            PI
        } else {
            (alpha.sin() / (lat_r.abs() + margin).cos())
                .clamp(-1.0, 1.0)
                .asin()
                + 2.0 * PI / sw as f64
        };
        let half_cols = (span / (2.0 * PI) * sw as f64).ceil() as i64;
        let all_cols = 2 * half_cols + 1 >= sw as i64;
        let (x, _) = conv::envmap_position(r.to_array(), self.rows, sw);
        let centre = x.floor() as i64;
        let mut acc = DVec3::ZERO;
        let mut acc32 = Vec3::ZERO;
        let exponent_f32 = exponent as f32;
        let mut visit = |i: usize| {
            let d = self.dirs[i];
            let ca = d.dot(rf);
            if ca < c_min as f32 {
                return;
            }
            let ci = d.dot(nf);
            if ci <= 0.0 {
                return;
            }
            if fast {
                acc32 += self.weighted[i] * (ca.powf(exponent_f32) * ci);
            } else {
                acc += self.weighted[i].as_dvec3() * ((ca as f64).powf(exponent) * ci as f64);
            }
        };
        // Rows whose latitude is within `alpha + margin` of the lobe's
        // (lat = π/2 − π(row + ½)/H), one more each side for rounding; the
        // test below decides, as over every row.
        let h = self.rows as f64;
        let row_of = |lat: f64| (FRAC_PI_2 - lat) / PI * h - 0.5;
        let first = (row_of(lat_r + alpha + margin).floor() - 1.0).max(0.0) as usize;
        let last = (row_of(lat_r - alpha - margin).ceil() + 1.0).clamp(0.0, h - 1.0) as usize;
        for (row, &lat) in self.lat.iter().enumerate().take(last + 1).skip(first) {
            if (lat - lat_r).abs() > alpha + margin {
                continue;
            }
            let base = row * sw;
            if all_cols {
                (0..sw).for_each(|c| visit(base + c));
            } else {
                for dc in -half_cols..=half_cols {
                    visit(base + (centre + dc).rem_euclid(sw as i64) as usize);
                }
            }
        }
        acc + acc32.as_dvec3()
    }
}

/// An environment map prepared for fast Phong shading (module docs).
#[derive(Clone, Debug)]
pub struct PrefilteredEnv {
    irradiance: EnvMap,
    levels: Vec<Level>,
    /// With [`PrefilteredEnv::resolving`]: the map, and the rows of each
    /// level finer than it with the level once a lobe has needed it.
    finer: Option<(EnvMap, Vec<FinerLevel>)>,
}

/// A level finer than the map: its rows, and the level once made.
type FinerLevel = (usize, OnceLock<Level>);

/// `env` area-averaged down to at most `rows × 2·rows` (as is if already smaller).
fn at_most(env: &EnvMap, rows: usize) -> EnvMap {
    if env.height() <= rows && env.width() <= 2 * rows {
        env.clone()
    } else {
        let h = env.height().min(rows);
        let w = env.width().min(2 * rows);
        env.resample(w, h).expect("sizes are positive")
    }
}

/// The specular chain of `env`: its area-correct downsamplings to rows
/// `16·2^(j/2)` below its own, then the map itself.
fn levels(env: &EnvMap) -> Vec<Level> {
    let mut levels = Vec::new();
    let mut j = 0;
    loop {
        let rows = (MIN_LEVEL_ROWS as f64 * (j as f64 / 2.0).exp2()).round() as usize;
        if rows >= env.height() {
            levels.push(Level::new(env));
            return levels;
        }
        levels.push(Level::new(&at_most(env, rows)));
        j += 1;
    }
}

/// The irradiance `E(N)` on an `IRRADIANCE_ROWS × 2·IRRADIANCE_ROWS` grid of normals.
fn irradiance_map(env: &EnvMap) -> EnvMap {
    let src = at_most(env, 2 * IRRADIANCE_ROWS);
    let (sh, sw) = (src.height(), src.width());
    let dirs: Vec<DVec3> = (0..sh * sw)
        .map(|i| DVec3::from(conv::envmap_pixel_direction(i / sw, i % sw, sh, sw)))
        .collect();
    let sa = conv::envmap_row_solid_angles(sh, sw);
    let (h, w) = (IRRADIANCE_ROWS, 2 * IRRADIANCE_ROWS);
    let data: Vec<Vec3> = (0..h * w)
        .into_par_iter()
        .map(|i| {
            let n = DVec3::from(conv::envmap_pixel_direction(i / w, i % w, h, w));
            let mut acc = DVec3::ZERO;
            for (j, (d, l)) in dirs.iter().zip(src.data()).enumerate() {
                let c = d.dot(n);
                if c > 0.0 {
                    acc += l.as_dvec3() * (c * sa[j / sw]);
                }
            }
            acc.as_vec3()
        })
        .collect();
    EnvMap::derived(w, h, data)
}

impl PrefilteredEnv {
    /// Prepares `env`: the irradiance grid (rayon over normals) and the chain
    /// of downsampled levels. Deterministic.
    pub fn new(env: &EnvMap) -> Self {
        Self {
            irradiance: irradiance_map(env),
            levels: levels(env),
            finer: None,
        }
    }

    /// [`PrefilteredEnv::new`] reading `env` as a continuous function (module
    /// docs): lobes narrower than the map resolves are summed over its
    /// bilinear upsampling to the next level of the chain that resolves them
    /// (rows `16·2^(j/2)`, up to [`MAX_RESOLVING_ROWS`]), made the first time
    /// one is needed; the irradiance of a map under 64 rows is that of its
    /// bilinear upsampling to 64. Lobes the map resolves are summed as by
    /// `new`, to the same bits.
    pub fn resolving(env: &EnvMap) -> Self {
        let h = env.height();
        // The irradiance of the continuous map: a map coarser than the
        // irradiance's source grid is upsampled to it first.
        let rows = 2 * IRRADIANCE_ROWS;
        let irradiance = if h < rows {
            let cols = (rows * env.width()).div_ceil(h).max(1);
            irradiance_map(&env.resample(cols, rows).expect("sizes are positive"))
        } else {
            irradiance_map(env)
        };
        let mut p = Self {
            irradiance,
            levels: levels(env),
            finer: None,
        };
        if h < MAX_RESOLVING_ROWS {
            let finer = (0..)
                .map(|j| (MIN_LEVEL_ROWS as f64 * (j as f64 / 2.0).exp2()).round() as usize)
                .filter(|&rows| rows > h)
                .map(|rows| rows.min(MAX_RESOLVING_ROWS))
                .take_while(|&rows| rows < MAX_RESOLVING_ROWS)
                .chain([MAX_RESOLVING_ROWS])
                .map(|rows| (rows, OnceLock::new()))
                .collect();
            p.finer = Some((env.clone(), finer));
        }
        p
    }

    /// The irradiance `E(N) = ∫ L(ω) max(0, ω·N) dω` for a unit normal (bilinear lookup).
    pub fn irradiance(&self, normal: Vec3) -> Vec3 {
        self.irradiance.sample(normal)
    }

    /// Eq. 3.7, approximated (module docs): same arguments and conventions as
    /// [`shade_exact`](crate::shade_exact); a zero or non-finite normal gives black.
    pub fn shade(&self, normal: Vec3, view: Vec3, material: &PhongMaterial) -> Vec3 {
        let Some(n) = unit(normal) else {
            return Vec3::ZERO;
        };
        let v = unit(view).unwrap_or(DVec3::Z);
        let diffuse = material.diffuse * self.irradiance.sample(n.as_vec3()) / std::f32::consts::PI;
        if material.specular == Vec3::ZERO {
            return diffuse;
        }
        let e = material.exponent.max(0.0) as f64;
        // Finest spacing needed: π/H ≤ (2/3)/√n.
        let need = std::f64::consts::PI * e.sqrt() / SPACING_PER_LOBE_WIDTH;
        let (level, fast) = match self.levels.iter().find(|l| l.rows as f64 >= need) {
            Some(l) => (l, false),
            None => match &self.finer {
                Some((env, finer)) => {
                    // The upsampled map is smooth at its own pixels' scale:
                    // a spacing of one lobe width samples the lobe well.
                    let need = need * SPACING_PER_LOBE_WIDTH / FINER_SPACING_PER_LOBE_WIDTH;
                    let (rows, cell) = finer
                        .iter()
                        .find(|(rows, _)| *rows as f64 >= need)
                        .unwrap_or(&finer[finer.len() - 1]);
                    let level = cell.get_or_init(|| {
                        let cols = (rows * env.width()).div_ceil(env.height()).max(1);
                        Level::new(&env.resample(cols, *rows).expect("sizes are positive"))
                    });
                    (level, true)
                }
                None => (&self.levels[self.levels.len() - 1], false),
            },
        };
        let r = 2.0 * v.dot(n) * n - v;
        let s = level.lobe_sum(r, n, e, fast) * ((e + 2.0) / (2.0 * std::f64::consts::PI));
        diffuse + material.specular * s.as_vec3()
    }
}
