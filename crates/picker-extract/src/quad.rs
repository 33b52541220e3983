//! A plane the user gives instead of the predicted one: a normal, or the four
//! corners of a rectangle seen on the surface (the way an artist rectifies a
//! photographed texture by hand).
//!
//! Corners are photo pixel coordinates in the pick's convention (x right, y
//! down, after EXIF orientation; `(x, y)` is the centre of that pixel,
//! fractions lie between centres), so the continuous point is
//! `(x + ½, y + ½)`, the convention of [`crate::plane::plane_coords`]. With
//! the principal point at the photo's centre `c` and focal `f`, a point's ray
//! is `r = ((x + ½ − c_x)/f, −(y + ½ − c_y)/f, −1)`. The plane through the
//! camera and one side of the quad has normal `r_a × r_b`; the 3-D direction
//! of two opposite sides (parallel on the surface) is the cross product of
//! their two planes' normals (their vanishing direction), and the surface's
//! normal is the cross product of the two sides' directions. The focal
//! length, when no field of view is given, is the one under which the two
//! directions are at right angles (a rectangle): with the vanishing points
//! `v₁`, `v₂` relative to the centre, `f² = −v₁·v₂` ([`Quad::focal`]).

use glam::{DVec2, DVec3, Vec3};
use rayon::prelude::*;

/// The plane the rectification uses when the user gives one
/// ([`crate::pipeline::Options::plane`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum UserPlane {
    /// The plane's unit normal in camera space (x right, y up, z towards
    /// the camera: the convention of the normals element). `(0, 0, 1)` is
    /// a surface facing the camera (a scan, a head-on photo).
    Normal(Vec3),
    /// Four corners of a rectangle on the surface, in order around it.
    Quad(Quad),
}

impl UserPlane {
    /// The plane facing the camera: normal `(0, 0, 1)`.
    pub const FRONT: UserPlane = UserPlane::Normal(Vec3::Z);

    /// A normal plane from a direction: normalised; refused when it is not
    /// finite or has no length.
    pub fn normal(n: [f32; 3]) -> Result<Self, String> {
        let v = Vec3::from(n);
        if !v.is_finite() || v.length() < 1e-6 {
            return Err(format!(
                "the normal {},{},{} has no direction (it needs finite components, not all zero)",
                n[0], n[1], n[2]
            ));
        }
        Ok(UserPlane::Normal(v.normalize()))
    }
}

/// The four corners of a rectangle on a surface as the photo shows them, in
/// order around it (either way round); see the module docs for the
/// coordinates. The first side (corner 1 to corner 2) becomes the texture's
/// axis nearest the photo's x axis or y axis, whichever it is closest to.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Quad(pub [[f32; 2]; 4]);

/// Shortest side of a usable quad, in photo pixels.
pub const MIN_SIDE_PX: f64 = 4.0;

/// Smallest area of a usable quad, in square photo pixels.
pub const MIN_AREA_PX: f64 = 64.0;

/// [`Quad::focal`] is used only when moving any corner by
/// `max(1 px, FOCAL_PROBE_SHARE × diagonal)` in x or y changes it by less
/// than [`FOCAL_MAX_CHANGE`]: a nearly head-on quad (its sides nearly
/// parallel in the photo) tells the focal length poorly.
pub const FOCAL_PROBE_SHARE: f64 = 0.002;

/// See [`FOCAL_PROBE_SHARE`].
pub const FOCAL_MAX_CHANGE: f64 = 0.1;

/// The plane a quad gives under one focal length.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct QuadPlane {
    /// Unit normal, camera space, facing the camera.
    pub normal: Vec3,
    /// Unit direction of the first side (corner 1 to corner 2) on the surface.
    pub along: Vec3,
    /// The angle between the two pairs of sides on the surface, degrees
    /// (90 for a rectangle seen with the right focal length).
    pub corner_angle_deg: f32,
}

