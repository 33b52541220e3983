//! The plane mode of the reprojection: a plane fitted to the picked pixels'
//! predicted normals, and the rectification of the photo onto it.
//!
//! The camera is a pinhole with square pixels and the principal point at the
//! image centre; its focal length comes from the predicted view vectors (a
//! view vector is the unit vector from the surface to the camera, so at pixel
//! centre `(x, y)`, `v ∝ ((c_x − x)/f, (y − c_y)/f, 1)` and `f = (c_x − x)·v_z/v_x`,
//! likewise in y; the median over the picked pixels), or from a given vertical
//! field of view. The plane's normal `N` is the normalised per-component median
//! of the predicted normals. A pixel's ray `d` meets the plane `N·P = −1` at
//! `P = −d/(N·d)` (the scale is unknowable from one image and irrelevant to a
//! texture). With an in-plane basis `e₁` (the camera's x axis projected on the
//! plane, or turned to follow the region's own lines: [`plane_basis`]) and
//! `e₂ = N × e₁`, the plane coordinates `(P·e₁, −P·e₂)` are a
//! homography of the pixel coordinates: the rectified view. The texture
//! square is placed where the picked pixels crowd on the plane, as large as
//! they cover it ([`Framing`]), from the geometric mean of the sides of
//! their robust bounding box (2nd–98th percentiles) down to a quarter of it.

use glam::Vec3;
use picker_render::io::Image;
use rayon::prelude::*;

use crate::reproject::Coords;

/// Focal length used when neither view vectors nor a field of view give one:
/// a 60° vertical field of view.
pub const DEFAULT_FOV_Y_DEG: f32 = 60.0;

fn median(v: &mut [f32]) -> Option<f32> {
    if v.is_empty() {
        return None;
    }
    let mid = v.len() / 2;
    v.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
    Some(v[mid])
}

