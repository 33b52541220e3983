//! The baseline: a harmonic (membrane) fill. Unknown texels solve Laplace's
//! equation `Δu = 0` with the known texels as Dirichlet data (Bertalmío et
//! al. 2000 without the transport term; visually close to Telea 2004 on small
//! holes), i.e. every unknown texel is the mean of its 4 neighbours.
//!
//! The solve is coarse-to-fine so it converges in a few sweeps even on 1024²
//! textures with large holes: a pull pyramid (a coarse texel is known when any
//! of its 2×2 children is, with their mean), an exact-enough solve on the
//! coarsest level, then at each finer level the coarse solution initialises the
//! unknown texels and red-black Gauss–Seidel sweeps remove the remaining
//! high-frequency error. Channels are independent and solved in parallel, so
//! the result does not depend on the number of threads.

use rayon::prelude::*;

use crate::{validate, Image, InpaintOptions, Inpainter, Plan, Result};

/// Harmonic (diffusion) inpainting, the baseline (see the [module docs](self)).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DiffusionInpainter {
    /// Gauss–Seidel sweeps at most per pyramid level (the coarsest level gets
    /// 20 times as many).
    pub max_sweeps: usize,
    /// A level stops early once no texel moves by more than this.
    pub tolerance: f32,
}

impl Default for DiffusionInpainter {
    fn default() -> Self {
        Self {
            max_sweeps: 60,
            tolerance: 1e-5,
        }
    }
}

impl Inpainter for DiffusionInpainter {
    fn name(&self) -> &str {
        "diffusion"
    }

    fn inpaint(&self, image: &Image, known: &[bool], opts: &InpaintOptions) -> Result<Image> {
        if let Plan::Done(img) = validate(image, known, opts)? {
            return Ok(img);
        }
        let mut out = image.clone();
        diffuse_planes(
            &mut out.data,
            known,
            image.channels,
            image.height,
            image.width,
            opts.toroidal,
            self.max_sweeps,
            self.tolerance,
        );
        Ok(out)
    }
}

/// One level of the mask pyramid.
struct MaskLevel {
    h: usize,
    w: usize,
    known: Vec<bool>,
    /// Unknown texel indices, "red" (`(row + col)` even) ones first.
    order: Vec<usize>,
}

impl MaskLevel {
    fn new(h: usize, w: usize, known: Vec<bool>) -> Self {
        let mut order: Vec<usize> = (0..h * w)
            .filter(|&i| !known[i] && (i / w + i % w).is_multiple_of(2))
            .collect();
        order.extend((0..h * w).filter(|&i| !known[i] && !(i / w + i % w).is_multiple_of(2)));
        Self { h, w, known, order }
    }
}

