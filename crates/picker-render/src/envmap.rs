//! Equirectangular environment maps in the conventions' mapping
//! ([`picker_nets::conventions::envmap_direction`]: row 0 straight up, centre
//! column straight ahead = −z, camera space): sampling, area-correct
//! resampling, rotation, and EXR / Radiance `.hdr` files.

use std::path::Path;

use glam::{DVec3, Mat3, Vec3};
use picker_nets::conventions as conv;
use picker_tensor::Tensor;

use crate::error::{Error, Result};
use crate::io;

/// Largest radiance magnitude an [`EnvMap`] holds (far above any physical
/// scene, the sun included: ~1e9 in typical HDR units), so that every sum
/// of the map over the sphere stays finite in `f32`.
pub const MAX_RADIANCE: f32 = 1e30;

/// The share of an [`EnvMap`]'s width on each side of its wrap seam over
/// which [`EnvMap::close_wrap_seam`] spreads its change (1/8: 45° of
/// azimuth behind the camera, where a network sees nothing).
pub const WRAP_SEAM_BAND: f32 = 0.125;

/// The share of an [`EnvMap`]'s rows at each pole over which
/// [`EnvMap::regularise_poles`] smooths the map around the pole (1/8: the
/// 22.5° nearest each pole).
pub const POLE_BAND: f32 = 0.125;

/// A linear-RGB HDR radiance map, `height × width`, row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct EnvMap {
    width: usize,
    height: usize,
    data: Vec<Vec3>,
}

impl EnvMap {
    /// A map from row-major radiance values; refuses a zero size, a wrong
    /// length, NaN or infinite values (a corrupt map: its NaN would reach
    /// every shaded pixel through the prefiltering and the exposure) and
    /// magnitudes beyond [`MAX_RADIANCE`]. Shading integrates the map at its
    /// pixel centres: a map only one or two pixels tall samples too few
    /// directions to light a surface faithfully.
    pub fn new(width: usize, height: usize, data: Vec<Vec3>) -> Result<Self> {
        if width == 0 || height == 0 {
            return Err(Error::Invalid {
                what: "environment map size",
                reason: format!("{height}x{width} is empty"),
            });
        }
        let Some(n) = width.checked_mul(height) else {
            return Err(Error::Invalid {
                what: "environment map size",
                reason: format!("{height}x{width} overflows"),
            });
        };
        if data.len() != n {
            return Err(Error::shape(
                format!("{height}x{width} environment map"),
                format!("{} pixels", width * height),
                data.len(),
            ));
        }
        let bad = data.iter().filter(|v| !v.is_finite()).count();
        if let Some(first) = data.iter().position(|v| !v.is_finite()) {
            return Err(Error::Invalid {
                what: "environment map radiance",
                reason: format!(
                    "{bad} of its {} pixels are NaN or infinite (the first at row {}, column {}); \
                     an environment map must be finite",
                    data.len(),
                    first / width,
                    first % width
                ),
            });
        }
        if let Some(first) = data
            .iter()
            .position(|v| v.abs().max_element() > MAX_RADIANCE)
        {
            return Err(Error::Invalid {
                what: "environment map radiance",
                reason: format!(
                    "the pixel at row {}, column {} has magnitude {:e}, beyond the {MAX_RADIANCE:e} an \
                     environment map may hold (sums of it over the sphere would overflow)",
                    first / width,
                    first % width,
                    data[first].abs().max_element()
                ),
            });
        }
        Ok(Self {
            width,
            height,
            data,
        })
    }

    /// A map derived inside this crate from a valid one (its irradiance: at
    /// most π times [`MAX_RADIANCE`], finite): no radiance bound.
    pub(crate) fn derived(width: usize, height: usize, data: Vec<Vec3>) -> Self {
        debug_assert_eq!(data.len(), width * height);
        debug_assert!(data.iter().all(|v| v.is_finite()));
        Self {
            width,
            height,
            data,
        }
    }

    /// A map of constant radiance `rgb` (sizes of 0 are raised to 1).
    ///
    /// # Panics
    /// When `width · height` overflows `usize`.
    pub fn uniform(width: usize, height: usize, rgb: Vec3) -> Self {
        let (width, height) = (width.max(1), height.max(1));
        let n = width
            .checked_mul(height)
            .unwrap_or_else(|| panic!("EnvMap::uniform: {height}x{width} overflows"));
        Self {
            width,
            height,
            data: vec![rgb; n],
        }
    }