fn cross2(a: DVec2, b: DVec2) -> f64 {
    a.x * b.y - a.y * b.x
}

impl Quad {
    /// The corners as continuous photo points (pixel centres at `+½`).
    fn points(&self) -> [DVec2; 4] {
        self.0
            .map(|[x, y]| DVec2::new(f64::from(x) + 0.5, f64::from(y) + 0.5))
    }

    /// Checks that the corners lie on a `w × h` photo (from the first pixel's
    /// centre minus ½ to the last one's plus ½) and go around a convex
    /// quadrilateral with sides of at least [`MIN_SIDE_PX`] and an area of
    /// at least [`MIN_AREA_PX`]. The error says which corner is wrong.
    pub fn check(&self, w: usize, h: usize) -> Result<(), String> {
        for (k, &[x, y]) in self.0.iter().enumerate() {
            if !(x.is_finite() && y.is_finite()) {
                return Err(format!("corner {} ({x},{y}) is not a number", k + 1));
            }
            let inside = |v: f32, n: usize| v >= -0.5 && f64::from(v) <= n as f64 - 0.5;
            if !(inside(x, w) && inside(y, h)) {
                return Err(format!(
                    "corner {} ({x},{y}) is outside the {w}x{h} photo",
                    k + 1
                ));
            }
        }
        let p = self.points();
        for k in 0..4 {
            let side = (p[(k + 1) % 4] - p[k]).length();
            if side < MIN_SIDE_PX {
                return Err(format!(
                    "corners {} and {} are {side:.1} pixels apart (at least {MIN_SIDE_PX} needed)",
                    k + 1,
                    (k + 1) % 4 + 1
                ));
            }
        }
        let turns: Vec<f64> = (0..4)
            .map(|k| cross2(p[(k + 1) % 4] - p[k], p[(k + 2) % 4] - p[(k + 1) % 4]))
            .collect();
        let sign = turns.iter().map(|t| t.signum()).sum::<f64>();
        if let Some(k) = turns
            .iter()
            .position(|t| t.signum() != sign.signum() || *t == 0.0)
        {
            return Err(format!(
                "the corners do not go around a convex quadrilateral (the turn at corner {} is {}): give them in order around the rectangle",
                (k + 1) % 4 + 1,
                if turns[k] == 0.0 { "straight" } else { "the other way" }
            ));
        }
        let area = 0.5
            * (0..4)
                .map(|k| cross2(p[k], p[(k + 1) % 4]))
                .sum::<f64>()
                .abs();
        if area < MIN_AREA_PX {
            return Err(format!(
                "the quadrilateral covers {area:.0} square pixels (at least {MIN_AREA_PX} needed)"
            ));
        }
        Ok(())
    }

    /// The lengths of the four sides (1–2, 2–3, 3–4, 4–1) on the plane of
    /// unit normal `n` (camera space) through `N·P = −1`, the plane
    /// [`crate::plane::plane_coords`] measures in, under focal `focal` for a
    /// `w × h` photo: each corner's ray met with the plane. `None` when a
    /// ray misses the plane's front.
    pub fn sides_on_plane(&self, w: usize, h: usize, focal: f32, n: Vec3) -> Option<[f64; 4]> {
        let (c, f) = (DVec2::new(w as f64 / 2.0, h as f64 / 2.0), f64::from(focal));
        let n = n.as_dvec3();
        let mut p = [DVec3::ZERO; 4];
        for (q, out) in self.points().iter().zip(&mut p) {
            let d = DVec3::new((q.x - c.x) / f, -(q.y - c.y) / f, -1.0);
            let nd = n.dot(d);
            if nd.is_nan() || nd >= -1e-9 {
                return None;
            }
            *out = -d / nd;
        }
        Some(std::array::from_fn(|k| (p[(k + 1) % 4] - p[k]).length()))
    }