/// Focal length in pixels of a `w×h` image from its view vectors at the picked (or any) pixels.
pub fn focal_from_view(view: &Image, mask: &[bool]) -> Option<f32> {
    let (w, h) = (view.width, view.height);
    let (cx, cy) = (w as f32 / 2.0, h as f32 / 2.0);
    let mut est = Vec::new();
    for (i, _) in mask.iter().enumerate().filter(|(_, &m)| m) {
        let v = view.rgb(i);
        if v.z.is_nan() || v.z <= 0.05 {
            continue;
        }
        let (x, y) = ((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
        if v.x.abs() > 0.02 && (cx - x).abs() > 0.05 * w as f32 {
            let f = (cx - x) * v.z / v.x;
            if f > 0.0 {
                est.push(f);
            }
        }
        if v.y.abs() > 0.02 && (y - cy).abs() > 0.05 * h as f32 {
            let f = (y - cy) * v.z / v.y;
            if f > 0.0 {
                est.push(f);
            }
        }
    }
    if est.len() < 8 {
        return None;
    }
    median(&mut est)
}

/// Focal length in pixels of an image `h` pixels tall with vertical field of view `fov_y_deg`.
pub fn focal_from_fov(h: usize, fov_y_deg: f32) -> f32 {
    (h as f32 / 2.0) / (fov_y_deg.to_radians() / 2.0).tan()
}

/// Vertical field of view in degrees of an image `h` pixels tall with focal
/// length `focal` pixels (the inverse of [`focal_from_fov`]).
pub fn fov_from_focal(h: usize, focal: f32) -> f32 {
    2.0 * ((h as f32 / 2.0) / focal).atan().to_degrees()
}

/// The plane normal: normalised per-component median of `normals` over `mask`.
pub fn plane_normal(normals: &Image, mask: &[bool]) -> Option<Vec3> {
    let mut comp = [Vec::new(), Vec::new(), Vec::new()];
    for (i, &m) in mask.iter().enumerate() {
        if m {
            let n = normals.rgb(i);
            if n.is_finite() && n.length() > 1e-6 {
                let n = n.normalize();
                for c in 0..3 {
                    comp[c].push(n[c]);
                }
            }
        }
    }
    let [a, b, c] = &mut comp;
    let n = Vec3::new(median(a)?, median(b)?, median(c)?);
    (n.length() > 1e-6).then(|| n.normalize())
}

/// Angular spread (degrees) of the picked normals around `n`: the median angle.
pub fn normal_spread_deg(normals: &Image, mask: &[bool], n: Vec3) -> f32 {
    let mut ang: Vec<f32> = mask
        .iter()
        .enumerate()
        .filter(|(_, &m)| m)
        .filter_map(|(i, _)| {
            let v = normals.rgb(i);
            (v.length() > 1e-6).then(|| v.normalize().dot(n).clamp(-1.0, 1.0).acos().to_degrees())
        })
        .collect();
    median(&mut ang).unwrap_or(180.0)
}

/// The part of a material that lies on one plane with the pixel `anchor`
/// (see [`coplanar_part`]).
#[derive(Clone, Debug, PartialEq)]
pub struct PlanePart {
    /// Pixels of the part (the mask's grid, row-major).
    pub mask: Vec<bool>,
    /// The part's plane normal ([`plane_normal`] over it).
    pub normal: Vec3,
    /// Its [`normal_spread_deg`].
    pub spread_deg: f32,
    /// Its share of the mask's pixels.
    pub share: f64,
}

/// Smallest share of a material's pixels that [`coplanar_part`] accepts as
/// its plane (below it the texture would come from a sliver).
pub const PART_MIN_SHARE: f64 = 0.05;
/// Fewest pixels [`coplanar_part`] accepts.
pub const PART_MIN_PIXELS: usize = 16;

/// The pixels of `mask` (`w × h`) on the plane at `anchor`: a material that
/// is not one plane (a room's walls meeting at corners, a box's faces, a
/// mask that took in a neighbour) is rectified from the plane the user
/// picked, and pixels of another plane do not land at wrong places in its
/// texture. The plane's normal is the [`plane_normal`] of the masked pixels
/// in a window around `anchor` (radius 3% of the larger side, at least 2
/// pixels, doubled until it holds 9 masked pixels); the part is the
/// 8-connected region of masked pixels whose normal is within `max_dev_deg`
/// of it that holds `anchor` (or, when `anchor`'s own normal is off, the
/// region nearest to it). Only the connected region: a table top and the
/// floor are parallel but not one plane (rectified together, their pixels
/// would be two clusters of the texture plane, which [`plane_coords`]
/// frames as one), with the masked pixels of the holes it encloses that
/// are blotches of the normals rather than parallel faces
/// ([`BLOTCH_MAX_ON_PLANE`]); its normal and spread are the region's own. `None` when the normals
/// are unusable, the part is smaller than [`PART_MIN_SHARE`] of the mask or
/// [`PART_MIN_PIXELS`], or its own spread exceeds `max_dev_deg`.
///
/// # Panics
/// If `mask` does not hold `w·h` values or `normals` is not `3 × h × w`.
pub fn coplanar_part(
    normals: &Image,
    mask: &[bool],
    w: usize,
    h: usize,
    anchor: (usize, usize),
    max_dev_deg: f32,
) -> Option<PlanePart> {
    assert_eq!(mask.len(), w * h, "mask size");
    assert!(
        normals.channels == 3 && normals.width == w && normals.height == h,
        "normals size"
    );
    let total = mask.iter().filter(|&&m| m).count();
    if total == 0 {
        return None;
    }
    let (ax, ay) = (anchor.0.min(w - 1), anchor.1.min(h - 1));
    let mut r = ((0.03 * w.max(h) as f64).round() as usize).max(2);
    let reference = loop {
        let mut win = vec![false; w * h];
        let mut n = 0;
        for y in ay.saturating_sub(r)..(ay + r + 1).min(h) {
            for x in ax.saturating_sub(r)..(ax + r + 1).min(w) {
                if mask[y * w + x] {
                    win[y * w + x] = true;
                    n += 1;
                }
            }
        }
        if n >= 9 || n == total || r >= w.max(h) {
            break plane_normal(normals, &win)?;
        }
        r *= 2;
    };
    let cos_max = max_dev_deg.to_radians().cos();
    let on_plane = crate::mask::Mask {
        width: w,
        height: h,
        data: (0..w * h)
            .map(|i| {
                let n = normals.rgb(i);
                mask[i] && n.length() > 1e-6 && n.normalize().dot(reference) >= cos_max
            })
            .collect(),
    };
    let (label, _) = crate::mask::components(&on_plane);
    let at = crate::mask::nearest_label(&label, w, (ax, ay));
    if at == 0 {
        return None;
    }
    let on: Vec<bool> = label.iter().map(|&l| l == at).collect();
    let part = with_enclosed_blotches(&on, &on_plane.data, mask, w, h);
    let count = part.iter().filter(|&&b| b).count();
    let share = count as f64 / total as f64;
    if count < PART_MIN_PIXELS || share < PART_MIN_SHARE {
        return None;
    }
    // The plane and its spread are the region's own (the holes' normals
    // are the ones that disagreed).
    let normal = plane_normal(normals, &on)?;
    let spread_deg = normal_spread_deg(normals, &on, normal);
    (spread_deg <= max_dev_deg).then_some(PlanePart {
        mask: part,
        normal,
        spread_deg,
        share,
    })
}

/// `on` (a region of the plane) with the masked pixels of its holes
/// ([`crate::mask::enclosed`]) where fewer than [`BLOTCH_MAX_ON_PLANE`] of
/// a hole's masked pixels are on the plane (`on_plane`). The networks'
/// normals on a photo are blotchy — a gravel path's or a table's patches
/// tilted 20–60° — and such a blotch inside the region is on its plane; a
/// hole that holds a parallel face of its own (a table top on the floor,
/// ringed by its sides) is another surface and stays out.
fn with_enclosed_blotches(
    on: &[bool],
    on_plane: &[bool],
    mask: &[bool],
    w: usize,
    h: usize,
) -> Vec<bool> {
    let holes = crate::mask::Mask {
        width: w,
        height: h,
        data: crate::mask::enclosed(on, w, h),
    };
    let (label, sizes) = crate::mask::components4(&holes);
    let (mut masked, mut level) = (vec![0usize; sizes.len()], vec![0usize; sizes.len()]);
    for i in (0..w * h).filter(|&i| label[i] != 0 && mask[i]) {
        masked[label[i] as usize] += 1;
        level[label[i] as usize] += usize::from(on_plane[i]);
    }
    let blotch: Vec<bool> = masked
        .iter()
        .zip(&level)
        .map(|(&m, &l)| (l as f64) < BLOTCH_MAX_ON_PLANE * m as f64)
        .collect();
    (0..w * h)
        .map(|i| on[i] || (mask[i] && label[i] != 0 && blotch[label[i] as usize]))
        .collect()
}

/// A hole of a plane's region whose masked pixels are at least this share
/// on the plane (a parallel face of another surface) is not taken into it
/// ([`coplanar_part`]).
pub const BLOTCH_MAX_ON_PLANE: f64 = 0.25;

/// Whether the plane of normal `n` shows its front at pixel `(x, y)` of a
/// `w × h` image for every focal length of a plausible room photo
/// ([`crate::lines::FOCAL_FOV_RANGE`]): [`plane_coords`] gives a pixel whose ray meets
/// the plane's back no coordinates, so a plane that faces away at the pick
/// (a noisy predicted normal) would rectify nothing.
pub fn faces_camera(n: Vec3, (x, y): (usize, usize), w: usize, h: usize) -> bool {
    let (lo, hi) = crate::lines::FOCAL_FOV_RANGE;
    [lo, hi].iter().all(|&fov| {
        let f = focal_from_fov(h, fov);
        let d = Vec3::new(
            (x as f32 + 0.5 - w as f32 / 2.0) / f,
            -(y as f32 + 0.5 - h as f32 / 2.0) / f,
            -1.0,
        );
        n.dot(d) < -1e-4
    })
}

/// How a photo's pixels become rays: the focal length (photo pixels) and
/// the lens distortion ([`crate::lens`]; `lambda = 0`: a pinhole). A bare
/// focal length converts into a pinhole camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    focal: f32,
    lambda: f32,
}

impl From<f32> for Camera {
    fn from(focal: f32) -> Self {
        Self { focal, lambda: 0.0 }
    }
}

impl Camera {
    /// A camera of focal length `focal` (photo pixels) and lens distortion
    /// `lambda` ([`crate::lens::Lens`]).
    ///
    /// # Panics
    /// When `lambda` is outside [`crate::lens::LAMBDA_MIN`]..=[`crate::lens::LAMBDA_MAX`]
    /// (a lens that folds the photo's corners over).
    pub fn new(focal: f32, lambda: f32) -> Self {
        let (lo, hi) = (crate::lens::LAMBDA_MIN, crate::lens::LAMBDA_MAX);
        assert!(
            (lo..=hi).contains(&lambda),
            "lens λ {lambda} outside {lo}..={hi}"
        );
        Self { focal, lambda }
    }

    /// Focal length, photo pixels.
    pub fn focal(&self) -> f32 {
        self.focal
    }

    /// The division model's coefficient.
    pub fn lambda(&self) -> f32 {
        self.lambda
    }

    /// The camera-space ray (not normalised, `z = −1`) through the point
    /// `(x, y)` (pixels, y down) of a `w × h` photo: its undistorted
    /// position relative to the centre over the focal length.
    #[inline]
    pub fn ray(&self, x: f32, y: f32, w: usize, h: usize) -> Vec3 {
        let (cx, cy) = (w as f32 / 2.0, h as f32 / 2.0);
        let d = crate::lens::divide(
            glam::Vec2::new(x - cx, y - cy),
            self.lambda,
            crate::lens::half_diagonal_sq(w, h),
        );
        Vec3::new(d.x / self.focal, -d.y / self.focal, -1.0)
    }
}

/// A direction `along` turns the texture axes only when it is within this
/// many degrees of the plane (the plane's own lines are; a direction far
/// out of it says nothing about the plane's axes).
pub const MAX_AXIS_TILT_DEG: f32 = 10.0;

/// The in-plane axes for normal `n`: `e1` is the photo's x axis projected
/// onto the plane (its y axis when x is nearly along `n`), `e2 = n × e1`.
///
/// With `along`, a direction in the plane that its texture's lines follow
/// (a floor's planks, a wall's brick courses: [`crate::lines`]), the axes
/// are turned by the smallest angle that puts `e1` or `e2` along it, so the
/// pattern comes out parallel to the texture's edges instead of at the
/// angle it happens to make with the camera. Ignored when it is more than
/// [`MAX_AXIS_TILT_DEG`] out of the plane or not finite.
pub fn plane_basis(n: Vec3, along: Option<Vec3>) -> (Vec3, Vec3) {
    let x = Vec3::X - Vec3::X.dot(n) * n;
    let e1 = if x.length() > 1e-3 {
        x.normalize()
    } else {
        (Vec3::Y - Vec3::Y.dot(n) * n).normalize()
    };
    let max_out = MAX_AXIS_TILT_DEG.to_radians().sin();
    let turned = along
        .map(Vec3::normalize_or_zero)
        .filter(|d| d.is_finite() && d.length() > 0.5 && d.dot(n).abs() <= max_out)
        .map(|d| {
            let a = (d - d.dot(n) * n).normalize();
            let b = n.cross(a);
            // Of ±a and ±b, the one closest to the untouched e1 (ties keep
            // the first).
            [a, b, -a, -b]
                .into_iter()
                .fold((a, f32::NEG_INFINITY), |best, c| {
                    let dot = c.dot(e1);
                    if dot > best.1 {
                        (c, dot)
                    } else {
                        best
                    }
                })
                .0
        });
    let e1 = turned.unwrap_or(e1);
    (e1, n.cross(e1))
}

/// How the texture square is placed on the rectified plane
/// ([`plane_coords_with_side`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Framing {
    /// The square of the picked pixels' 2–98% box's geometric-mean side, where
    /// it holds the most of them: the most of the surface, to look for a
    /// repeating pattern's periods in.
    Whole,
    /// The largest square, from that side down to a quarter of it (while it
    /// holds [`FRAME_MIN_PIXELS`]), that the picked pixels cover
    /// ([`FRAME_COVER`]), where it holds the most of them: the texture the
    /// photo shows best, with the least left to the inpainter.
    Covered,
}

/// The texture square framed on the rectified plane
/// ([`plane_coords_with_side`]).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Square {
    /// Its side in plane units (the plane through `N·P = −1`, camera space:
    /// units of the plane's distance from the camera).
    #[serde(skip)]
    pub side: f32,
    /// Its corner `(s, t)` in plane units (the texture's axes).
    #[serde(skip)]
    pub origin: [f32; 2],
    /// Its side as a share of the geometric mean of the sides of the picked
    /// pixels' 2–98% box (1, or `2^(−k/2)` for a smaller square the pixels
    /// cover better: [`Framing::Covered`]).
    pub side_share: f32,
    /// The share of its [`FRAME_CELLS`]² cells holding a picked pixel;
    /// `None` when it was centred on the box (no grid fits the region).
    pub cells_observed: Option<f64>,
}

/// The rectified plane coordinates of the picked pixels of a `w×h` photo
/// (camera `cam`: a focal length in photo pixels, or a [`Camera`] with a
/// lens), mapped into the texture square ([`Framing::Covered`]); pixels
/// whose ray misses the plane's front get `NaN`. The texture's axes follow
/// `along` when given ([`plane_basis`]). The square's size and position:
/// see [`Framing`] and `frame_with`; when no size can be searched (a region
/// thousands of times longer than wide), the box's geometric-mean side
/// centred on the box, or on the median pixel when that would hold none of
/// them (separate clusters, the box's centre empty).
pub fn plane_coords(
    w: usize,
    h: usize,
    mask: &[bool],
    n: Vec3,
    cam: impl Into<Camera>,
    along: Option<Vec3>,
) -> Coords {
    plane_coords_with(w, h, mask, None, n, cam, along)
}