    /// Columns.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Rows.
    pub fn height(&self) -> usize {
        self.height
    }

    /// The row-major pixels.
    pub fn data(&self) -> &[Vec3] {
        &self.data
    }

    /// The row-major pixels, mutable.
    pub fn data_mut(&mut self) -> &mut [Vec3] {
        &mut self.data
    }

    /// Radiance of pixel `(row, col)`.
    ///
    /// # Panics
    /// When the pixel is outside the map.
    pub fn get(&self, row: usize, col: usize) -> Vec3 {
        assert!(
            row < self.height && col < self.width,
            "EnvMap::get: pixel ({row}, {col}) is outside the {}x{} map",
            self.height,
            self.width
        );
        self.data[row * self.width + col]
    }

    /// Unit camera-space direction of the centre of pixel `(row, col)`
    /// ([`conv::envmap_pixel_direction`]).
    pub fn direction(&self, row: usize, col: usize) -> Vec3 {
        let d = conv::envmap_pixel_direction(row, col, self.height, self.width);
        Vec3::new(d[0] as f32, d[1] as f32, d[2] as f32)
    }

    /// Solid angle (sr) of a pixel of row `row` ([`conv::pixel_solid_angle`], exact band area).
    pub fn solid_angle(&self, row: usize) -> f64 {
        conv::pixel_solid_angle(row, self.height, self.width)
    }

    /// Radiance seen in direction `dir` (need not be unit length): bilinear
    /// between pixel centres, wrapping in longitude and clamping in latitude
    /// (within half a pixel of a pole the nearest row is used).
    pub fn sample(&self, dir: Vec3) -> Vec3 {
        let (x, y) = conv::envmap_position(
            [dir.x as f64, dir.y as f64, dir.z as f64],
            self.height,
            self.width,
        );
        self.sample_position(x, y)
    }

    /// Bilinear sample at the continuous position `(x, y)` in pixels (centres at `+0.5`).
    pub(crate) fn sample_position(&self, x: f64, y: f64) -> Vec3 {
        let (w, h) = (self.width, self.height);
        let fy = (y - 0.5).clamp(0.0, (h - 1) as f64);
        let r0 = (fy.floor() as usize).min(h - 1);
        let r1 = (r0 + 1).min(h - 1);
        let ty = (fy - r0 as f64) as f32;
        let fx = x - 0.5;
        let c0f = fx.floor();
        let tx = (fx - c0f) as f32;
        let c0 = (c0f as i64).rem_euclid(w as i64) as usize;
        let c1 = (c0 + 1) % w;
        let top = self.get(r0, c0).lerp(self.get(r0, c1), tx);
        let bottom = self.get(r1, c0).lerp(self.get(r1, c1), tx);
        top.lerp(bottom, ty)
    }

    /// The solid-angle-weighted mean radiance `Σ L_i ΔΩ_i / 4π` (f64 accumulation).
    pub fn mean(&self) -> Vec3 {
        let mut acc = DVec3::ZERO;
        for row in 0..self.height {
            let mut r = DVec3::ZERO;
            for col in 0..self.width {
                r += self.get(row, col).as_dvec3();
            }
            acc += r * self.solid_angle(row);
        }
        (acc / (4.0 * std::f64::consts::PI)).as_vec3()
    }

    /// The `ε` added before taking logs of radiance ([`Self::close_wrap_seam`],
    /// [`Self::regularise_poles`]): 10⁻³ of the map's mean, so black stays finite.
    fn log_floor(&self) -> Vec3 {
        (self.mean() * 1e-3).max(Vec3::splat(1e-30))
    }