    /// The photo pixels of a `w × h` photo whose centres lie inside the
    /// quadrilateral or on its sides (any order of the corners around it;
    /// a quad that is not convex, [`Quad::check`], gets the pixels on the
    /// inner side of all four sides). The mask of the region the quad
    /// outlines (`--mask quad`).
    pub fn interior(&self, w: usize, h: usize) -> crate::mask::Mask {
        self.interior_through(&crate::lens::Lens::pinhole(w, h), w, h)
    }

    /// [`Quad::interior`] through a lens ([`crate::lens`]): the pixels whose
    /// undistorted centres lie inside the undistorted quad, so that its sides
    /// follow the rectangle's edges where the lens bends them. Through a
    /// pinhole, [`Quad::interior`].
    pub fn interior_through(
        &self,
        lens: &crate::lens::Lens,
        w: usize,
        h: usize,
    ) -> crate::mask::Mask {
        let p = self.undistorted(lens).points();
        // Twice the signed area: its sign says which way the corners go.
        let area2: f64 = (0..4).map(|k| p[k].perp_dot(p[(k + 1) % 4])).sum();
        let s = if area2 < 0.0 { -1.0 } else { 1.0 };
        let data = (0..w * h)
            .into_par_iter()
            .map(|i| {
                let c = glam::Vec2::new((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
                let q = lens.undistort(c).as_dvec2();
                (0..4).all(|k| s * (p[(k + 1) % 4] - p[k]).perp_dot(q - p[k]) >= -1e-9)
            })
            .collect();
        crate::mask::Mask {
            width: w,
            height: h,
            data,
        }
    }

    /// The pixel nearest the corners' mean (the pick when none is given).
    pub fn centre_pixel(&self) -> [u32; 2] {
        let m = self.0.iter().fold([0.0f64; 2], |a, c| {
            [a[0] + f64::from(c[0]) / 4.0, a[1] + f64::from(c[1]) / 4.0]
        });
        [m[0].round().max(0.0) as u32, m[1].round().max(0.0) as u32]
    }

    /// The two vanishing points (homogeneous, centred photo coordinates) of
    /// the sides 1–2 / 4–3 and 2–3 / 1–4.
    fn vanishing(p: &[DVec2; 4], c: DVec2) -> [DVec3; 2] {
        let h = |q: DVec2| (q - c).extend(1.0);
        let line = |a: usize, b: usize| h(p[a]).cross(h(p[b]));
        [line(0, 1).cross(line(3, 2)), line(1, 2).cross(line(0, 3))]
    }

    fn focal_of(p: &[DVec2; 4], c: DVec2) -> Option<f64> {
        let [v1, v2] = Self::vanishing(p, c);
        // Finite vanishing points only (the sides meet in the photo's plane).
        let scale = p.iter().map(|q| (*q - c).length()).fold(1.0, f64::max);
        let finite = |v: DVec3| v.z.abs() * scale * 1e6 > v.truncate().length();
        if !(finite(v1) && finite(v2)) {
            return None;
        }
        let (a, b) = (v1.truncate() / v1.z, v2.truncate() / v2.z);
        let f2 = -a.dot(b);
        (f2 > 0.0 && f2.is_finite()).then(|| f2.sqrt())
    }

    /// The quad with its corners undistorted by `lens` ([`crate::lens`]):
    /// where they would lie through a pinhole, which the plane and focal
    /// length are found from.
    pub fn undistorted(&self, lens: &crate::lens::Lens) -> Self {
        // Corners are in pick coordinates (a pixel's centre at +½).
        Self(self.0.map(|c| {
            let u = lens.undistort(glam::Vec2::from(c) + 0.5) - 0.5;
            [u.x, u.y]
        }))
    }

    /// The focal length (photo pixels) under which the quad's sides meet at
    /// right angles on the surface, when the quad tells it well
    /// ([`FOCAL_PROBE_SHARE`]) and it gives a field of view within
    /// [`crate::lines::FOCAL_FOV_RANGE`]; `None` otherwise (a head-on quad,
    /// a quad that is no rectangle under any focal).
    pub fn focal(&self, w: usize, h: usize) -> Option<f32> {
        let p = self.points();
        let c = DVec2::new(w as f64 / 2.0, h as f64 / 2.0);
        let f = Self::focal_of(&p, c)?;
        let (lo, hi) = crate::lines::FOCAL_FOV_RANGE;
        let fov = crate::plane::fov_from_focal(h, f as f32);
        if !(lo..=hi).contains(&fov) {
            return None;
        }
        let step = (FOCAL_PROBE_SHARE * (w as f64).hypot(h as f64)).max(1.0);
        for k in 0..4 {
            for d in [
                DVec2::new(step, 0.0),
                DVec2::new(-step, 0.0),
                DVec2::new(0.0, step),
                DVec2::new(0.0, -step),
            ] {
                let mut q = p;
                q[k] += d;
                match Self::focal_of(&q, c) {
                    Some(g) if (g - f).abs() < FOCAL_MAX_CHANGE * f => {}
                    _ => return None,
                }
            }
        }
        Some(f as f32)
    }

    /// The surface's plane under focal `focal` (photo pixels) for a `w × h`
    /// photo. Refused when the sides give no directions (a degenerate quad)
    /// or when the plane would not show its front at every corner (no
    /// rectangle on one surface looks like this under that focal).
    pub fn plane(&self, w: usize, h: usize, focal: f32) -> Result<QuadPlane, String> {
        let f = f64::from(focal);
        if !(f.is_finite() && f > 0.0) {
            return Err(format!("focal length {focal} is not positive"));
        }
        let c = DVec2::new(w as f64 / 2.0, h as f64 / 2.0);
        let r = self
            .points()
            .map(|q| DVec3::new((q.x - c.x) / f, -(q.y - c.y) / f, -1.0));
        let dir = |a: usize, b: usize, d: usize, e: usize| {
            r[a].cross(r[b]).cross(r[d].cross(r[e])).normalize_or_zero()
        };
        let (d1, d2) = (dir(0, 1, 3, 2), dir(1, 2, 0, 3));
        let n = d1.cross(d2);
        if d1 == DVec3::ZERO || d2 == DVec3::ZERO || n.length() < 1e-9 {
            return Err("its sides give no plane (two of them lie on one line)".into());
        }
        let centre = r.iter().fold(DVec3::ZERO, |a, &b| a + b);
        let n = n.normalize();
        let n = if n.dot(centre) > 0.0 { -n } else { n };
        if r.iter().any(|ri| n.dot(*ri) >= -1e-9) {
            return Err(
                "no rectangle on one surface looks like this quadrilateral (the surface it gives would be seen edge-on or from behind at a corner)"
                    .into(),
            );
        }
        // The first side's direction, pointing from corner 1 to corner 2.
        let along = if d1.dot(r[1] / -n.dot(r[1]) - r[0] / -n.dot(r[0])) < 0.0 {
            -d1
        } else {
            d1
        };
        Ok(QuadPlane {
            normal: n.as_vec3(),
            along: along.as_vec3(),
            corner_angle_deg: d1.dot(d2).abs().clamp(0.0, 1.0).acos().to_degrees() as f32,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The photo pixel coordinates (pick convention) of camera-space point
    /// `q` for a `w × h` photo with focal `f`.
    fn project(q: DVec3, w: usize, h: usize, f: f64) -> [f32; 2] {
        let x = w as f64 / 2.0 + f * q.x / -q.z - 0.5;
        let y = h as f64 / 2.0 - f * q.y / -q.z - 0.5;
        [x as f32, y as f32]
    }

    /// A rectangle with sides `a` (along `e1`) and `b` centred at `o` on the
    /// plane of normal `n`, seen by the camera of a `w × h` photo, focal `f`.
    fn rect_quad(
        (n, e1, o): (DVec3, DVec3, DVec3),
        (a, b): (f64, f64),
        (w, h, f): (usize, usize, f64),
    ) -> Quad {
        let n = n.normalize();
        let e1 = (e1 - e1.dot(n) * n).normalize();
        let e2 = n.cross(e1);
        let c = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)];
        Quad(c.map(|(s, t)| project(o + e1 * (s * a / 2.0) + e2 * (t * b / 2.0), w, h, f)))
    }

    fn angle_deg(a: Vec3, b: Vec3) -> f32 {
        a.normalize()
            .dot(b.normalize())
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees()
    }

    /// A rectangle's interior is its pixels, corners and sides included,
    /// either way round; a tilted quad's count is its area within its
    /// perimeter, and each pixel agrees with a winding-number test.
    /// A rectangle of the pinhole picture seen through a barrel lens: its
    /// sides bow outwards between its corners, so the pixels just outside
    /// the straight quad through its (distorted) corners, at the middle of
    /// a side, are inside it through the lens; a pinhole gives `interior`.
    #[test]
    fn the_interior_through_a_lens_follows_the_bent_sides() {
        let (w, h) = (200, 150);
        let lens = crate::lens::Lens::new(-0.3, w, h);
        let rect = [
            [30.0f32, 20.0],
            [170.0, 20.0],
            [170.0, 130.0],
            [30.0, 130.0],
        ];
        // The rectangle's corners (continuous coordinates) as picked.
        let corners = rect.map(|c| {
            let d = lens.distort(glam::Vec2::from(c)).unwrap() - 0.5;
            [d.x, d.y]
        });
        let q = Quad(corners);
        let straight = q.interior(w, h);
        let bent = q.interior_through(&lens, w, h);
        assert_eq!(
            q.interior_through(&crate::lens::Lens::pinhole(w, h), w, h),
            straight
        );
        assert!(bent.count() > straight.count());
        // The top side's middle: the chord through the two top corners at
        // x = 100, and a pixel two rows above it.
        let top = (corners[0][1] + corners[1][1]) / 2.0 + 0.5;
        let i = (top as usize - 2) * w + 100;
        assert!(bent.data[i] && !straight.data[i], "top chord at {top}");
        // Every pixel of the bent interior undistorts into the rectangle.
        for (i, _) in bent.data.iter().enumerate().filter(|(_, &b)| b) {
            let u = lens.undistort(glam::Vec2::new((i % w) as f32 + 0.5, (i / w) as f32 + 0.5));
            assert!(
                (29.9..=170.1).contains(&u.x) && (19.9..=130.1).contains(&u.y),
                "{u}"
            );
        }
    }

    #[test]
    fn the_interior_is_the_pixels_inside() {
        let q = Quad([[10.0, 10.0], [20.0, 10.0], [20.0, 15.0], [10.0, 15.0]]);
        let m = q.interior(40, 30);
        assert_eq!(m.count(), 11 * 6);
        assert!(m.data[10 * 40 + 10] && m.data[15 * 40 + 20] && !m.data[16 * 40 + 20]);
        let r = Quad([q.0[3], q.0[2], q.0[1], q.0[0]]);
        assert_eq!(r.interior(40, 30), m);
        let t = Quad([[5.3, 20.1], [60.7, 4.2], [75.5, 50.9], [12.2, 70.4]]);
        let (w, h) = (90, 80);
        let m = t.interior(w, h);
        let p = t.points();
        let area: f64 = (0..4)
            .map(|k| p[k].perp_dot(p[(k + 1) % 4]))
            .sum::<f64>()
            .abs()
            / 2.0;
        let perimeter: f64 = (0..4).map(|k| (p[(k + 1) % 4] - p[k]).length()).sum();
        assert!(
            (m.count() as f64 - area).abs() < perimeter,
            "{} vs {area}",
            m.count()
        );
        // Winding number of the closed polygon around each pixel centre.
        for i in 0..w * h {
            let c = DVec2::new((i % w) as f64 + 0.5, (i / w) as f64 + 0.5);
            let turn: f64 = (0..4)
                .map(|k| {
                    let (a, b) = (p[k] - c, p[(k + 1) % 4] - c);
                    a.perp_dot(b).atan2(a.dot(b))
                })
                .sum();
            let inside = turn.abs() > std::f64::consts::PI;
            let on_side = (0..4).any(|k| {
                let (a, b) = (p[k], p[(k + 1) % 4]);
                ((b - a).perp_dot(c - a) / (b - a).length()).abs() < 1e-6
            });
            if !on_side {
                assert_eq!(m.data[i], inside, "pixel {i}");
            }
        }
        // A quad beyond the photo: only the pixels inside both.
        let big = Quad([
            [-10.0, -10.0],
            [100.0, -10.0],
            [100.0, 100.0],
            [-10.0, 100.0],
        ]);
        assert_eq!(big.interior(7, 5).count(), 35);
        assert_eq!(big.interior(0, 5).count(), 0);
    }

    #[test]
    fn recovers_the_plane_and_the_focal_of_a_seen_rectangle() {
        let (w, h) = (640usize, 480usize);
        let mut rng = 0x5eedu64;
        let mut next = || {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            (rng >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut with_focal = 0;
        for case in 0..200 {
            let f = 300.0 + 500.0 * next();
            // Tilts 20–70° about a random in-image axis, facing the camera.
            let tilt = (20.0 + 50.0 * next()).to_radians();
            let az = std::f64::consts::TAU * next();
            let n = DVec3::new(tilt.sin() * az.cos(), tilt.sin() * az.sin(), tilt.cos());
            let o = DVec3::new(0.3 * (next() - 0.5), 0.3 * (next() - 0.5), -3.0);
            let e1 = DVec3::new(next() - 0.5, next() - 0.5, next() - 0.5);
            let (a, b) = (0.8 + next(), 0.8 + next());
            let q = rect_quad((n, e1, o), (a, b), (w, h, f));
            if q.check(w, h).is_err() {
                continue;
            }
            let p = q.plane(w, h, f as f32).unwrap();
            assert!(
                angle_deg(p.normal, n.as_vec3()) < 0.05,
                "case {case}: {p:?} vs {n}"
            );
            assert!(
                (p.corner_angle_deg - 90.0).abs() < 0.05,
                "case {case}: {p:?}"
            );
            let e1p = (e1 - e1.dot(n.normalize()) * n.normalize())
                .normalize()
                .as_vec3();
            assert!(
                angle_deg(p.along, e1p) < 0.05,
                "case {case}: along {:?} vs {e1p}",
                p.along
            );
            // The sides' lengths keep the rectangle's proportions.
            let sides = q.sides_on_plane(w, h, f as f32, n.as_vec3()).unwrap();
            let (sa, sb) = ((sides[0] + sides[2]) / 2.0, (sides[1] + sides[3]) / 2.0);
            assert!(
                (sides[0] / sides[2] - 1.0).abs() < 1e-4,
                "case {case}: {sides:?}"
            );
            assert!(
                (sa / sb - a / b).abs() < 1e-3 * a / b,
                "case {case}: {sides:?} vs {a}x{b}"
            );
            if let Some(g) = q.focal(w, h) {
                with_focal += 1;
                assert!(
                    (f64::from(g) - f).abs() < 1e-3 * f,
                    "case {case}: focal {g} vs {f}"
                );
            }
        }
        // Most tilted rectangles tell the focal.
        assert!(with_focal > 100, "{with_focal}");
    }

    #[test]
    fn a_head_on_rectangle_faces_the_camera_and_tells_no_focal() {
        let (w, h) = (400, 300);
        let q = Quad([[100.0, 50.0], [300.0, 50.0], [300.0, 250.0], [100.0, 250.0]]);
        q.check(w, h).unwrap();
        for f in [200.0, 400.0, 900.0] {
            let p = q.plane(w, h, f).unwrap();
            assert!(angle_deg(p.normal, Vec3::Z) < 1e-3, "{p:?}");
            assert!(angle_deg(p.along, Vec3::X) < 1e-3, "{p:?}");
            assert!((p.corner_angle_deg - 90.0).abs() < 1e-3);
        }
        assert_eq!(q.focal(w, h), None);
        // The other way round gives the same plane, the first side reversed.
        let r = Quad([[100.0, 250.0], [300.0, 250.0], [300.0, 50.0], [100.0, 50.0]]);
        let p = r.plane(w, h, 400.0).unwrap();
        assert!(angle_deg(p.normal, Vec3::Z) < 1e-3);
        assert_eq!(q.centre_pixel(), [200, 150]);
    }

    #[test]
    fn refuses_bad_quads() {
        let (w, h) = (400, 300);
        let ok = [[100.0, 50.0], [300.0, 60.0], [290.0, 250.0], [110.0, 240.0]];
        Quad(ok).check(w, h).unwrap();
        let with = |k: usize, c: [f32; 2]| {
            let mut q = ok;
            q[k] = c;
            Quad(q).check(w, h).unwrap_err()
        };
        assert!(with(2, [400.0, 250.0]).contains("corner 3"), "outside");
        assert!(with(0, [-1.0, 50.0]).contains("outside"));
        assert!(with(1, [f32::NAN, 50.0]).contains("not a number"));
        // Crossed (a bow tie): corners 2 and 3 swapped.
        let bow = Quad([ok[0], ok[2], ok[1], ok[3]]).check(w, h).unwrap_err();
        assert!(bow.contains("convex"), "{bow}");
        // Concave: corner 3 pulled inside.
        assert!(with(2, [180.0, 120.0]).contains("convex"));
        // Three on a line.
        // Three on a line: corner 2 halfway between corners 1 and 3.
        assert!(with(1, [195.0, 150.0]).contains("straight"));
        assert!(Quad([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])
            .check(w, h)
            .unwrap_err()
            .contains("apart"));
        assert!(Quad([[0.0, 0.0], [60.0, 0.0], [60.0, 1.0], [0.0, 1.0]])
            .check(w, h)
            .is_err());
        // The edges of the photo are inside.
        Quad([[-0.5, -0.5], [399.5, -0.5], [399.5, 299.5], [-0.5, 299.5]])
            .check(w, h)
            .unwrap();
    }

    #[test]
    fn every_focal_gives_a_convex_quad_a_plane_facing_the_camera() {
        // A convex quadrilateral is the image of a rectangle whose plane's
        // vanishing line misses it, whatever the focal length: a strongly
        // converging trapezoid is a floor under a short focal and still a
        // plane in front of the camera under a long one.
        let (w, h) = (400, 300);
        let q = Quad([[190.0, 10.0], [210.0, 10.0], [399.0, 290.0], [0.0, 290.0]]);
        q.check(w, h).unwrap();
        let p = q.plane(w, h, 150.0).unwrap();
        assert!(p.normal.z > 0.0 && p.normal.y > 0.0, "{p:?}");
        for f in [50.0f32, 150.0, 400.0, 2000.0, 1e5] {
            let p = q.plane(w, h, f).unwrap();
            for [x, y] in q.0 {
                let r = Vec3::new((x + 0.5 - 200.0) / f, -(y + 0.5 - 150.0) / f, -1.0);
                assert!(p.normal.dot(r) < 0.0, "f {f}: {p:?}");
            }
        }
        assert!(q.plane(w, h, 0.0).is_err());
        assert!(q.plane(w, h, f32::NAN).is_err());
    }

    #[test]
    fn user_normal_is_normalised_or_refused() {
        assert_eq!(
            UserPlane::normal([0.0, 0.0, 2.0]).unwrap(),
            UserPlane::FRONT
        );
        assert!(UserPlane::normal([0.0, 0.0, 0.0]).is_err());
        assert!(UserPlane::normal([f32::INFINITY, 0.0, 1.0]).is_err());
    }
}