/// [`plane_coords`] that also gives coordinates to the pixels of `extra`
/// (when given) in the same square: the square is framed by `mask`'s pixels
/// alone, so `mask`'s coordinates are [`plane_coords`]' whatever `extra`
/// holds. The pipeline reprojects the rest of a material's mask through
/// them to fill the texels its surest part did not show.
///
/// # Panics
/// If `mask` or `extra` does not hold `w·h` values.
pub fn plane_coords_with(
    w: usize,
    h: usize,
    mask: &[bool],
    extra: Option<&[bool]>,
    n: Vec3,
    cam: impl Into<Camera>,
    along: Option<Vec3>,
) -> Coords {
    plane_coords_with_side(w, h, mask, extra, n, cam, along, Framing::Covered).0
}

/// The plane coordinates `(s, t)` (plane units, the texture's axes
/// [`plane_basis`]) of the `wanted` pixels of a `w×h` photo (camera
/// `cam`); `NaN` elsewhere and where a pixel's ray misses the
/// plane's front. Rows in parallel; every pixel is computed alone (the same
/// bits for any thread count).
fn rectified(
    w: usize,
    h: usize,
    wanted: impl Fn(usize) -> bool + Sync,
    n: Vec3,
    cam: impl Into<Camera>,
    along: Option<Vec3>,
) -> (Vec<f32>, Vec<f32>) {
    let (e1, e2) = plane_basis(n, along);
    let cam = cam.into();
    let len = w * h;
    // Rows in parallel, each writing every one of its values: at 12 MP,
    // filling two NaN vectors first took ~40 ms on one thread (the first
    // touch of their pages), now spread over the threads.
    let mut s: Vec<f32> = Vec::with_capacity(len);
    let mut t: Vec<f32> = Vec::with_capacity(len);
    let step = w.max(1);
    s.spare_capacity_mut()[..len]
        .par_chunks_mut(step)
        .zip(t.spare_capacity_mut()[..len].par_chunks_mut(step))
        .enumerate()
        .for_each(|(row, (rs, rt))| {
            for (col, (a, b)) in rs.iter_mut().zip(rt.iter_mut()).enumerate() {
                let mut at = (f32::NAN, f32::NAN);
                if wanted(row * w + col) {
                    let d = cam.ray(col as f32 + 0.5, row as f32 + 0.5, w, h);
                    let nd = n.dot(d);
                    if nd < -1e-4 {
                        let p = -d / nd;
                        at = (p.dot(e1), -p.dot(e2));
                    }
                }
                a.write(at.0);
                b.write(at.1);
            }
        });
    // SAFETY: the first `len` slots of both vectors were split into rows of
    // `step` (the last possibly shorter), and every slot of every row was
    // written above; `f32` needs no drop.
    unsafe {
        s.set_len(len);
        t.set_len(len);
    }
    (s, t)
}

/// The coordinates of the picked pixels of a `w×h` photo in the square of
/// side `side` (plane units) whose corner is `origin` (`(s, t)`, plane
/// units) on the plane `n` (camera `cam`, axes following `along`, as
/// [`plane_coords_with_side`]): `u, v ∈ [0, 1)` inside it, `NaN` elsewhere.
/// With a [`Square`]'s own `origin` and `side` they are
/// [`plane_coords_with_side`]'s, bit for bit; the pipeline passes a larger
/// square around it, whose texels past the square's sides let its wrap
/// edges be cut where its two sides look alike
/// ([`picker_inpaint::wrap_cut`]).
///
/// # Panics
/// If `mask` does not hold `w·h` values.
#[allow(clippy::too_many_arguments)]
pub fn plane_coords_in(
    w: usize,
    h: usize,
    mask: &[bool],
    n: Vec3,
    cam: impl Into<Camera>,
    along: Option<Vec3>,
    origin: [f32; 2],
    side: f32,
) -> Coords {
    assert_eq!(mask.len(), w * h, "mask size");
    let (mut s, mut t) = rectified(w, h, |i| mask[i], n, cam, along);
    into_square(&mut s, &mut t, w, origin, side);
    Coords {
        width: w,
        height: h,
        u: s,
        v: t,
        wrap: false,
    }
}

/// Plane coordinates `(s, t)` (rows of `w`, in parallel) replaced in place
/// by their coordinates in the square of side `side` at corner `origin`:
/// `NaN` for both where either falls outside it.
fn into_square(s: &mut [f32], t: &mut [f32], w: usize, origin: [f32; 2], side: f32) {
    let [sc, tc] = origin;
    s.par_chunks_mut(w.max(1))
        .zip(t.par_chunks_mut(w.max(1)))
        .for_each(|(rs, rt)| {
            for (ps, pt) in rs.iter_mut().zip(rt.iter_mut()) {
                let (u, v) = (square_coord(*ps, sc, side), square_coord(*pt, tc, side));
                (*ps, *pt) = if u.is_finite() && v.is_finite() {
                    (u, v)
                } else {
                    (f32::NAN, f32::NAN)
                };
            }
        });
}

/// A plane coordinate `p` in the square starting at `corner` with side
/// `side`: `(p − corner) / side` when in `[0, 1)`, else `NaN`.
fn square_coord(p: f32, corner: f32, side: f32) -> f32 {
    let u = (p - corner) / side;
    if p.is_finite() && (0.0..1.0).contains(&u) {
        u
    } else {
        f32::NAN
    }
}

/// [`plane_coords_with`] with the square placed as `framing` says, and the
/// square ([`Square`]: its side in plane units, and how it was framed);
/// `None` when no picked pixel sees the plane's front (every coordinate is
/// then NaN).
///
/// # Panics
/// If `mask` or `extra` does not hold `w·h` values.
#[allow(clippy::too_many_arguments)]
pub fn plane_coords_with_side(
    w: usize,
    h: usize,
    mask: &[bool],
    extra: Option<&[bool]>,
    n: Vec3,
    cam: impl Into<Camera>,
    along: Option<Vec3>,
    framing: Framing,
) -> (Coords, Option<Square>) {
    assert_eq!(mask.len(), w * h, "mask size");
    assert!(extra.is_none_or(|e| e.len() == w * h), "extra size");
    let wanted = |i: usize| mask[i] || extra.is_some_and(|e| e[i]);
    let (mut s, mut t) = rectified(w, h, wanted, n, cam, along);
    let step = w.max(1);
    // Both percentiles of the finite values, found in parallel without
    // collecting them (`select::kth_smallest`: the values a selection over
    // the collected finite values gives), both coordinates side by side.
    let pct2 = |v: &[f32], q0: f32, q1: f32| -> Option<(f32, f32)> {
        let at = crate::select::kth_smallest(
            v.len(),
            |i| (mask[i] && v[i].is_finite()).then(|| v[i]),
            |len| {
                let k = |q: f32| ((len - 1) as f32 * q) as usize;
                Some(vec![k(q0), k(q1)])
            },
        )?;
        Some((at[0], at[1]))
    };
    let (Some((s0, s1)), Some((t0, t1))) =
        rayon::join(|| pct2(&s, 0.02, 0.98), || pct2(&t, 0.02, 0.98))
    else {
        let none = Coords {
            width: w,
            height: h,
            u: vec![f32::NAN; w * h],
            v: vec![f32::NAN; w * h],
            wrap: false,
        };
        return (none, None);
    };
    let side0 = ((s1 - s0).max(1e-9) * (t1 - t0).max(1e-9)).sqrt();
    let (side, sc, tc, cells) =
        match frame_square(&s, &t, mask, w, [s0, s1, t0, t1], side0, framing) {
            Some((side, sc, tc, cover)) => (side, sc, tc, Some(cover)),
            None => {
                let side = side0;
                let (mut sc, mut tc) = box_centred([s0, s1, t0, t1], side);
                // Separate clusters (two parallel surfaces taken as one) can leave the
                // box's centre empty: then the square is centred on the median pixel.
                let inside = |v: f32, c: f32| (0.0..1.0).contains(&((v - c) / side));
                let framed: usize = s
                    .par_chunks(step)
                    .zip(t.par_chunks(step))
                    .zip(mask.par_chunks(step))
                    .map(|((rs, rt), rm)| {
                        rs.iter()
                            .zip(rt)
                            .zip(rm)
                            .filter(|&((&a, &b), &m)| {
                                m && a.is_finite() && inside(a, sc) && inside(b, tc)
                            })
                            .count()
                    })
                    .sum();
                if framed == 0 {
                    if let (Some((sm, _)), Some((tm, _))) =
                        rayon::join(|| pct2(&s, 0.5, 0.5), || pct2(&t, 0.5, 0.5))
                    {
                        (sc, tc) = (sm - side / 2.0, tm - side / 2.0);
                    }
                }
                (side, sc, tc, None)
            }
        };
    // The plane coordinates become the texture coordinates in place (NaN
    // where a pixel has none or falls outside the square).
    into_square(&mut s, &mut t, step, [sc, tc], side);

    let coords = Coords {
        width: w,
        height: h,
        u: s,
        v: t,
        wrap: false,
    };
    let square = Square {
        side,
        origin: [sc, tc],
        side_share: side / side0,
        cells_observed: cells,
    };
    (coords, Some(square))
}