    /// Closes the map's wrap seam: the left and right edges are one
    /// direction (straight behind the camera) but a network predicts them
    /// apart, so a reflection that looks behind (a sphere's centre) showed a
    /// line where they meet. Per row, in the log of the radiance (with
    /// `ε` = 10⁻³ of the map's mean added, so that black stays finite), the
    /// step across the seam is made the mean of the steps just inside it on
    /// either side; the change is spread over [`WRAP_SEAM_BAND`] of the
    /// width on each side, falling linearly from half the excess step at the
    /// edge to nothing at the band's end. A map continuous across the seam
    /// (its seam step within 10⁻⁶ of that mean) is left as it is; columns outside
    /// the bands never change. Maps narrower than 4 columns are left alone.
    /// Returns the largest factor an edge pixel was changed by (1: none).
    pub fn close_wrap_seam(&mut self) -> f32 {
        let (w, h) = (self.width, self.height);
        if w < 4 {
            return 1.0;
        }
        let band = ((w as f32 * WRAP_SEAM_BAND).round() as usize).clamp(1, w / 2);
        let eps = self.log_floor();
        let ln = |v: Vec3| Vec3::new((v.x + eps.x).ln(), (v.y + eps.y).ln(), (v.z + eps.z).ln());
        let mut worst = 0.0f32;
        for row in 0..h {
            let at = |c: usize| ln(self.get(row, c));
            let step = at(0) - at(w - 1);
            let inside = 0.5 * ((at(1) - at(0)) + (at(w - 1) - at(w - 2)));
            let excess = step - inside;
            if excess.abs().max_element() < 1e-6 {
                continue;
            }
            worst = worst.max(excess.abs().max_element() * 0.5);
            for k in 0..band {
                let f = 1.0 - k as f32 / band as f32;
                let shift = excess * (0.5 * f);
                for (c, sign) in [(k, -1.0f32), (w - 1 - k, 1.0)] {
                    let v = &mut self.data[row * w + c];
                    let l = ln(*v) + shift * sign;
                    *v = (Vec3::new(l.x.exp(), l.y.exp(), l.z.exp()) - eps)
                        .max(Vec3::ZERO)
                        .min(Vec3::splat(MAX_RADIANCE));
                }
            }
        }
        worst.exp()
    }

    /// Makes the map regular at its poles: every pixel of the top (bottom)
    /// row lies within half a row of straight up (down), so the map cannot
    /// vary much around a pole, but a network predicts each column apart,
    /// and a glossy sphere's reflection of the zenith showed a pinched cone.
    /// In the [`POLE_BAND`] of rows nearest each pole, each row's log
    /// radiance (with `ε` = 10⁻³ of the map's mean added) is split into its
    /// harmonics around the pole (a discrete Fourier series over the
    /// columns) and harmonic `m ≥ 1` is scaled by `(θ/θ_b)^m`, `θ` the row's
    /// angle from the pole and `θ_b` the band's: a function smooth on the
    /// sphere has its `m`-th harmonic shrink like `θ^m` there. Each row's
    /// mean (its 0th harmonic) and the rows outside the bands are kept.
    /// Maps under 8 rows or 4 columns are left alone. Returns the largest
    /// factor a pixel was changed by (1: none).
    pub fn regularise_poles(&mut self) -> f32 {
        let (w, h) = (self.width, self.height);
        if h < 8 || w < 4 {
            return 1.0;
        }
        let band = ((h as f32 * POLE_BAND).round() as usize).clamp(1, h / 2);
        let eps = self.log_floor();
        let theta_b = band as f64;
        let mut worst = 0.0f32;
        let tau = std::f64::consts::TAU;
        let rows = (0..band)
            .map(|k| (k, k))
            .chain((0..band).map(|k| (h - 1 - k, k)));
        for (row, k) in rows {
            // Angle from the pole in rows: the row's centre.
            let ratio = (k as f64 + 0.5) / theta_b;
            for c in 0..3 {
                let logs: Vec<f64> = (0..w)
                    .map(|x| f64::from(self.data[row * w + x][c] + eps[c]).ln())
                    .collect();
                let mut out: Vec<f64> = vec![0.0; w];
                // Harmonics 0..=w/2 (real series); the Nyquist one once.
                for m in 0..=w / 2 {
                    let (mut a, mut b) = (0.0f64, 0.0f64);
                    for (x, l) in logs.iter().enumerate() {
                        let ph = tau * (m * x) as f64 / w as f64;
                        a += l * ph.cos();
                        b += l * ph.sin();
                    }
                    let norm = if m == 0 || 2 * m == w { 1.0 } else { 2.0 } / w as f64;
                    let scale = if m == 0 { 1.0 } else { ratio.powi(m as i32) };
                    for (x, o) in out.iter_mut().enumerate() {
                        let ph = tau * (m * x) as f64 / w as f64;
                        *o += norm * scale * (a * ph.cos() + b * ph.sin());
                    }
                }
                for (x, o) in out.iter().enumerate() {
                    let v = &mut self.data[row * w + x][c];
                    let change = (o - logs[x]) as f32;
                    worst = worst.max(change.abs());
                    *v = ((o.exp() - f64::from(eps[c])) as f32).clamp(0.0, MAX_RADIANCE);
                }
            }
        }
        worst.exp()
    }