/// Fills the unknown texels of `c` planar planes of `h × w` (at least one
/// texel known) in place; unknown input values are never read.
#[allow(clippy::too_many_arguments)]
pub(crate) fn diffuse_planes(
    data: &mut [f32],
    known: &[bool],
    c: usize,
    h: usize,
    w: usize,
    toroidal: bool,
    max_sweeps: usize,
    tolerance: f32,
) {
    debug_assert_eq!(data.len(), c * h * w);
    // The mask pyramid, shared by all channels.
    let mut levels = vec![MaskLevel::new(h, w, known.to_vec())];
    loop {
        let f = levels.last().expect("at least one level");
        if f.h.max(f.w) <= 8 {
            break;
        }
        let (h2, w2) = (f.h.div_ceil(2), f.w.div_ceil(2));
        let mut k2 = vec![false; h2 * w2];
        for (i, k) in f.known.iter().enumerate() {
            if *k {
                k2[(i / f.w / 2) * w2 + (i % f.w) / 2] = true;
            }
        }
        levels.push(MaskLevel::new(h2, w2, k2));
    }
    let n = h * w;
    data.par_chunks_mut(n.max(1)).take(c).for_each(|plane| {
        // Restriction: mean of the known children.
        let mut values: Vec<Vec<f32>> = vec![plane.to_vec()];
        for l in 1..levels.len() {
            let (f, co) = (&levels[l - 1], &levels[l]);
            let fine = &values[l - 1];
            let mut sum = vec![0.0f64; co.h * co.w];
            let mut cnt = vec![0u32; co.h * co.w];
            for (i, (&k, &v)) in f.known.iter().zip(fine).enumerate() {
                if k {
                    let j = (i / f.w / 2) * co.w + (i % f.w) / 2;
                    sum[j] += v as f64;
                    cnt[j] += 1;
                }
            }
            let coarse = sum
                .iter()
                .zip(&cnt)
                .map(|(&s, &k)| if k > 0 { (s / k as f64) as f32 } else { 0.0 })
                .collect();
            values.push(coarse);
        }
        // Coarsest level: start from the mean of the known texels.
        let top = levels.len() - 1;
        {
            let lv = &levels[top];
            let v = &mut values[top];
            let (s, k) = lv
                .known
                .iter()
                .zip(v.iter())
                .filter(|(k, _)| **k)
                .fold((0.0f64, 0usize), |(s, n), (_, &x)| (s + x as f64, n + 1));
            let mean = if k > 0 { (s / k as f64) as f32 } else { 0.0 };
            for &i in &lv.order {
                v[i] = mean;
            }
            sweep(lv, v, toroidal, max_sweeps.saturating_mul(20), tolerance);
        }
        // Prolongation and smoothing, coarse to fine.
        for l in (0..top).rev() {
            let (lv, co) = (&levels[l], &levels[l + 1]);
            let (lower, upper) = values.split_at_mut(l + 1);
            let (v, cv) = (&mut lower[l], &upper[0]);
            for &i in &lv.order {
                v[i] = prolong(cv, co.h, co.w, i / lv.w, i % lv.w);
            }
            sweep(lv, v, toroidal, max_sweeps, tolerance);
        }
        for &i in &levels[0].order {
            plane[i] = values[0][i];
        }
    });
}

/// Bilinear value of the coarse level at the centre of fine texel `(y, x)`.
fn prolong(cv: &[f32], ch: usize, cw: usize, y: usize, x: usize) -> f32 {
    let fy = ((y as f32 + 0.5) * 0.5 - 0.5).clamp(0.0, (ch - 1) as f32);
    let fx = ((x as f32 + 0.5) * 0.5 - 0.5).clamp(0.0, (cw - 1) as f32);
    let (y0, x0) = (fy as usize, fx as usize);
    let (y1, x1) = ((y0 + 1).min(ch - 1), (x0 + 1).min(cw - 1));
    let (ty, tx) = (fy - y0 as f32, fx - x0 as f32);
    let a = cv[y0 * cw + x0] * (1.0 - tx) + cv[y0 * cw + x1] * tx;
    let b = cv[y1 * cw + x0] * (1.0 - tx) + cv[y1 * cw + x1] * tx;
    a * (1.0 - ty) + b * ty
}

/// Red-black Gauss–Seidel sweeps of `u = mean of the 4 neighbours` over the
/// unknown texels of one level, until no texel moves by more than `tol`.
fn sweep(lv: &MaskLevel, v: &mut [f32], toroidal: bool, max_sweeps: usize, tol: f32) {
    let (h, w) = (lv.h, lv.w);
    for _ in 0..max_sweeps {
        let mut change = 0.0f32;
        for &i in &lv.order {
            let (y, x) = (i / w, i % w);
            let mut s = 0.0f32;
            let mut k = 0u32;
            let mut add = |j: usize| {
                if j != i {
                    s += v[j];
                    k += 1;
                }
            };
            if x > 0 {
                add(i - 1);
            } else if toroidal {
                add(i + w - 1);
            }
            if x + 1 < w {
                add(i + 1);
            } else if toroidal {
                add(i + 1 - w);
            }
            if y > 0 {
                add(i - w);
            } else if toroidal {
                add(i + (h - 1) * w);
            }
            if y + 1 < h {
                add(i + w);
            } else if toroidal {
                add(i - (h - 1) * w);
            }
            if k > 0 {
                let nv = s / k as f32;
                change = change.max((nv - v[i]).abs());
                v[i] = nv;
            }
        }
        if change <= tol {
            break;
        }
    }
}