/// Cells of the framing grid along each side of the texture square
/// ([`plane_coords`]): the square's position is searched in steps of
/// `1/FRAME_CELLS` of its side, and its coverage measured in these cells.
pub const FRAME_CELLS: usize = 16;

/// Share of the framing cells of the texture square that must hold a picked
/// pixel for a square size to be taken ([`plane_coords`]).
pub const FRAME_COVER: f64 = 0.85;

/// Square sizes tried, largest first: the box's geometric-mean side times
/// `2^(−k/2)` for `k` in `0..FRAME_LEVELS` (down to a quarter).
pub const FRAME_LEVELS: usize = 5;

/// Fewest picked pixels a square smaller than the box's geometric-mean side
/// must hold to be taken: a texture is at least 16 texels a side
/// ([`crate::reproject::texture_size`]), and a square holding fewer than
/// 16 × 16 pixels would be mostly interpolated. (A floor of 64 × 64, so that
/// a small photo keeps a larger if mostly inpainted texture — `coffee.jpg` at
/// 320 × 213 gives 36 texels where the whole square gave 68, half of them
/// observed — lost 0.17–0.24 dB of mean aligned PSNR on the synthetic sets in
/// the plane mode, whose 320 × 240 images then kept squares 40–60 % observed.)
pub const FRAME_MIN_PIXELS: u64 = 16 * 16;

/// Most cells of the framing grid along either axis: a square size whose
/// grid would need more (a region far more elongated than the square) is not
/// tried.
const FRAME_MAX_CELLS: usize = 1024;

/// The grid over which a texture square's position is searched: cells of
/// `side / FRAME_CELLS`, covering every square of that side that overlaps
/// the picked pixels' 2–98% box, aligned so that the square centred on the
/// box starts on a cell corner (`centre`).
#[derive(Clone, Copy, Debug)]
struct FrameGrid {
    origin: [f64; 2],
    cell: f64,
    n: [usize; 2],
    centre: [usize; 2],
}

/// The best position of a square on a [`FrameGrid`].
#[derive(Clone, Copy, Debug)]
struct Placement {
    /// Its corner `(sc, tc)` in plane units.
    corner: (f32, f32),
    /// Picked pixels inside.
    count: u64,
    /// Share of its cells holding at least one.
    cover: f64,
}

impl FrameGrid {
    /// The grid for the box `[s0, s1, t0, t1]` and square side `side`;
    /// `None` when it would need more than [`FRAME_MAX_CELLS`] cells along an
    /// axis (or the side is not a positive finite number).
    fn new(bx: [f32; 4], side: f64) -> Option<Self> {
        let g = FRAME_CELLS as f64;
        let cell = side / g;
        if !(cell.is_finite() && cell > 0.0) {
            return None;
        }
        let axis = |lo: f32, hi: f32| -> Option<(f64, usize, usize)> {
            let (lo, hi) = (f64::from(lo), f64::from(hi));
            let centred = (lo + hi) / 2.0 - side / 2.0;
            let before = ((centred - (lo - side)) / cell).ceil().max(0.0);
            let after = ((hi + side - centred) / cell).ceil().max(g);
            (before + after <= FRAME_MAX_CELLS as f64).then_some((
                centred - before * cell,
                (before + after) as usize,
                before as usize,
            ))
        };
        let (os, ns, cs) = axis(bx[0], bx[1])?;
        let (ot, nt, ct) = axis(bx[2], bx[3])?;
        Some(FrameGrid {
            origin: [os, ot],
            cell,
            n: [ns, nt],
            centre: [cs, ct],
        })
    }

    /// The cell index of a point `(a, b)`, `None` off the grid.
    #[inline]
    fn cell_of(&self, a: f32, b: f32) -> Option<usize> {
        let ix = ((f64::from(a) - self.origin[0]) / self.cell).floor();
        let iy = ((f64::from(b) - self.origin[1]) / self.cell).floor();
        ((0.0..self.n[0] as f64).contains(&ix) && (0.0..self.n[1] as f64).contains(&iy))
            .then(|| iy as usize * self.n[0] + ix as usize)
    }

    /// The square position holding the most counted pixels (`hist`: counts
    /// per cell): among equals the centred one (whose exact corner is
    /// `centred`), else the nearest to it, else the first in row order.
    fn choose(&self, hist: &[u32], centred: (f32, f32)) -> Placement {
        let [nx, ny] = self.n;
        let g = FRAME_CELLS;
        // Summed-area tables of the counts and of the cells holding any,
        // (nx + 1) × (ny + 1).
        let mut sat = vec![0u64; (nx + 1) * (ny + 1)];
        let mut hit = vec![0u64; (nx + 1) * (ny + 1)];
        for y in 0..ny {
            let (mut run, mut run_hit) = (0u64, 0u64);
            for x in 0..nx {
                let c = hist[y * nx + x];
                run += u64::from(c);
                run_hit += u64::from(c > 0);
                let (k, above) = ((y + 1) * (nx + 1) + x + 1, y * (nx + 1) + x + 1);
                sat[k] = sat[above] + run;
                hit[k] = hit[above] + run_hit;
            }
        }
        let window = |t: &[u64], x: usize, y: usize| {
            let at = |x: usize, y: usize| t[y * (nx + 1) + x];
            at(x + g, y + g) + at(x, y) - at(x + g, y) - at(x, y + g)
        };
        let mut best = (0u64, u64::MAX, self.centre[0], self.centre[1]);
        for oy in 0..=ny - g {
            for ox in 0..=nx - g {
                let count = window(&sat, ox, oy);
                let (dx, dy) = (ox.abs_diff(self.centre[0]), oy.abs_diff(self.centre[1]));
                let d = (dx * dx + dy * dy) as u64;
                if count > best.0 || (count == best.0 && d < best.1) {
                    best = (count, d, ox, oy);
                }
            }
        }
        let (count, _, ox, oy) = best;
        let corner = if [ox, oy] == self.centre {
            centred
        } else {
            (
                (self.origin[0] + ox as f64 * self.cell) as f32,
                (self.origin[1] + oy as f64 * self.cell) as f32,
            )
        };
        Placement {
            corner,
            count,
            cover: window(&hit, ox, oy) as f64 / (g * g) as f64,
        }
    }
}

/// The corner of the square of side `side` centred on the box `[s0, s1, t0, t1]`.
fn box_centred(bx: [f32; 4], side: f32) -> (f32, f32) {
    (
        (bx[0] + bx[1]) / 2.0 - side / 2.0,
        (bx[2] + bx[3]) / 2.0 - side / 2.0,
    )
}

/// The texture square among the picked pixels' plane coordinates: its side
/// and corner `(side, sc, tc)`, given the 2–98% box `bx` of the picked
/// pixels' coordinates and `hist`, which counts them into a grid's cells.
///
/// At each size tried the position (in steps of a [`FRAME_CELLS`]th of the
/// side) holding the most picked pixels is found. [`Framing::Whole`] tries
/// the box's geometric-mean side `side0` only; [`Framing::Covered`] tries
/// `side0` down to a quarter of it ([`FRAME_LEVELS`]), largest first, while
/// the square holds at least [`FRAME_MIN_PIXELS`] picked pixels, and takes
/// the first whose square has at least [`FRAME_COVER`] of its cells observed
/// (none: the best covered of those tried, the larger among equals). `None` (the
/// caller centres a `side0` square on the box) when no size's grid fits
/// [`FRAME_MAX_CELLS`] or no pixel is counted.
///
/// The photo sees a surface most finely, and most completely, where its
/// pixels crowd in the plane: a floor or a street receding from the camera
/// has most of its pixels near the camera and a long, thin, blurred far part
/// that stretches its box, and most picked regions are not rectangles.
/// Centred on the box with the box's geometric-mean side, the square held
/// mostly a cobbled street's smeared distance, and the median pick of 26
/// real photos (5 × 4 picks each) saw 47 % of its texture (a quarter of them
/// under 31 %), the rest invented by the inpainter; covered, 85 % (under
/// 72 %). On a square region seen evenly (a wall head-on) every position
/// inside holds as many pixels, and the box-centred square is kept. The
/// counts are integers, so the choice does not depend on how they were
/// gathered (the thread count).
fn frame_with(
    bx: [f32; 4],
    side0: f32,
    framing: Framing,
    hist: impl Fn(&FrameGrid) -> Vec<u32>,
) -> Option<(f32, f32, f32, f64)> {
    let mut fallback: Option<(f32, Placement)> = None;
    let levels = match framing {
        Framing::Whole => 1,
        Framing::Covered => FRAME_LEVELS,
    };
    for k in 0..levels {
        let side = if k == 0 {
            side0
        } else {
            (f64::from(side0) * 0.5f64.powf(k as f64 / 2.0)) as f32
        };
        let Some(grid) = FrameGrid::new(bx, f64::from(side)) else {
            continue;
        };
        let f = grid.choose(&hist(&grid), box_centred(bx, side));
        if f.count == 0 {
            continue;
        }
        // Smaller squares hold no more pixels: too few already, stop.
        if k > 0 && f.count < FRAME_MIN_PIXELS {
            break;
        }
        if f.cover >= FRAME_COVER || framing == Framing::Whole {
            return Some((side, f.corner.0, f.corner.1, f.cover));
        }
        if fallback.is_none_or(|(_, b)| f.cover > b.cover) {
            fallback = Some((side, f));
        }
    }
    fallback.map(|(side, f)| (side, f.corner.0, f.corner.1, f.cover))
}