    /// The map at `width × height`. Downsampling (either dimension smaller) is
    /// area-correct: each target pixel is the solid-angle-weighted average of
    /// the source pixels it overlaps (weights = overlap area on the sphere, so
    /// the map's mean radiance is preserved exactly). Upsampling (both
    /// dimensions at least as large) samples bilinearly at the target centres.
    pub fn resample(&self, width: usize, height: usize) -> Result<EnvMap> {
        if width == 0 || height == 0 {
            return Err(Error::Invalid {
                what: "environment map size",
                reason: format!("{height}x{width} is empty"),
            });
        }
        if width == self.width && height == self.height {
            return Ok(self.clone());
        }
        if width.checked_mul(height).is_none() {
            return Err(Error::Invalid {
                what: "environment map size",
                reason: format!("{height}x{width} overflows"),
            });
        }
        if width >= self.width && height >= self.height {
            let sx = self.width as f64 / width as f64;
            let sy = self.height as f64 / height as f64;
            let mut data = Vec::with_capacity(width * height);
            for row in 0..height {
                for col in 0..width {
                    data.push(
                        self.sample_position((col as f64 + 0.5) * sx, (row as f64 + 0.5) * sy),
                    );
                }
            }
            return EnvMap::new(width, height, data);
        }
        // Longitude overlaps: fractions of the full turn shared by target column j and source column k.
        let overlaps = |n_src: usize, n_dst: usize, weight: &dyn Fn(f64, f64) -> f64| {
            let mut out: Vec<Vec<(usize, f64)>> = vec![Vec::new(); n_dst];
            for (j, o) in out.iter_mut().enumerate() {
                let (a, b) = (j as f64 / n_dst as f64, (j + 1) as f64 / n_dst as f64);
                let k0 = (a * n_src as f64).floor() as usize;
                let k1 = ((b * n_src as f64).ceil() as usize).min(n_src);
                for k in k0..k1 {
                    let lo = a.max(k as f64 / n_src as f64);
                    let hi = b.min((k + 1) as f64 / n_src as f64);
                    if hi > lo {
                        let wgt = weight(lo, hi);
                        if wgt > 0.0 {
                            o.push((k, wgt));
                        }
                    }
                }
            }
            out
        };
        let cols = overlaps(self.width, width, &|lo, hi| hi - lo);
        // Latitude: t ∈ [0,1] from the top; band area ∝ sin(lat(lo)) − sin(lat(hi)).
        let lat = |t: f64| std::f64::consts::FRAC_PI_2 - std::f64::consts::PI * t;
        let rows = overlaps(self.height, height, &|lo, hi| lat(lo).sin() - lat(hi).sin());
        let mut data = Vec::with_capacity(width * height);
        for rw in &rows {
            for cw in &cols {
                let mut acc = DVec3::ZERO;
                let mut total = 0.0;
                for &(r, wr) in rw {
                    for &(c, wc) in cw {
                        acc += self.get(r, c).as_dvec3() * (wr * wc);
                        total += wr * wc;
                    }
                }
                data.push(if total > 0.0 {
                    (acc / total).as_vec3()
                } else {
                    Vec3::ZERO
                });
            }
        }
        EnvMap::new(width, height, data)
    }

    /// The environment turned by the rotation `r`: `out.sample(r·d) == self.sample(d)`,
    /// i.e. each output pixel in direction `e` is `self.sample(rᵀ·e)` (bilinear).
    /// `r` should be orthonormal; the output has the same size.
    pub fn rotated(&self, r: Mat3) -> EnvMap {
        let rt = r.transpose();
        let mut data = Vec::with_capacity(self.data.len());
        for row in 0..self.height {
            for col in 0..self.width {
                data.push(self.sample(rt * self.direction(row, col)));
            }
        }
        EnvMap {
            width: self.width,
            height: self.height,
            data,
        }
    }

    /// [`rotated`](Self::rotated) by `radians` about the up axis (+y, right-handed:
    /// a positive angle turns what was straight ahead (−z) towards the left (−x)).
    pub fn rotated_yaw(&self, radians: f32) -> EnvMap {
        self.rotated(Mat3::from_rotation_y(radians))
    }

