//! Analytic primitives and brute-force ray casting (world space, metres, +y up).
//!
//! Every primitive is axis-aligned: rectangles lying in a plane `x`, `y` or `z` =
//! const (floor, ceiling, wall panels), cuboids, vertical capped cylinders and
//! spheres. A scene has a few dozen of them, so rays are tested against all of
//! them (with an early-out bounding-box test for cylinders and spheres being
//! unnecessary at this scale). Each hit also returns 2-D *mapping coordinates*
//! in metres, from which [`crate::scene`] derives texture coordinates: planar
//! coordinates for rectangles, box faces and cylinder caps; arc length × height
//! for cylinder sides and longitude × latitude arc lengths for spheres (the
//! first coordinate is then periodic with the circumference, see [`Hit::period`]).

use glam::{Vec2, Vec3};
use serde::Serialize;

/// The two in-plane axes of a plane perpendicular to axis `k`, in the order the
/// mapping coordinates use them: for walls (k = x or z) horizontal first, then
/// height; for floors and ceilings (k = y), x then z.
pub const fn plane_axes(k: usize) -> (usize, usize) {
    match k {
        0 => (2, 1),
        1 => (0, 2),
        _ => (0, 1),
    }
}

/// A primitive shape.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Shape {
    /// A rectangle in the plane `axis = pos` (axis 0 = x, 1 = y, 2 = z) spanning
    /// `lo..hi` on the two in-plane axes ([`plane_axes`] order). Its front side
    /// faces `normal_sign · e_axis`; it is hit from both sides.
    Rect {
        /// Axis perpendicular to the rectangle.
        axis: u8,
        /// Position of the plane on that axis.
        pos: f32,
        /// Lower corner on the in-plane axes.
        lo: [f32; 2],
        /// Upper corner on the in-plane axes.
        hi: [f32; 2],
        /// +1 or −1: the side the front faces.
        normal_sign: f32,
    },
    /// An axis-aligned box.
    Cuboid {
        /// Lower corner.
        min: Vec3,
        /// Upper corner.
        max: Vec3,
    },
    /// A capped cylinder with a vertical axis, standing on `base` (centre of its bottom cap).
    Cylinder {
        /// Centre of the bottom cap.
        base: Vec3,
        /// Radius.
        radius: f32,
        /// Height.
        height: f32,
    },
    /// A sphere.
    Sphere {
        /// Centre.
        center: Vec3,
        /// Radius.
        radius: f32,
    },
}

/// A ray hit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Ray parameter (distance along a unit direction).
    pub t: f32,
    /// Outward unit normal of the surface (world space; for rectangles the front normal).
    pub normal: Vec3,
    /// Mapping coordinates in metres (see the module docs).
    pub coords: Vec2,
    /// `Some(c)`: `coords.x` is periodic with period `c` (cylinder sides, spheres).
    pub period: Option<f32>,
}

/// An axis-aligned bounding box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Lower corner.
    pub min: Vec3,
    /// Upper corner.
    pub max: Vec3,
}

/// The two ray parameters `t0 ≤ t1` where `o + t·d` (unit `d`) meets the sphere, if it does.
#[inline]
fn sphere_roots(o: Vec3, d: Vec3, center: Vec3, radius: f32) -> Option<(f32, f32)> {
    let oc = o - center;
    let b = oc.dot(d);
    let c = oc.length_squared() - radius * radius;
    let disc = b * b - c;
    if disc < 0.0 {
        return None;
    }
    let s = disc.sqrt();
    Some((-b - s, -b + s))
}

impl Aabb {
    /// Whether the two boxes overlap after growing `self` by `margin` on every side.
    pub fn overlaps(&self, o: &Aabb, margin: f32) -> bool {
        (self.min - margin).cmplt(o.max).all() && (self.max + margin).cmpgt(o.min).all()
    }
    /// Euclidean distance from `p` to the box (0 inside).
    pub fn distance(&self, p: Vec3) -> f32 {
        (self.min - p).max(p - self.max).max(Vec3::ZERO).length()
    }
}

impl Shape {
    /// The shape's bounding box.
    pub fn aabb(&self) -> Aabb {
        match *self {
            Shape::Rect {
                axis, pos, lo, hi, ..
            } => {
                let k = axis as usize;
                let (a, b) = plane_axes(k);
                let mut min = Vec3::ZERO;
                let mut max = Vec3::ZERO;
                min[k] = pos;
                max[k] = pos;
                min[a] = lo[0];
                max[a] = hi[0];
                min[b] = lo[1];
                max[b] = hi[1];
                Aabb { min, max }
            }
            Shape::Cuboid { min, max } => Aabb { min, max },
            Shape::Cylinder {
                base,
                radius,
                height,
            } => Aabb {
                min: base - Vec3::new(radius, 0.0, radius),
                max: base + Vec3::new(radius, height, radius),
            },
            Shape::Sphere { center, radius } => Aabb {
                min: center - radius,
                max: center + radius,
            },
        }
    }