/// [`frame_with`] over the `mask`ed pixels with finite `s` of a `w`-wide
/// image, their counts gathered in parallel.
fn frame_square(
    s: &[f32],
    t: &[f32],
    mask: &[bool],
    w: usize,
    bx: [f32; 4],
    side: f32,
    framing: Framing,
) -> Option<(f32, f32, f32, f64)> {
    let rows = mask.len() / w.max(1);
    let jobs = (rayon::current_num_threads() * 2).clamp(1, rows.max(1));
    let per = rows.div_ceil(jobs).max(1);
    frame_with(bx, side, framing, |grid| {
        let cells = grid.n[0] * grid.n[1];
        (0..jobs)
            .into_par_iter()
            .map(|j| {
                let mut h = vec![0u32; cells];
                let end = ((j + 1) * per * w).min(mask.len());
                for i in (j * per * w).min(end)..end {
                    if mask[i] && s[i].is_finite() {
                        if let Some(c) = grid.cell_of(s[i], t[i]) {
                            h[c] += 1;
                        }
                    }
                }
                h
            })
            .reduce(
                || vec![0u32; cells],
                |mut a, b| {
                    a.iter_mut().zip(&b).for_each(|(x, y)| *x += y);
                    a
                },
            )
    })
}

/// The plain, sequential implementation of [`frame_square`].
fn frame_square_reference(
    s: &[f32],
    t: &[f32],
    mask: &[bool],
    bx: [f32; 4],
    side: f32,
    framing: Framing,
) -> Option<(f32, f32, f32, f64)> {
    frame_with(bx, side, framing, |grid| {
        let mut hist = vec![0u32; grid.n[0] * grid.n[1]];
        for i in 0..mask.len() {
            if mask[i] && s[i].is_finite() {
                if let Some(c) = grid.cell_of(s[i], t[i]) {
                    hist[c] += 1;
                }
            }
        }
        hist
    })
}