    /// From a tensor `[1, 3, H, W]` (planar RGB).
    pub fn from_tensor(t: &Tensor) -> Result<EnvMap> {
        let [n, c, h, w] = t.shape();
        if n != 1 || c != 3 {
            return Err(Error::shape(
                "environment map tensor",
                "[1, 3, H, W]",
                format!("{:?}", t.shape()),
            ));
        }
        let img = t.image(0);
        let hw = h * w;
        let data = (0..hw)
            .map(|i| Vec3::new(img[i], img[hw + i], img[2 * hw + i]))
            .collect();
        EnvMap::new(w, h, data)
    }

    /// As a tensor `[1, 3, H, W]` (planar RGB).
    pub fn to_tensor(&self) -> Tensor {
        let img = self.to_image();
        Tensor::new([1, 3, self.height, self.width], img.data)
            .expect("the length of a 3-plane image matches its shape")
    }

    /// As a planar 3-channel image.
    pub fn to_image(&self) -> io::Image {
        let mut img = io::Image::zeros(3, self.height, self.width);
        for (i, &v) in self.data.iter().enumerate() {
            img.set_rgb(i, v);
        }
        img
    }

    /// From a planar image with 3 (RGB) or 1 (grey) channels.
    pub fn from_image(img: &io::Image) -> Result<EnvMap> {
        if img.channels != 3 && img.channels != 1 {
            return Err(Error::shape(
                "environment map image",
                "1 or 3 channels",
                img.channels,
            ));
        }
        EnvMap::new(
            img.width,
            img.height,
            (0..img.plane_len()).map(|i| img.rgb(i)).collect(),
        )
    }

    /// Reads an environment map: OpenEXR (`.exr`: channels R,G,B — an A is
    /// ignored — or Y; f32 or half) or Radiance RGBE (`.hdr`, `.pic`), by extension.
    pub fn read(path: &Path) -> Result<EnvMap> {
        match io::extension(path).as_str() {
            "exr" => EnvMap::from_image(&io::read_exr(path)?).map_err(|e| Error::decode(path, e)),
            "hdr" | "pic" => {
                let f = std::fs::File::open(path).map_err(|e| Error::io(path, "open", e))?;
                let dec = image::codecs::hdr::HdrDecoder::new(std::io::BufReader::new(f))
                    .map_err(|e| Error::decode(path, e))?;
                let img = image::DynamicImage::from_decoder(dec)
                    .map_err(|e| Error::decode(path, e))?
                    .to_rgb32f();
                let (w, h) = (img.width() as usize, img.height() as usize);
                let data = img.pixels().map(|p| Vec3::from(p.0)).collect();
                EnvMap::new(w, h, data).map_err(|e| Error::decode(path, e))
            }
            other => Err(Error::decode(
                path,
                format!("unsupported environment map type {other:?} (expected .exr or .hdr)"),
            )),
        }
    }

    /// Writes the map as a 32-bit float RGB EXR, atomically.
    pub fn write_exr(&self, path: &Path) -> Result<()> {
        io::write_exr(path, &self.to_image())
    }

    /// Writes the map as Radiance RGBE (`.hdr`, run-length encoded by the
    /// `image` crate's encoder), atomically. RGBE keeps 8-bit mantissas: about
    /// 1% relative precision; negative values become 0.
    pub fn write_hdr(&self, path: &Path) -> Result<()> {
        let px: Vec<image::Rgb<f32>> = self
            .data
            .iter()
            .map(|v| image::Rgb(v.max(Vec3::ZERO).to_array()))
            .collect();
        let mut buf = Vec::new();
        image::codecs::hdr::HdrEncoder::new(&mut buf)
            .encode(&px, self.width, self.height)
            .map_err(|e| Error::Encode {
                format: "HDR",
                reason: e.to_string(),
            })?;
        io::write_atomic(path, &buf)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use picker_tensor::Rng;

    fn random_map(rng: &mut Rng, w: usize, h: usize) -> EnvMap {
        let data = (0..w * h)
            .map(|_| {
                Vec3::new(
                    rng.uniform(0.0, 4.0),
                    rng.uniform(0.0, 2.0),
                    rng.uniform(0.0, 1.0),
                )
            })
            .collect();
        EnvMap::new(w, h, data).unwrap()
    }

    #[test]
    fn non_finite_radiance_is_refused_with_its_place() {
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            let mut data = vec![Vec3::splat(0.5); 12];
            data[7] = Vec3::new(0.1, bad, 0.2);
            data[9] = Vec3::splat(bad);
            let e = EnvMap::new(4, 3, data).unwrap_err().to_string();
            assert!(
                e.contains("2 of its 12 pixels") && e.contains("row 1, column 3"),
                "{e}"
            );
        }
        // Negative and large finite values are radiance the caller chose, up
        // to MAX_RADIANCE (beyond it the shaders' sums would overflow).
        let mut data = vec![Vec3::splat(0.5); 12];
        data[0] = Vec3::splat(-1.0);
        data[1] = Vec3::splat(MAX_RADIANCE);
        assert!(EnvMap::new(4, 3, data.clone()).is_ok());
        data[1] = Vec3::splat(3e38);
        let e = EnvMap::new(4, 3, data).unwrap_err().to_string();
        assert!(e.contains("row 0, column 1"), "{e}");
    }