    /// The nearest hit of the ray `o + t·d` (`d` unit) with `t_min < t < t_max`.
    #[inline]
    pub fn intersect(&self, o: Vec3, d: Vec3, t_min: f32, t_max: f32) -> Option<Hit> {
        match *self {
            Shape::Rect {
                axis,
                pos,
                lo,
                hi,
                normal_sign,
            } => {
                let k = axis as usize;
                if d[k].abs() < 1e-12 {
                    return None;
                }
                let t = (pos - o[k]) / d[k];
                if !(t > t_min && t < t_max) {
                    return None;
                }
                let p = o + t * d;
                let (a, b) = plane_axes(k);
                if p[a] < lo[0] || p[a] > hi[0] || p[b] < lo[1] || p[b] > hi[1] {
                    return None;
                }
                let mut normal = Vec3::ZERO;
                normal[k] = normal_sign;
                Some(Hit {
                    t,
                    normal,
                    coords: Vec2::new(p[a], p[b]),
                    period: None,
                })
            }
            Shape::Cuboid { min, max } => {
                let inv = d.recip();
                let t0 = (min - o) * inv;
                let t1 = (max - o) * inv;
                let tn = t0.min(t1);
                let tf = t0.max(t1);
                let (mut near, mut axis) = (tn.x, 0);
                if tn.y > near {
                    near = tn.y;
                    axis = 1;
                }
                if tn.z > near {
                    near = tn.z;
                    axis = 2;
                }
                let far = tf.min_element();
                if near > far || far <= t_min || near >= t_max {
                    return None;
                }
                let (t, normal_dir) = if near > t_min {
                    (near, -d[axis].signum())
                } else {
                    // Origin inside the box: leave through the far face.
                    let axis_f = if tf.x <= tf.y && tf.x <= tf.z {
                        0
                    } else if tf.y <= tf.z {
                        1
                    } else {
                        2
                    };
                    if far >= t_max {
                        return None;
                    }
                    axis = axis_f;
                    (far, d[axis].signum())
                };
                let p = o + t * d;
                let mut normal = Vec3::ZERO;
                normal[axis] = normal_dir;
                let (a, b) = plane_axes(axis);
                Some(Hit {
                    t,
                    normal,
                    coords: Vec2::new(p[a], p[b]),
                    period: None,
                })
            }
            Shape::Cylinder {
                base,
                radius,
                height,
            } => {
                let mut best: Option<Hit> = None;
                let mut t_best = t_max;
                // Side.
                let ox = o.x - base.x;
                let oz = o.z - base.z;
                let a = d.x * d.x + d.z * d.z;
                if a > 1e-12 {
                    let b = ox * d.x + oz * d.z;
                    let c = ox * ox + oz * oz - radius * radius;
                    let disc = b * b - a * c;
                    if disc >= 0.0 {
                        let s = disc.sqrt();
                        for t in [(-b - s) / a, (-b + s) / a] {
                            if t > t_min && t < t_best {
                                let p = o + t * d;
                                if p.y >= base.y && p.y <= base.y + height {
                                    let n = Vec3::new(p.x - base.x, 0.0, p.z - base.z) / radius;
                                    let phi = n.z.atan2(n.x) + std::f32::consts::PI;
                                    t_best = t;
                                    best = Some(Hit {
                                        t,
                                        normal: n.normalize_or(Vec3::X),
                                        coords: Vec2::new(phi * radius, p.y - base.y),
                                        period: Some(std::f32::consts::TAU * radius),
                                    });
                                    break;
                                }
                            }
                        }
                    }
                }
                // Caps.
                if d.y.abs() > 1e-12 {
                    for (y, ny) in [(base.y, -1.0f32), (base.y + height, 1.0)] {
                        let t = (y - o.y) / d.y;
                        if t > t_min && t < t_best {
                            let p = o + t * d;
                            let (dx, dz) = (p.x - base.x, p.z - base.z);
                            if dx * dx + dz * dz <= radius * radius {
                                t_best = t;
                                best = Some(Hit {
                                    t,
                                    normal: Vec3::new(0.0, ny, 0.0),
                                    coords: Vec2::new(p.x, p.z),
                                    period: None,
                                });
                            }
                        }
                    }
                }
                best
            }
            Shape::Sphere { center, radius } => {
                let (t0, t1) = sphere_roots(o, d, center, radius)?;
                let t = if t0 > t_min { t0 } else { t1 };
                if !(t > t_min && t < t_max) {
                    return None;
                }
                let p = o + t * d;
                let n = ((p - center) / radius).normalize_or(Vec3::Y);
                let phi = n.z.atan2(n.x) + std::f32::consts::PI;
                let theta = n.y.clamp(-1.0, 1.0).acos();
                Some(Hit {
                    t,
                    normal: n,
                    coords: Vec2::new(phi * radius, theta * radius),
                    period: Some(std::f32::consts::TAU * radius),
                })
            }
        }
    }
}