/// The plain, sequential implementation of [`plane_coords_with_side`]'s
/// coordinates (the reference its parallel version is tested against).
#[allow(clippy::too_many_arguments)]
pub fn plane_coords_reference(
    w: usize,
    h: usize,
    mask: &[bool],
    extra: Option<&[bool]>,
    n: Vec3,
    cam: impl Into<Camera>,
    along: Option<Vec3>,
    framing: Framing,
) -> Coords {
    let (e1, e2) = plane_basis(n, along);
    let cam = cam.into();
    let mut s = vec![f32::NAN; w * h];
    let mut t = vec![f32::NAN; w * h];
    for i in 0..w * h {
        if !mask[i] && !extra.is_some_and(|e| e[i]) {
            continue;
        }
        let d = cam.ray((i % w) as f32 + 0.5, (i / w) as f32 + 0.5, w, h);
        let nd = n.dot(d);
        if nd >= -1e-4 {
            continue;
        }
        let p = -d / nd;
        s[i] = p.dot(e1);
        t[i] = -p.dot(e2);
    }
    let pct = |v: &[f32], q: f32| -> Option<f32> {
        let mut f: Vec<f32> = (0..w * h)
            .filter(|&i| mask[i] && v[i].is_finite())
            .map(|i| v[i])
            .collect();
        if f.is_empty() {
            return None;
        }
        let k = ((f.len() - 1) as f32 * q) as usize;
        f.select_nth_unstable_by(k, |a, b| a.total_cmp(b));
        Some(f[k])
    };
    let mut coords = Coords {
        width: w,
        height: h,
        u: vec![f32::NAN; w * h],
        v: vec![f32::NAN; w * h],
        wrap: false,
    };
    let (Some(s0), Some(s1), Some(t0), Some(t1)) =
        (pct(&s, 0.02), pct(&s, 0.98), pct(&t, 0.02), pct(&t, 0.98))
    else {
        return coords;
    };
    let side = ((s1 - s0).max(1e-9) * (t1 - t0).max(1e-9)).sqrt();
    let (side, sc, tc) = match frame_square_reference(&s, &t, mask, [s0, s1, t0, t1], side, framing)
    {
        Some((side, sc, tc, _)) => (side, sc, tc),
        None => {
            let (mut sc, mut tc) = box_centred([s0, s1, t0, t1], side);
            let inside = |v: f32, c: f32| (0.0..1.0).contains(&((v - c) / side));
            let framed = (0..w * h)
                .filter(|&i| mask[i] && s[i].is_finite() && inside(s[i], sc) && inside(t[i], tc))
                .count();
            if framed == 0 {
                if let (Some(sm), Some(tm)) = (pct(&s, 0.5), pct(&t, 0.5)) {
                    (sc, tc) = (sm - side / 2.0, tm - side / 2.0);
                }
            }
            (side, sc, tc)
        }
    };
    for i in 0..w * h {
        if s[i].is_finite() {
            let (u, v) = ((s[i] - sc) / side, (t[i] - tc) / side);
            if (0.0..1.0).contains(&u) && (0.0..1.0).contains(&v) {
                coords.u[i] = u;
                coords.v[i] = v;
            }
        }
    }
    coords
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parallel_plane_coords_match_reference() {
        let mut rng = picker_tensor::Rng::new(9);
        for &(w, h) in &[(1, 1), (1, 7), (9, 1), (2, 2), (31, 17), (130, 97)] {
            for k in 0..6 {
                let density = [0.0, 0.02, 0.5, 0.9, 1.0, 0.3][k];
                let mask: Vec<bool> = (0..w * h).map(|_| rng.f64() < density).collect();
                let n = Vec3::new(
                    rng.uniform(-1.0, 1.0),
                    rng.uniform(-1.0, 1.0),
                    rng.uniform(-0.2, 1.0),
                );
                let n = if k == 5 { Vec3::X } else { n.normalize() };
                // A pinhole, or a lens (barrel or pincushion).
                let focal = Camera::new(
                    rng.uniform(5.0, 200.0),
                    if k % 3 == 0 {
                        0.0
                    } else {
                        rng.uniform(-0.5, 0.3)
                    },
                );
                let along = (k % 2 == 1).then(|| {
                    let d = Vec3::new(rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0), 0.3);
                    d - d.dot(n) * n
                });
                let a = plane_coords(w, h, &mask, n, focal, along);
                let b =
                    plane_coords_reference(w, h, &mask, None, n, focal, along, Framing::Covered);
                let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                for framing in [Framing::Whole, Framing::Covered] {
                    // The side is the square's (positive) when any pixel has
                    // coordinates.
                    let (fa, side) =
                        plane_coords_with_side(w, h, &mask, None, n, focal, along, framing);
                    match side {
                        None => assert!(fa.u.iter().all(|u| u.is_nan()), "{w}x{h} k{k}"),
                        Some(sq) => {
                            assert!(sq.side > 0.0 && sq.side.is_finite(), "{w}x{h} k{k}");
                            assert!(sq.side_share > 0.0 && sq.side_share <= 1.0, "{sq:?}");
                            if framing == Framing::Whole {
                                assert_eq!(sq.side_share, 1.0, "{sq:?}");
                            }
                        }
                    }
                    let fb = plane_coords_reference(w, h, &mask, None, n, focal, along, framing);
                    assert_eq!(bits(&fa.u), bits(&fb.u), "{w}x{h} k{k} {framing:?}");
                    assert_eq!(bits(&fa.v), bits(&fb.v), "{w}x{h} k{k} {framing:?}");
                }
                assert_eq!(bits(&a.u), bits(&b.u), "{w}x{h} k{k}");
                assert_eq!(bits(&a.v), bits(&b.v), "{w}x{h} k{k}");
                // Extra pixels (some also in the mask) get coordinates in
                // the same square; the mask's own are unchanged.
                let extra: Vec<bool> = (0..w * h).map(|_| rng.f64() < 0.4).collect();
                let c = plane_coords_with(w, h, &mask, Some(&extra), n, focal, along);
                let d = plane_coords_reference(
                    w,
                    h,
                    &mask,
                    Some(&extra),
                    n,
                    focal,
                    along,
                    Framing::Covered,
                );
                assert_eq!(bits(&c.u), bits(&d.u), "{w}x{h} k{k} extra");
                assert_eq!(bits(&c.v), bits(&d.v), "{w}x{h} k{k} extra");
                for i in 0..w * h {
                    if mask[i] {
                        assert_eq!(c.u[i].to_bits(), a.u[i].to_bits(), "{w}x{h} k{k} @{i}");
                        assert_eq!(c.v[i].to_bits(), a.v[i].to_bits(), "{w}x{h} k{k} @{i}");
                    } else if !extra[i] {
                        assert!(c.u[i].is_nan() && c.v[i].is_nan(), "{w}x{h} k{k} @{i}");
                    }
                }
            }
        }
    }

    /// Extra pixels on the plane beyond the mask continue its coordinates:
    /// a frontal plane's `u` grows by the same step per pixel across them
    /// (those that still fall inside the square).
    #[test]
    fn extra_pixels_continue_the_masks_coordinates() {
        let (w, h) = (40, 20);
        let mask: Vec<bool> = (0..w * h).map(|i| (i % w) < 20).collect();
        let extra: Vec<bool> = (0..w * h).map(|i| (i % w) >= 20).collect();
        let c = plane_coords_with(w, h, &mask, Some(&extra), Vec3::Z, 50.0, None);
        let row = 10 * w;
        let du = c.u[row + 1] - c.u[row];
        assert!(du > 0.0);
        let mut seen = 0;
        for x in 20..w {
            let u = c.u[row + x];
            if u.is_finite() {
                assert!((u - c.u[row] - du * x as f32).abs() < 1e-4, "x {x}: {u}");
                seen += 1;
            }
        }
        // The mask frames a 20×20 square: extra pixels beyond it have none.
        assert!(seen < 20 && c.u[row + w - 1].is_nan(), "{seen}");
    }

    #[test]
    fn fov_and_focal_are_inverse() {
        for (h, fov) in [(240usize, 60.0f32), (3000, 72.64), (1, 25.0), (480, 110.0)] {
            let f = focal_from_fov(h, fov);
            assert!((fov_from_focal(h, f) - fov).abs() < 1e-3, "{h} {fov}");
        }
        // 320×240 at 72.64°: the README example's 163.2 px.
        assert!((focal_from_fov(240, 72.64) - 163.2).abs() < 0.1);
    }

    #[test]
    fn focal_is_recovered_from_exact_view_vectors() {
        let (w, h, f) = (64, 48, 55.0f32);
        let mut view = Image::zeros(3, h, w);
        for i in 0..w * h {
            let (x, y) = ((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
            let v = Vec3::new((32.0 - x) / f, (y - 24.0) / f, 1.0).normalize();
            view.set_rgb(i, v);
        }
        let est = focal_from_view(&view, &vec![true; w * h]).unwrap();
        assert!((est - f).abs() < 0.01, "{est}");
        assert!((focal_from_fov(48, 90.0) - 24.0).abs() < 1e-4);
    }

    #[test]
    fn a_frontal_plane_is_an_affine_grid() {
        // Normal towards the camera: plane coordinates are proportional to pixels.
        let (w, h) = (40, 30);
        let c = plane_coords(w, h, &vec![true; w * h], Vec3::Z, 50.0, None);
        let mid = (h / 2) * w + w / 2;
        let du = c.u[mid + 1] - c.u[mid];
        assert!(du > 0.0);
        for y in 2..h - 2 {
            for x in 2..w - 3 {
                let i = y * w + x;
                if c.u[i].is_finite() && c.u[i + 1].is_finite() {
                    assert!(((c.u[i + 1] - c.u[i]) - du).abs() < 1e-5);
                }
            }
        }
        // rows go down in v
        assert!(c.v[(h / 2 + 1) * w + w / 2] > c.v[(h / 2) * w + w / 2]);
    }

    #[test]
    fn texture_axes_follow_the_plane_lines() {
        // A floor (normal up, seen from above at an angle) whose planks run
        // at 30° to the camera's x axis: the coordinates of points along a
        // plank keep their v (e1 along the planks), and the turn is the
        // smallest one (e1 within 45° of the camera's x axis projected).
        let n = Vec3::new(0.0, 1.0, 0.3).normalize();
        let x0 = (Vec3::X - Vec3::X.dot(n) * n).normalize();
        let z0 = n.cross(x0);
        let (c, s) = (30f32.to_radians().cos(), 30f32.to_radians().sin());
        let plank = c * x0 + s * z0;
        for along in [plank, -plank, n.cross(plank), plank + 0.1 * n] {
            let (e1, e2) = plane_basis(n, Some(along));
            assert!((e1.dot(plank).abs() - 1.0).abs() < 0.01 || e1.dot(plank).abs() < 0.01);
            assert!(e1.dot(x0) > 45f32.to_radians().cos() - 1e-4, "{e1} {x0}");
            assert!(e1.dot(n).abs() < 1e-5 && (e2 - n.cross(e1)).length() < 1e-6);
        }
        let (e1, _) = plane_basis(n, Some(plank));
        assert!((e1 - plank).length() < 1e-5);
        // Out of the plane, not finite or zero: the untouched basis.
        let plain = plane_basis(n, None);
        for bad in [n, plank + 0.5 * n, Vec3::NAN, Vec3::ZERO] {
            assert_eq!(plane_basis(n, Some(bad)), plain);
        }
        // The rectified view: photo points on one plank share their v.
        let (w, h, f) = (64usize, 48usize, 50.0f32);
        // (A mask around the plank, so the texture square holds it.)
        let mask: Vec<bool> = (0..w * h)
            .map(|i| (18..34).contains(&(i / w)) && (8..56).contains(&(i % w)))
            .collect();
        let coords = plane_coords(w, h, &mask, n, f, Some(plank));
        let pix = |p: Vec3| {
            // The pixel at which plane point p (camera space) is seen.
            let (x, y) = (
                -p.x / p.z * f + w as f32 / 2.0,
                p.y / p.z * f + h as f32 / 2.0,
            );
            (x as usize, y as usize)
        };
        // A point on the plane N·P = −1, about 3 units ahead.
        let ahead = Vec3::new(0.0, 0.0, -3.0);
        let p0 = ahead - (ahead.dot(n) + 1.0) * n;
        let mut vs = Vec::new();
        for k in -4..=4 {
            let (x, y) = pix(p0 + plank * (k as f32 * 0.15));
            if x < w && y < h {
                let i = y * w + x;
                if coords.v[i].is_finite() {
                    vs.push((coords.u[i], coords.v[i]));
                }
            }
        }
        assert!(vs.len() >= 5, "{vs:?}");
        let (umin, umax) = vs
            .iter()
            .fold((f32::MAX, f32::MIN), |m, p| (m.0.min(p.0), m.1.max(p.0)));
        let (vmin, vmax) = vs
            .iter()
            .fold((f32::MAX, f32::MIN), |m, p| (m.0.min(p.1), m.1.max(p.1)));
        // Along the plank u moves, v stays within the pixel rounding.
        assert!(umax - umin > 5.0 * (vmax - vmin), "{vs:?}");
    }

    #[test]
    fn a_receding_floor_is_rectified() {
        // A floor seen at an angle: equal steps on the floor are unequal in the
        // image; after rectification, the texel density along a column
        // grows towards the horizon but the coordinates stay monotone.
        let (w, h) = (64, 64);
        let mut mask = vec![false; w * h];
        for y in 40..h {
            for x in 0..w {
                mask[y * w + x] = true;
            }
        }
        let n = Vec3::new(0.0, 1.0, 0.2).normalize();
        let c = plane_coords(w, h, &mask, n, 60.0, None);
        let col: Vec<f32> = (40..h)
            .map(|y| c.v[y * w + w / 2])
            .filter(|v| v.is_finite())
            .collect();
        assert!(col.len() > 10);
        assert!(col.windows(2).all(|p| p[1] > p[0]));
        let steps: Vec<f32> = col.windows(2).map(|p| p[1] - p[0]).collect();
        assert!(steps[0] > steps[steps.len() - 1] * 1.5, "{steps:?}");
    }

    /// `w × h` normals: left of column `split` `a`, from it on `b`, with
    /// a little noise.
    fn two_planes(w: usize, h: usize, split: usize, a: Vec3, b: Vec3, seed: u64) -> Image {
        let mut rng = picker_tensor::Rng::new(seed);
        let mut img = Image::zeros(3, h, w);
        for y in 0..h {
            for x in 0..w {
                let n = if x < split { a } else { b };
                let n = (n + Vec3::new(
                    rng.uniform(-0.05, 0.05),
                    rng.uniform(-0.05, 0.05),
                    rng.uniform(-0.05, 0.05),
                ))
                .normalize();
                img.set_rgb(y * w + x, n);
            }
        }
        img
    }

    #[test]
    fn coplanar_part_takes_the_picked_wall() {
        let (w, h) = (60, 40);
        let a = Vec3::new(0.7, 0.0, 0.7).normalize();
        let b = Vec3::new(-0.7, 0.1, 0.7).normalize();
        let normals = two_planes(w, h, 24, a, b, 3);
        let mask = vec![true; w * h];
        for (anchor, left) in [
            ((5, 20), true),
            ((23, 0), true),
            ((40, 39), false),
            ((24, 5), false),
        ] {
            let p = coplanar_part(&normals, &mask, w, h, anchor, 20.0).expect("a part");
            let want: Vec<bool> = (0..w * h).map(|i| (i % w < 24) == left).collect();
            assert_eq!(p.mask, want, "anchor {anchor:?}");
            let truth = if left { a } else { b };
            assert!(p.normal.dot(truth) > 0.999, "{:?} vs {truth:?}", p.normal);
            assert!(p.spread_deg < 5.0);
            let share = if left { 24.0 / 60.0 } else { 36.0 / 60.0 };
            assert!((p.share - share).abs() < 1e-9);
        }
    }

    #[test]
    fn coplanar_part_follows_the_mask_and_refuses_slivers() {
        let (w, h) = (60, 40);
        let a = Vec3::new(0.0, 1.0, 0.2).normalize();
        let b = Vec3::Z;
        // A floor (a) with a table top (a, parallel but another plane)
        // that does not touch it, and a two-column strip of wall (b) at the
        // right edge.
        let mut normals = two_planes(w, h, 58, a, b, 4);
        let table = |i: usize| (30..50).contains(&(i % w)) && (10..16).contains(&(i / w));
        let gap = |i: usize| (28..52).contains(&(i % w)) && (8..18).contains(&(i / w)) && !table(i);
        for i in (0..w * h).filter(|&i| gap(i)) {
            normals.set_rgb(i, Vec3::X);
        }
        let floor = |i: usize| i % w < 58 && !gap(i) && !table(i);
        // The mask leaves out the top rows; the anchor outside the mask
        // reads the normals of the masked pixels around it.
        let mask: Vec<bool> = (0..w * h).map(|i| i / w >= 4).collect();
        let p = coplanar_part(&normals, &mask, w, h, (10, 2), 20.0).unwrap();
        let want: Vec<bool> = (0..w * h).map(|i| i / w >= 4 && floor(i)).collect();
        assert_eq!(p.mask, want, "the floor, not the table top");
        let p = coplanar_part(&normals, &mask, w, h, (40, 12), 20.0).unwrap();
        let want: Vec<bool> = (0..w * h).map(table).collect();
        assert_eq!(p.mask, want, "the table top, not the floor");
        // The wall is under 5% of the mask (2 of 60 columns): no part.
        assert!(coplanar_part(&normals, &mask, w, h, (59, 20), 20.0).is_none());
        // An anchor beyond the grid is clamped to it (the same sliver).
        assert!(coplanar_part(&normals, &mask, w, h, (500, 500), 20.0).is_none());
        // Nothing masked, or no usable normals: none.
        assert!(coplanar_part(&normals, &vec![false; w * h], w, h, (5, 5), 20.0).is_none());
        let zero = Image::zeros(3, h, w);
        assert!(coplanar_part(&zero, &mask, w, h, (5, 20), 20.0).is_none());
    }

    #[test]
    fn coplanar_part_takes_in_the_blotches_it_encloses() {
        let (w, h) = (60, 40);
        let a = Vec3::new(0.0, 0.8, 0.6).normalize();
        let tilted = Vec3::new(0.6, 0.8, 0.2).normalize();
        assert!(a.dot(tilted).acos().to_degrees() > 30.0);
        let mut normals = two_planes(w, h, w, a, a, 5);
        let inside = |i: usize, x0: usize, x1: usize, y0: usize, y1: usize| {
            (x0..x1).contains(&(i % w)) && (y0..y1).contains(&(i / w))
        };
        // Blotches of tilted normals: one inside, one at the top border,
        // one inside with a small island of the plane's normal.
        let blotch = |i: usize| {
            inside(i, 10, 18, 10, 16) || inside(i, 40, 50, 0, 6) || inside(i, 25, 35, 25, 35)
        };
        for i in (0..w * h).filter(|&i| blotch(i) && !inside(i, 29, 31, 29, 31)) {
            normals.set_rgb(i, tilted);
        }
        // A few pixels inside the first blotch are not the material.
        let mask: Vec<bool> = (0..w * h).map(|i| !inside(i, 12, 14, 12, 14)).collect();
        let p = coplanar_part(&normals, &mask, w, h, (5, 30), 20.0).expect("a part");
        let want: Vec<bool> = (0..w * h)
            .map(|i| mask[i] && !inside(i, 40, 50, 0, 6))
            .collect();
        assert_eq!(p.mask, want);
        assert!(p.normal.dot(a) > 0.999, "{:?}", p.normal);
        assert!(p.spread_deg < 5.0, "{}", p.spread_deg);
        let share = want.iter().filter(|&&b| b).count() as f64 / (w * h - 4) as f64;
        assert!((p.share - share).abs() < 1e-12);
        // A hole that is a quarter or more the plane's own normal (a
        // parallel face ringed by its sides) stays out.
        for i in (0..w * h).filter(|&i| inside(i, 26, 32, 26, 32)) {
            normals.set_rgb(i, a);
        }
        let p = coplanar_part(&normals, &mask, w, h, (5, 30), 20.0).expect("a part");
        assert!((0..w * h)
            .filter(|&i| inside(i, 25, 35, 25, 35))
            .all(|i| !p.mask[i]));
        assert!((0..w * h)
            .filter(|&i| inside(i, 10, 18, 10, 16))
            .all(|i| p.mask[i] == mask[i]));
    }

    #[test]
    fn faces_camera_cases() {
        let (w, h) = (320, 240);
        // A wall facing the camera, at the centre and at a corner.
        assert!(faces_camera(Vec3::Z, (160, 120), w, h));
        assert!(faces_camera(Vec3::Z, (0, 0), w, h));
        // Its back.
        assert!(!faces_camera(-Vec3::Z, (160, 120), w, h));
        // A floor (normal up) seen below the horizon, and above it (its back).
        assert!(faces_camera(Vec3::Y, (160, 230), w, h));
        assert!(!faces_camera(Vec3::Y, (160, 10), w, h));
        // A side wall facing right, seen on the left of the image only.
        assert!(faces_camera(Vec3::X, (10, 120), w, h));
        assert!(!faces_camera(Vec3::X, (300, 120), w, h));
    }

    /// The share of a `g × g` grid over the texture square that the
    /// `mask`ed pixels' coordinates fall into.
    fn square_cover(c: &Coords, mask: &[bool], g: usize) -> f64 {
        c.footprint(mask, g).unwrap()
    }

    /// The coordinates in a given square: the framed square's own origin
    /// and side give the framed coordinates bit for bit; a square grown by
    /// a margin on every side keeps them (rescaled) and adds the pixels
    /// around it.
    #[test]
    fn coordinates_in_a_square_around_the_framed_one() {
        let (w, h) = (160, 120);
        let mask: Vec<bool> = (0..w * h).map(|i| i / w >= 40).collect();
        let n = Vec3::new(0.0, 1.0, 0.3).normalize();
        let focal = 150.0;
        for framing in [Framing::Covered, Framing::Whole] {
            let (c, sq) = plane_coords_with_side(w, h, &mask, None, n, focal, None, framing);
            let sq = sq.unwrap();
            let same = plane_coords_in(w, h, &mask, n, focal, None, sq.origin, sq.side);
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&same.u), bits(&c.u), "{framing:?}");
            assert_eq!(bits(&same.v), bits(&c.v), "{framing:?}");
            let g = 0.25 * sq.side;
            let big = plane_coords_in(
                w,
                h,
                &mask,
                n,
                focal,
                None,
                [sq.origin[0] - g, sq.origin[1] - g],
                1.5 * sq.side,
            );
            let (mut inside, mut around) = (0, 0);
            for (i, &picked) in mask.iter().enumerate() {
                if c.u[i].is_finite() {
                    inside += 1;
                    let (u, v) = ((big.u[i] * 1.5 - 0.25), (big.v[i] * 1.5 - 0.25));
                    assert!((u - c.u[i]).abs() < 1e-4 && (v - c.v[i]).abs() < 1e-4);
                } else if big.u[i].is_finite() {
                    around += 1;
                    assert!(picked);
                }
            }
            assert!(inside > 0 && around > 0, "{framing:?}: {inside} {around}");
        }
    }

    #[test]
    fn a_receding_floor_is_framed_where_the_photo_sees_it_best() {
        // A floor seen from eye height, pitched down a little: the lower half
        // of the image, the horizon at row 110. Its far rows stretch the box
        // of plane coordinates many times deeper than wide.
        let (w, h) = (200, 240);
        let mask: Vec<bool> = (0..w * h).map(|i| i / w >= 120).collect();
        let n = Vec3::new(0.0, 1.0, 0.08).normalize();
        let focal = 180.0;
        let c = plane_coords(w, h, &mask, n, focal, None);
        let r = plane_coords_reference(w, h, &mask, None, n, focal, None, Framing::Covered);
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&c.u), bits(&r.u));
        assert_eq!(bits(&c.v), bits(&r.v));
        // The same square whatever the thread count.
        for threads in [1, 3] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let t = pool.install(|| plane_coords(w, h, &mask, n, focal, None));
            assert_eq!(bits(&t.u), bits(&c.u), "{threads} threads");
            assert_eq!(bits(&t.v), bits(&c.v), "{threads} threads");
        }
        // The framed pixels are the near ones (the lower rows), they fill
        // the square, and the far rows (which see it coarsely) are left out.
        let rows: Vec<usize> = (0..w * h)
            .filter(|&i| c.u[i].is_finite())
            .map(|i| i / w)
            .collect();
        assert!(rows.len() > 2000, "{} framed", rows.len());
        let mean = rows.iter().sum::<usize>() as f64 / rows.len() as f64;
        assert!(mean > 180.0, "mean framed row {mean}");
        assert!(rows.iter().all(|&y| y > 135), "far rows framed");
        let cover = square_cover(&c, &mask, FRAME_CELLS);
        assert!(cover >= FRAME_COVER, "cover {cover}");
        // The whole square (for the periods) is the box's geometric-mean
        // side, larger, and also where the pixels crowd: its middle row is
        // nearer than the box's middle.
        let (whole, side) =
            plane_coords_with_side(w, h, &mask, None, n, focal, None, Framing::Whole);
        let (_, covered_side) =
            plane_coords_with_side(w, h, &mask, None, n, focal, None, Framing::Covered);
        assert!(
            side.unwrap().side > covered_side.unwrap().side * 1.3,
            "{side:?} {covered_side:?}"
        );
        let rows: Vec<usize> = (0..w * h)
            .filter(|&i| whole.u[i].is_finite())
            .map(|i| i / w)
            .collect();
        assert!(rows.len() > 4000, "{} framed", rows.len());
        let mean = rows.iter().sum::<usize>() as f64 / rows.len() as f64;
        assert!(mean > 175.0, "mean row framed by the whole square {mean}");
    }

    /// The photo columns and rows `(x0, x1, y0, y1)` of the pixels framed
    /// by `c` (inclusive).
    fn framed_box(c: &Coords) -> (usize, usize, usize, usize) {
        let w = c.width;
        let f: Vec<usize> = (0..c.u.len()).filter(|&i| c.u[i].is_finite()).collect();
        let xs = f.iter().map(|i| i % w);
        let ys = f.iter().map(|i| i / w);
        (
            xs.clone().min().unwrap(),
            xs.max().unwrap(),
            ys.clone().min().unwrap(),
            ys.max().unwrap(),
        )
    }

    #[test]
    fn a_wall_seen_head_on_keeps_the_box_centred_square() {
        // A square facing the camera: the texture square is its box
        // (the 2–98 % box of 200 × 200 pixels: 192 a side, centred).
        let (w, h) = (320, 240);
        let rect = |x0: usize, x1: usize, y0: usize, y1: usize| -> Vec<bool> {
            (0..w * h)
                .map(|i| (x0..x1).contains(&(i % w)) && (y0..y1).contains(&(i / w)))
                .collect()
        };
        let c = plane_coords(w, h, &rect(60, 260, 20, 220), Vec3::Z, 200.0, None);
        let (x0, x1, y0, y1) = framed_box(&c);
        assert!(
            (x0 + x1).abs_diff(319) <= 3 && (x1 - x0 + 1).abs_diff(192) <= 1,
            "columns {x0}..={x1}"
        );
        assert!(
            (y0 + y1).abs_diff(239) <= 3 && (y1 - y0 + 1).abs_diff(192) <= 1,
            "rows {y0}..={y1}"
        );
        // A 2 : 1 rectangle, 240 × 120: the square of the box's
        // geometric-mean side (about 166 pixels) would be 28 % empty; the
        // square taken is the next size (117), which it fills, centred
        // (every position inside holds as many pixels).
        let c = plane_coords(w, h, &rect(40, 280, 60, 180), Vec3::Z, 200.0, None);
        let (x0, x1, y0, y1) = framed_box(&c);
        assert!(
            y0.abs_diff(61) <= 2 && y1.abs_diff(178) <= 2,
            "rows {y0}..={y1}"
        );
        assert!((x0 + x1).abs_diff(319) <= 3, "columns {x0}..={x1}");
        assert!((x1 - x0 + 1).abs_diff(117) <= 3, "columns {x0}..={x1}");
        // The same at a twelfth of the size (20 × 10 pixels): a smaller
        // square would hold fewer than FRAME_MIN_PIXELS, so the square
        // keeps the box's geometric-mean side (about 13), 25 % empty.
        let c = plane_coords(w, h, &rect(150, 170, 115, 125), Vec3::Z, 200.0, None);
        let (x0, x1, y0, y1) = framed_box(&c);
        assert_eq!((y0, y1), (115, 124));
        assert!((x1 - x0 + 1).abs_diff(13) <= 1, "columns {x0}..={x1}");
    }

    #[test]
    fn an_irregular_region_is_framed_where_it_is_whole() {
        // A ring (a rug around a table, seen head-on): centred on its box
        // with the box's size the square would hold the empty middle; the
        // square taken is one that the ring fills.
        let (w, h) = (360, 360);
        let mask: Vec<bool> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32 - 180.0, (i / w) as f32 - 180.0);
                let r = (x * x + y * y).sqrt();
                (80.0..170.0).contains(&r)
            })
            .collect();
        let c = plane_coords(w, h, &mask, Vec3::Z, 240.0, None);
        let r = plane_coords_reference(w, h, &mask, None, Vec3::Z, 240.0, None, Framing::Covered);
        assert_eq!(
            c.u.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
            r.u.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
        );
        let cover = square_cover(&c, &mask, FRAME_CELLS);
        assert!(cover >= FRAME_COVER, "cover {cover}");
        // Still a usable part of it.
        let framed = c.u.iter().filter(|u| u.is_finite()).count();
        assert!(framed as u64 >= FRAME_MIN_PIXELS, "{framed} framed");
    }

    #[test]
    fn a_region_too_elongated_for_the_grid_is_framed_on_its_box() {
        // One row of a frontal wall: the box is 100 pixels by (almost)
        // nothing, the square's side the geometric mean of the two, far
        // more than FRAME_MAX_CELLS cells along the row; it is centred on the
        // box (and reported without a cell count), as before the search.
        let (w, h) = (120, 40);
        let mask: Vec<bool> = (0..w * h)
            .map(|i| i / w == 20 && (10..110).contains(&(i % w)))
            .collect();
        for framing in [Framing::Whole, Framing::Covered] {
            let (c, sq) = plane_coords_with_side(w, h, &mask, None, Vec3::Z, 100.0, None, framing);
            let r = plane_coords_reference(w, h, &mask, None, Vec3::Z, 100.0, None, framing);
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&c.u), bits(&r.u));
            let sq = sq.expect("a square");
            assert_eq!((sq.side_share, sq.cells_observed), (1.0, None), "{sq:?}");
            let framed: Vec<usize> = (0..w * h).filter(|&i| c.u[i].is_finite()).collect();
            assert!(!framed.is_empty() && framed.len() < 5, "{framed:?}");
            let mid = framed[framed.len() / 2] % w;
            assert!(mid.abs_diff(60) <= 2, "framed at column {mid}");
        }
    }

    #[test]
    fn two_far_clusters_are_framed_at_the_median() {
        // A floor seen in two patches at the same depth, far apart left
        // and right (the middle masked out): the box is wide and shallow,
        // its centre falls in the gap and the square (the geometric mean of
        // its sides) is narrower than the gap; it must still hold pixels.
        let (w, h) = (80, 60);
        let mask: Vec<bool> = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                (50..56).contains(&y) && !(12..68).contains(&x)
            })
            .collect();
        let n = Vec3::new(0.0, 1.0, 0.05).normalize();
        let a = plane_coords(w, h, &mask, n, 60.0, None);
        let b = plane_coords_reference(w, h, &mask, None, n, 60.0, None, Framing::Covered);
        let landed = a.u.iter().filter(|u| u.is_finite()).count();
        assert!(landed > 0, "nothing framed");
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&a.u), bits(&b.u));
        assert_eq!(bits(&a.v), bits(&b.v));
    }
}