    /// A smooth map (so bilinear sampling is accurate): a sky gradient and a soft lobe.
    pub(crate) fn smooth_map(w: usize, h: usize) -> EnvMap {
        let probe = EnvMap::uniform(w, h, Vec3::ZERO);
        let sun = Vec3::new(0.3, 0.6, -0.5).normalize();
        let data = (0..h)
            .flat_map(|r| (0..w).map(move |c| (r, c)))
            .map(|(r, c)| {
                let d = probe.direction(r, c);
                let s = (d.dot(sun) - 1.0).exp() * 3.0;
                Vec3::new(
                    0.5 + 0.4 * d.y + s,
                    0.7 + 0.2 * d.x + s,
                    1.0 - 0.3 * d.z + 0.5 * s,
                )
            })
            .collect();
        EnvMap::new(w, h, data).unwrap()
    }

    #[test]
    fn sampling_hits_pixel_centres_and_wraps() {
        let mut rng = Rng::new(1);
        let m = random_map(&mut rng, 12, 6);
        for r in 0..6 {
            for c in 0..12 {
                assert!(
                    (m.sample(m.direction(r, c)) - m.get(r, c))
                        .abs()
                        .max_element()
                        < 1e-4
                );
            }
        }
        // Half-way across the seam: the average of the first and last columns.
        let mid = m.sample_position(0.0, 2.5);
        assert!(
            (mid - (m.get(2, 0) + m.get(2, 11)) / 2.0)
                .abs()
                .max_element()
                < 1e-5
        );
        assert!(EnvMap::new(0, 3, vec![]).is_err());
        assert!(EnvMap::new(2, 2, vec![Vec3::ONE; 3]).is_err());
    }

    #[test]
    fn resample_preserves_mean() {
        let mut rng = Rng::new(2);
        let m = random_map(&mut rng, 40, 30);
        for (w, h) in [(20, 15), (16, 8), (7, 5), (1, 1), (40, 15), (13, 31)] {
            let r = m.resample(w, h).unwrap();
            assert_eq!((r.width(), r.height()), (w, h));
            let (a, b) = (m.mean(), r.mean());
            assert!(
                (a - b).abs().max_element() < 1e-5 * a.max_element(),
                "{w}x{h}: {a} {b}"
            );
        }
        let s = smooth_map(32, 16);
        let up = s.resample(128, 64).unwrap();
        let (a, b) = (s.mean(), up.mean());
        assert!(
            (a - b).abs().max_element() < 1e-2 * a.max_element(),
            "{a} {b}"
        );
        let u = EnvMap::uniform(9, 5, Vec3::splat(2.0))
            .resample(4, 3)
            .unwrap();
        assert!(u
            .data()
            .iter()
            .all(|v| (*v - Vec3::splat(2.0)).abs().max_element() < 1e-6));
    }