impl Aabb {
    /// Whether the ray `o + t·d` (`inv = 1/d` per component) meets the box for some `t_min < t < t_max`.
    #[inline]
    pub fn hit_by(&self, o: Vec3, inv: Vec3, t_min: f32, t_max: f32) -> bool {
        let t0 = (self.min - o) * inv;
        let t1 = (self.max - o) * inv;
        let near = t0.min(t1).max_element().max(t_min);
        let far = t0.max(t1).min_element().min(t_max);
        near <= far
    }
}

impl Shape {
    /// Whether the shape blocks the segment `o + t·d`, `t_min < t < t_max` (`inv = 1/d`):
    /// [`Shape::intersect`] without computing the hit's normal and coordinates.
    #[inline]
    pub fn blocks(&self, o: Vec3, d: Vec3, inv: Vec3, t_min: f32, t_max: f32) -> bool {
        match *self {
            Shape::Cuboid { min, max } => Aabb { min, max }.hit_by(o, inv, t_min, t_max),
            Shape::Sphere { center, radius } => {
                let Some((t0, t1)) = sphere_roots(o, d, center, radius) else {
                    return false;
                };
                (t0 > t_min && t0 < t_max) || (t1 > t_min && t1 < t_max)
            }
            _ => self.intersect(o, d, t_min, t_max).is_some(),
        }
    }
}

/// Index and hit of the nearest of `shapes` hit by `o + t·d`, `t_min < t < t_max`.
pub fn nearest<'a>(
    shapes: impl IntoIterator<Item = &'a Shape>,
    o: Vec3,
    d: Vec3,
    t_min: f32,
    t_max: f32,
) -> Option<(usize, Hit)> {
    let mut best = None;
    let mut t_best = t_max;
    for (i, s) in shapes.into_iter().enumerate() {
        if let Some(h) = s.intersect(o, d, t_min, t_best) {
            t_best = h.t;
            best = Some((i, h));
        }
    }
    best
}

/// Whether any of `shapes` blocks the segment `o + t·d`, `t_min < t < t_max`.
pub fn occluded<'a>(
    shapes: impl IntoIterator<Item = &'a Shape>,
    o: Vec3,
    d: Vec3,
    t_min: f32,
    t_max: f32,
) -> bool {
    shapes
        .into_iter()
        .any(|s| s.intersect(o, d, t_min, t_max).is_some())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hits_each_shape() {
        let o = Vec3::new(0.0, 0.5, 5.0);
        let d = Vec3::new(0.0, 0.0, -1.0);
        let cube = Shape::Cuboid {
            min: Vec3::splat(-1.0),
            max: Vec3::splat(1.0),
        };
        let h = cube.intersect(o, d, 0.0, 100.0).unwrap();
        assert!((h.t - 4.0).abs() < 1e-6 && h.normal == Vec3::Z);
        let sph = Shape::Sphere {
            center: Vec3::ZERO,
            radius: 1.0,
        };
        let h = sph
            .intersect(Vec3::new(0.0, 0.0, 5.0), d, 0.0, 100.0)
            .unwrap();
        assert!((h.t - 4.0).abs() < 1e-6 && (h.normal - Vec3::Z).length() < 1e-6);
        let cyl = Shape::Cylinder {
            base: Vec3::ZERO,
            radius: 1.0,
            height: 1.0,
        };
        let h = cyl.intersect(o, d, 0.0, 100.0).unwrap();
        assert!((h.t - 4.0).abs() < 1e-6 && (h.normal - Vec3::Z).length() < 1e-6);
        let h = cyl
            .intersect(Vec3::new(0.2, 3.0, 0.0), -Vec3::Y, 0.0, 100.0)
            .unwrap();
        assert!((h.t - 2.0).abs() < 1e-6 && h.normal == Vec3::Y);
        let rect = Shape::Rect {
            axis: 2,
            pos: -2.0,
            lo: [-1.0, 0.0],
            hi: [1.0, 1.0],
            normal_sign: 1.0,
        };
        let h = rect.intersect(o, d, 0.0, 100.0).unwrap();
        assert!((h.t - 7.0).abs() < 1e-6 && h.coords == Vec2::new(0.0, 0.5));
        assert!(rect.intersect(o, d, 0.0, 6.0).is_none());
        let all = [rect, cube, sph];
        assert_eq!(nearest(&all, o, d, 0.0, 100.0).unwrap().0, 1);
        assert!(occluded(&all, o, d, 0.0, 100.0));
        assert!(!occluded(&all, o, -d, 0.0, 100.0));
    }

    #[test]
    fn aabb_tests() {
        let a = Aabb {
            min: Vec3::ZERO,
            max: Vec3::ONE,
        };
        let b = Aabb {
            min: Vec3::splat(1.05),
            max: Vec3::splat(2.0),
        };
        assert!(!a.overlaps(&b, 0.0));
        assert!(a.overlaps(&b, 0.1));
        assert_eq!(a.distance(Vec3::splat(0.5)), 0.0);
        assert!((a.distance(Vec3::new(3.0, 0.5, 0.5)) - 2.0).abs() < 1e-6);
    }
}