    #[test]
    fn the_poles_lose_their_azimuthal_detail_as_a_smooth_map_would() {
        let (w, h) = (40usize, 30usize);
        let mut rng = picker_tensor::Rng::new(7);
        let data: Vec<Vec3> = (0..w * h)
            .map(|_| {
                Vec3::new(
                    rng.uniform(0.1, 3.0),
                    rng.uniform(0.1, 3.0),
                    rng.uniform(0.1, 3.0),
                )
            })
            .collect();
        let orig = EnvMap::new(w, h, data).unwrap();
        let mut m = orig.clone();
        let worst = m.regularise_poles();
        assert!(worst > 1.0);
        let band = (h as f32 * POLE_BAND).round() as usize;
        let eps = orig.mean() * 1e-3;
        let logs = |map: &EnvMap, row: usize, c: usize| -> Vec<f64> {
            (0..w)
                .map(|x| f64::from(map.get(row, x)[c] + eps[c]).ln())
                .collect()
        };
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        let spread = |v: &[f64]| {
            let m = mean(v);
            (v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / v.len() as f64).sqrt()
        };
        for (row, k) in (0..band)
            .map(|k| (k, k))
            .chain((0..band).map(|k| (h - 1 - k, k)))
        {
            let ratio = (k as f64 + 0.5) / band as f64;
            for c in 0..3 {
                let (a, b) = (logs(&orig, row, c), logs(&m, row, c));
                // The row's mean (the value at the pole) is kept; its
                // variation around the pole shrinks at least as its first
                // harmonic must.
                assert!((mean(&a) - mean(&b)).abs() < 1e-4, "row {row}");
                assert!(
                    spread(&b) <= ratio * spread(&a) + 1e-6,
                    "row {row}: {} vs {}",
                    spread(&b),
                    spread(&a)
                );
            }
        }
        for row in band..h - band {
            for x in 0..w {
                assert_eq!(m.get(row, x), orig.get(row, x), "({row}, {x})");
            }
        }
        // A uniform map stays uniform; small maps are left alone.
        let mut u = EnvMap::uniform(40, 30, Vec3::new(0.5, 2.0, 0.0));
        u.regularise_poles();
        for v in u.data() {
            assert!(
                (*v - Vec3::new(0.5, 2.0, 0.0)).abs().max_element() < 1e-5,
                "{v}"
            );
        }
        let mut small =
            EnvMap::new(5, 7, (0..35).map(|i| Vec3::splat(i as f32)).collect()).unwrap();
        let before = small.clone();
        assert_eq!(small.regularise_poles(), 1.0);
        assert_eq!(small, before);
    }

    #[test]
    fn the_wrap_seam_is_closed_inside_its_bands_only() {
        // A ramp in log radiance along the columns: steps of `a` inside, a
        // drop of −a(w−1) across the seam, differently per channel and row.
        let (w, h) = (40usize, 6usize);
        let a = |row: usize| Vec3::new(0.05, -0.03, 0.1) * (1.0 + row as f32);
        let ramp = |row: usize, col: usize| {
            let l = a(row) * col as f32;
            Vec3::new(l.x.exp(), l.y.exp(), l.z.exp())
        };
        let data = (0..w * h).map(|i| ramp(i / w, i % w)).collect();
        let orig = EnvMap::new(w, h, data).unwrap();
        let mut m = orig.clone();
        let worst = m.close_wrap_seam();
        let band = (w as f32 * WRAP_SEAM_BAND).round() as usize;
        let eps = orig.mean() * 1e-3;
        let ln = |v: Vec3| Vec3::new((v.x + eps.x).ln(), (v.y + eps.y).ln(), (v.z + eps.z).ln());
        let mut biggest = 0.0f32;
        for row in 0..h {
            let at = |c: usize| ln(m.get(row, c));
            let inside = |c: usize| ln(orig.get(row, c + 1)) - ln(orig.get(row, c));
            // The seam's step is now the mean of the two steps beside it.
            let want = 0.5 * (inside(0) + inside(w - 2));
            let got = at(0) - at(w - 1);
            assert!(
                (got - want).abs().max_element() < 1e-4,
                "row {row}: {got} vs {want}"
            );
            let excess = (ln(orig.get(row, 0)) - ln(orig.get(row, w - 1))) - want;
            biggest = biggest.max(excess.abs().max_element() * 0.5);
            for col in band..w - band {
                assert_eq!(m.get(row, col), orig.get(row, col), "({row}, {col})");
            }
            // Inside the bands the change falls off linearly to the band's end.
            let change = |c: usize| (ln(m.get(row, c)) - ln(orig.get(row, c))).x;
            for k in 0..band {
                let f = 1.0 - k as f32 / band as f32;
                assert!(
                    (change(k) + 0.5 * excess.x * f).abs() < 1e-4,
                    "({row}, {k})"
                );
                assert!((change(w - 1 - k) - 0.5 * excess.x * f).abs() < 1e-4);
            }
        }
        assert!(
            (worst.ln() - biggest).abs() < 1e-4,
            "{worst} vs exp({biggest})"
        );
        // Continuous maps, uniform or periodic along the columns, are left
        // exactly as they were; so are maps under 4 columns.
        for map in [
            EnvMap::uniform(16, 8, Vec3::new(0.2, 3.0, 0.0)),
            EnvMap::new(
                16,
                4,
                (0..64)
                    .map(|i| {
                        let phi = std::f32::consts::TAU * ((i % 16) as f32 + 0.5) / 16.0;
                        Vec3::splat(1.0 + 0.5 * phi.cos())
                    })
                    .collect(),
            )
            .unwrap(),
            EnvMap::new(3, 2, (0..6).map(|i| Vec3::splat(i as f32)).collect()).unwrap(),
        ] {
            let mut closed = map.clone();
            assert_eq!(closed.close_wrap_seam(), 1.0);
            assert_eq!(closed, map);
        }
        // Black next to bright: finite, non-negative.
        let mut m = EnvMap::new(
            8,
            2,
            (0..16)
                .map(|i| {
                    if i % 8 < 4 {
                        Vec3::ZERO
                    } else {
                        Vec3::splat(50.0)
                    }
                })
                .collect(),
        )
        .unwrap();
        assert!(m.close_wrap_seam() > 1.0);
        assert!(m
            .data()
            .iter()
            .all(|v| v.is_finite() && v.min_element() >= 0.0));
    }

    #[test]
    fn rotation_round_trips_away_from_poles() {
        let m = smooth_map(64, 32);
        let r = Mat3::from_euler(glam::EulerRot::YXZ, 0.7, 0.3, -0.2);
        let back = m.rotated(r).rotated(r.transpose());
        for row in 6..26 {
            for col in 0..64 {
                let (a, b) = (m.get(row, col), back.get(row, col));
                assert!(
                    (a - b).abs().max_element() < 0.03 * a.max_element(),
                    "{row},{col}: {a} {b}"
                );
            }
        }
        // The defining property, and yaw by a whole number of columns is a shift.
        let rot = m.rotated(r);
        for d in [Vec3::new(0.2, 0.1, -1.0), Vec3::new(-0.5, -0.4, 0.3)] {
            let (a, b) = (rot.sample(r * d), m.sample(d));
            assert!(
                (a - b).abs().max_element() < 0.05 * b.max_element(),
                "{a} {b}"
            );
        }
        let q = std::f32::consts::FRAC_PI_2;
        let y = m.rotated_yaw(q);
        // Turning by +90° about +y brings what was ahead (-z) to the left (-x).
        let ahead = m.sample(Vec3::NEG_Z);
        assert!((y.sample(Vec3::NEG_X) - ahead).abs().max_element() < 1e-3 * ahead.max_element());
    }

    #[test]
    fn files_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let mut rng = Rng::new(3);
        let m = random_map(&mut rng, 10, 5);
        let p = dir.path().join("env.exr");
        m.write_exr(&p).unwrap();
        assert_eq!(EnvMap::read(&p).unwrap(), m);
        let p = dir.path().join("env.hdr");
        m.write_hdr(&p).unwrap();
        let back = EnvMap::read(&p).unwrap();
        assert_eq!((back.width(), back.height()), (10, 5));
        for (a, b) in back.data().iter().zip(m.data()) {
            // RGBE: 8-bit mantissa shared by the channels.
            assert!(
                (*a - *b).abs().max_element() <= 0.01 * b.max_element() + 1e-6,
                "{a} {b}"
            );
        }
        // Half-float RGBA EXRs are read too (alpha ignored).
        let p = dir.path().join("half.exr");
        exr::prelude::write_rgba_file(&p, 10, 5, |x, y| {
            let v = m.get(y, x);
            (
                half::f16::from_f32(v.x),
                half::f16::from_f32(v.y),
                half::f16::from_f32(v.z),
                half::f16::from_f32(1.0),
            )
        })
        .unwrap();
        let back = EnvMap::read(&p).unwrap();
        for (a, b) in back.data().iter().zip(m.data()) {
            assert!(
                (*a - *b).abs().max_element() <= 2e-3 * b.max_element() + 1e-6,
                "{a} {b}"
            );
        }
        let t = m.to_tensor();
        assert_eq!(EnvMap::from_tensor(&t).unwrap(), m);
        let e = EnvMap::read(&dir.path().join("nope.hdr"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("nope.hdr"), "{e}");
        assert!(EnvMap::read(&dir.path().join("x.jpg")).is_err());
    }
}
