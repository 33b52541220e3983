//! Random indoor scenes: an axis-aligned room with window openings (or an open
//! side), furniture-like primitives resting on the floor or on each other, ceiling
//! lamps, a sky, materials and a camera — everything drawn from one [`Rng`] seeded
//! by `(seed, index)` ([`scene_seed`]), so a scene depends on nothing else.
//!
//! World space: metres, +y up; the room spans `[0, W] × [0, H] × [0, D]`.

use glam::{Mat3, Vec2, Vec3};
use picker_render::EnvMap;
use picker_tensor::Rng;
use serde::Serialize;

use crate::assets::AssetLibrary;
use crate::geometry::{nearest, Aabb, Shape};
use crate::sky::{random_sky, SkyInfo};
use crate::textures::{random_texture, Texture, TextureInfo};
use crate::Result;

/// Sizes a scene is generated at.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SceneConfig {
    /// Image height in pixels.
    pub height: usize,
    /// Image width in pixels.
    pub width: usize,
    /// Side of every material's square texture, in texels.
    pub texture_size: usize,
    /// Sky (world-frame environment map) height; its width is twice that.
    pub sky_height: usize,
    /// Which camera views are drawn.
    pub views: Views,
}

/// The distribution of camera views a scene is drawn from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Views {
    /// Eye-level views into the room: pitch ±20°, roll ±3°, field of view
    /// 40–75°, no surface nearer than 1.2 m straight ahead (every dataset
    /// made before the option existed; the same draws, so old seeds make the
    /// same scenes).
    #[default]
    Room,
    /// Half [`View::Room`] views, a quarter looking down ([`View::Down`]:
    /// pitch −80…−30°, at a floor or a table top), a quarter close-ups
    /// ([`View::Close`]: a surface 0.3–1.5 m straight ahead); roll ±12° and a
    /// field of view of 30–75° for the latter two. Photos people take to pick
    /// a material look at it from above or from near as often as across a
    /// room.
    Wide,
}

impl Views {
    /// The name `picker synth --views` takes and `scene.json` records.
    pub fn name(self) -> &'static str {
        match self {
            Views::Room => "room",
            Views::Wide => "wide",
        }
    }
}

/// The kind of camera view a scene was drawn with ([`Views`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum View {
    /// Eye level, across the room.
    Room,
    /// Looking down at the floor or a table top.
    Down,
    /// A surface close ahead.
    Close,
}

/// What a [`View`] draws: degrees for the angles, metres for distances.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewBounds {
    /// Pitch range (positive looks up).
    pub pitch: [f32; 2],
    /// Largest roll either way.
    pub roll: f32,
    /// Vertical field-of-view range.
    pub fov: [f32; 2],
    /// No surface nearer than this straight ahead.
    pub free: f32,
    /// Some surface within this straight ahead (close-ups).
    pub reach: Option<f32>,
    /// The heading is any (else towards the room's centre ±75°).
    pub any_heading: bool,
}

impl View {
    /// Its bounds (the one table the generator and its tests read).
    pub fn bounds(self) -> ViewBounds {
        match self {
            View::Room => ViewBounds {
                pitch: [-20.0, 20.0],
                roll: 3.0,
                fov: [40.0, 75.0],
                free: 1.2,
                reach: None,
                any_heading: false,
            },
            View::Down => ViewBounds {
                pitch: [-80.0, -30.0],
                roll: 12.0,
                fov: [30.0, 75.0],
                free: 0.3,
                reach: None,
                any_heading: true,
            },
            View::Close => ViewBounds {
                pitch: [-30.0, 20.0],
                roll: 12.0,
                fov: [30.0, 75.0],
                free: 0.3,
                reach: Some(1.5),
                any_heading: true,
            },
        }
    }

    /// The name `scene.json` records.
    pub fn name(self) -> &'static str {
        match self {
            View::Room => "room",
            View::Down => "down",
            View::Close => "close",
        }
    }
}

impl SceneConfig {
    /// The defaults for an image of `height × width`: textures of 128² texels
    /// (32² below 64 pixels on the long side), a 64 × 128 sky (16 × 32 for tiny images).
    pub fn for_size(height: usize, width: usize) -> Self {
        let tiny = height.max(width) < 64;
        Self {
            height,
            width,
            texture_size: if tiny { 32 } else { 128 },
            sky_height: if tiny { 16 } else { 64 },
            views: Views::Room,
        }
    }
}

/// The seed of scene `index` of a run with seed `seed` (SplitMix64 of both).
pub fn scene_seed(seed: u64, index: u64) -> u64 {
    let mut z = seed ^ index.wrapping_mul(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A pinhole camera.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Camera {
    /// Position (world, metres).
    pub position: Vec3,
    /// Rotation about +y (radians; 0 looks along world −z).
    pub yaw: f32,
    /// Rotation about the camera's x axis (radians; positive looks up).
    pub pitch: f32,
    /// Rotation about the viewing axis (radians).
    pub roll: f32,
    /// Vertical field of view (radians).
    pub fov_y: f32,
    /// Camera-to-world rotation (columns: camera x, y, z axes in world space).
    pub rotation: Mat3,
}

impl Camera {
    /// A camera at `position` with the given angles.
    pub fn new(position: Vec3, yaw: f32, pitch: f32, roll: f32, fov_y: f32) -> Self {
        let rotation =
            Mat3::from_rotation_y(yaw) * Mat3::from_rotation_x(pitch) * Mat3::from_rotation_z(roll);
        Self {
            position,
            yaw,
            pitch,
            roll,
            fov_y,
            rotation,
        }
    }

    /// Camera-space unit direction through the centre of pixel `(row, col)` of an `h × w` image.
    #[inline]
    pub fn pixel_direction(&self, row: usize, col: usize, h: usize, w: usize) -> Vec3 {
        self.image_direction(col as f32 + 0.5, row as f32 + 0.5, h, w)
    }

    /// Camera-space unit direction through the continuous image position `(x, y)`
    /// (pixels, x right, y down, origin at the top-left corner).
    #[inline]
    pub fn image_direction(&self, x: f32, y: f32, h: usize, w: usize) -> Vec3 {
        let tan = (self.fov_y * 0.5).tan();
        let x = (x / w as f32 * 2.0 - 1.0) * tan * w as f32 / h as f32;
        let y = (1.0 - y / h as f32 * 2.0) * tan;
        Vec3::new(x, y, -1.0).normalize()
    }
}

/// A small spherical ceiling lamp (not itself visible in the image).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Lamp {
    /// Centre (world).
    pub position: Vec3,
    /// Radius of the emitting sphere (shadow softness).
    pub radius: f32,
    /// Radiant intensity per colour channel (W/sr, linear RGB, before exposure).
    pub intensity: Vec3,
}

/// A rectangular hole in the room's shell through which the sky is seen and lights the room.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Opening {
    /// Which wall (0: z = 0, 1: z = D, 2: x = 0, 3: x = W).
    pub wall: u8,
    /// Whether the whole wall is missing (an open side) rather than a window or door.
    pub open_side: bool,
    /// Corners (world), in order around the rectangle.
    pub corners: [Vec3; 4],
}

impl Opening {
    /// Area in m².
    pub fn area(&self) -> f32 {
        (self.corners[1] - self.corners[0]).length() * (self.corners[3] - self.corners[0]).length()
    }
    /// The point at `(s, t) ∈ [0,1]²` of the rectangle.
    pub fn point(&self, s: f32, t: f32) -> Vec3 {
        let [a, b, _, d] = self.corners;
        a + (b - a) * s + (d - a) * t
    }
}

/// A material's diffuse part: a tileable texture or one colour.
#[derive(Clone, Debug)]
pub enum Diffuse {
    /// A texture and how it was made.
    Texture(Texture, TextureInfo),
    /// One linear RGB colour.
    Colour(Vec3),
}

/// A material: diffuse texture or colour, specular albedo, glossiness, texture mapping.
#[derive(Clone, Debug)]
pub struct Material {
    /// Material id (1-based; 0 is the sky / no surface).
    pub id: u16,
    /// What it covers (`floor`, `walls`, `box 3` …).
    pub name: String,
    /// Diffuse albedo source.
    pub diffuse: Diffuse,
    /// Specular albedo ρs (linear RGB).
    pub specular: Vec3,
    /// Glossiness g ∈ [0, 1] (Phong exponent 2^(13 g)).
    pub glossiness: f32,
    /// World-space length of one texture repeat (metres).
    pub scale: f32,
    /// Rotation of the texture on planar faces (radians).
    pub rotation: f32,
    /// Texture-space offset.
    pub offset: Vec2,
    /// ρd*: the most frequent diffuse value ([`most_frequent`]).
    pub diffuse_mode: Vec3,
}

impl Material {
    /// Whether the diffuse part is a texture.
    pub fn textured(&self) -> bool {
        matches!(self.diffuse, Diffuse::Texture(..))
    }

    /// Texture coordinates `(u, v)` (unwrapped) of mapping coordinates `c` in metres;
    /// a periodic first coordinate (`period`) gets a whole number of repeats and no rotation.
    #[inline]
    pub fn uv(&self, c: Vec2, period: Option<f32>) -> Vec2 {
        match period {
            Some(p) => {
                let repeats = (p / self.scale).round().max(1.0);
                Vec2::new(c.x / p * repeats, c.y / self.scale) + self.offset
            }
            None => Vec2::from_angle(self.rotation).rotate(c / self.scale) + self.offset,
        }
    }

    /// The segmentation colour `(ρd* + ρs)/2`.
    pub fn segmentation(&self) -> Vec3 {
        (self.diffuse_mode + self.specular) * 0.5
    }
}

/// ρd*, "the most frequent diffuse value" of a texture: texels are quantised to
/// 16 levels per channel of their sRGB encoding (4096 bins); the fullest bin wins
/// (ties: the lowest bin index) and ρd* is the mean linear colour of its texels.
pub fn most_frequent(data: &[Vec3]) -> Vec3 {
    let bin = |c: Vec3| {
        let q = |v: f32| ((picker_nets::conventions::srgb_encode(v) * 16.0) as usize).min(15);
        q(c.x) * 256 + q(c.y) * 16 + q(c.z)
    };
    let mut counts = vec![0u32; 4096];
    for &c in data {
        counts[bin(c)] += 1;
    }
    let mut best = 0;
    for (i, &n) in counts.iter().enumerate() {
        if n > counts[best] {
            best = i;
        }
    }
    let (mut sum, mut n) = (glam::DVec3::ZERO, 0u32);
    for &c in data {
        if bin(c) == best {
            sum += c.as_dvec3();
            n += 1;
        }
    }
    if n == 0 {
        Vec3::ZERO
    } else {
        (sum / n as f64).as_vec3()
    }
}

/// A primitive with its material.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Primitive {
    /// Geometry.
    pub shape: Shape,
    /// Index into [`Scene::materials`].
    pub material: usize,
    /// Whether it belongs to the room's shell (floor, ceiling, walls).
    pub shell: bool,
}

/// A generated scene.
pub struct Scene {
    /// Run seed.
    pub seed: u64,
    /// Scene index within the run.
    pub index: u64,
    /// Sizes.
    pub config: SceneConfig,
    /// Room size (W, H, D) in metres.
    pub room: Vec3,
    /// Primitives: the shell first, then the furniture.
    pub primitives: Vec<Primitive>,
    /// Just the shapes of [`Scene::primitives`] (ray casting).
    pub shapes: Vec<Shape>,
    /// Shapes of the furniture only: the shell is convex, so it never blocks a
    /// segment between two points inside the room (shadow rays test these only).
    pub occluders: Vec<Shape>,
    /// Each furniture object's bounding box and its range in [`Scene::occluders`]
    /// (shadow rays test the box first).
    pub occluder_groups: Vec<(Aabb, std::ops::Range<usize>)>,
    /// Materials (index `i` has id `i + 1`).
    pub materials: Vec<Material>,
    /// Openings in the shell.
    pub openings: Vec<Opening>,
    /// Ceiling lamps.
    pub lamps: Vec<Lamp>,
    /// Camera.
    pub camera: Camera,
    /// The kind of view the camera was drawn as.
    pub view: View,
    /// Sky, world frame (centre column = world −z).
    pub sky: EnvMap,
    /// How the sky was made.
    pub sky_info: SkyInfo,
    /// Furniture objects as placed (kind and bounding box), for `scene.json`.
    pub objects: Vec<(String, Aabb)>,
}

fn uniform(rng: &mut Rng, lo: f32, hi: f32) -> f32 {
    if hi <= lo {
        lo
    } else {
        rng.uniform(lo, hi)
    }
}

fn chance(rng: &mut Rng, p: f64) -> bool {
    rng.f64() < p
}

/// A random material named `name`.
fn random_material(
    rng: &mut Rng,
    id: u16,
    name: String,
    size: usize,
    assets: Option<&AssetLibrary>,
) -> Result<Material> {
    let diffuse = if chance(rng, 0.7) {
        let (t, info) = random_texture(rng, size, assets)?;
        Diffuse::Texture(t, info)
    } else {
        // A colour with a random hue, saturation and lightness, picked in sRGB.
        let h = uniform(rng, 0.0, 1.0);
        let s = uniform(rng, 0.0, 0.8);
        let l = uniform(rng, 0.15, 0.9);
        let rgb = Vec3::new(h, h + 2.0 / 3.0, h + 1.0 / 3.0).map(|x| {
            let k = ((x * 6.0) % 6.0 - 3.0).abs() - 1.0;
            l * (1.0 - s + s * k.clamp(0.0, 1.0))
        });
        Diffuse::Colour(rgb.map(picker_render::io::srgb_decode))
    };
    let specular = if chance(rng, 0.1) {
        Vec3::ZERO
    } else if chance(rng, 0.85) {
        Vec3::splat(0.3 * uniform(rng, 0.0, 1.0).powi(2))
    } else {
        Vec3::new(
            uniform(rng, 0.05, 0.5),
            uniform(rng, 0.05, 0.5),
            uniform(rng, 0.05, 0.5),
        )
    };
    let glossiness = uniform(rng, 0.1, 0.85);
    let scale = uniform(rng, 0.3, 2.0);
    let rotation = if chance(rng, 0.5) {
        0.0
    } else {
        uniform(rng, 0.0, std::f32::consts::TAU)
    };
    let offset = Vec2::new(uniform(rng, 0.0, 1.0), uniform(rng, 0.0, 1.0));
    let diffuse_mode = match &diffuse {
        Diffuse::Texture(t, _) => most_frequent(&t.data),
        Diffuse::Colour(c) => *c,
    };
    Ok(Material {
        id,
        name,
        diffuse,
        specular,
        glossiness,
        scale,
        rotation,
        offset,
        diffuse_mode,
    })
}

/// Wall `i` of a `w × d` room: (axis, position, inward normal sign, length along the wall).
fn wall(i: u8, room: Vec3) -> (u8, f32, f32, f32) {
    match i {
        0 => (2, 0.0, 1.0, room.x),
        1 => (2, room.z, -1.0, room.x),
        2 => (0, 0.0, 1.0, room.z),
        _ => (0, room.x, -1.0, room.z),
    }
}

/// A world point on wall `i` at distance `a` along it and height `y`.
fn wall_point(i: u8, room: Vec3, a: f32, y: f32) -> Vec3 {
    match i {
        0 => Vec3::new(a, y, 0.0),
        1 => Vec3::new(a, y, room.z),
        2 => Vec3::new(0.0, y, a),
        _ => Vec3::new(room.x, y, a),
    }
}

/// Generates scene `index` of the run with seed `seed`.
pub fn generate(
    seed: u64,
    index: u64,
    config: SceneConfig,
    assets: Option<&AssetLibrary>,
) -> Result<Scene> {
    let mut rng = Rng::new(scene_seed(seed, index));
    let rng = &mut rng;
    let room = Vec3::new(
        uniform(rng, 3.0, 8.0),
        uniform(rng, 2.4, 3.5),
        uniform(rng, 3.0, 8.0),
    );
    let tex = config.texture_size;

    let mut materials = vec![
        random_material(rng, 1, "floor".into(), tex, assets)?,
        random_material(rng, 2, "ceiling".into(), tex, assets)?,
        random_material(rng, 3, "walls".into(), tex, assets)?,
    ];
    let mut primitives = Vec::new();
    let rect = |axis: u8, pos: f32, lo: [f32; 2], hi: [f32; 2], normal_sign: f32| Shape::Rect {
        axis,
        pos,
        lo,
        hi,
        normal_sign,
    };
    primitives.push(Primitive {
        shape: rect(1, 0.0, [0.0, 0.0], [room.x, room.z], 1.0),
        material: 0,
        shell: true,
    });
    primitives.push(Primitive {
        shape: rect(1, room.y, [0.0, 0.0], [room.x, room.z], -1.0),
        material: 1,
        shell: true,
    });

    // Walls: at most one open side; one window or door per other wall with
    // probability one half; at least one opening in all.
    let open_side = if chance(rng, 0.15) {
        Some(rng.range(0, 3) as u8)
    } else {
        None
    };
    let mut windows = [false; 4];
    for w in &mut windows {
        *w = chance(rng, 0.5);
    }
    if open_side.is_none() && !windows.iter().any(|&w| w) {
        windows[rng.range(0, 3)] = true;
    }
    let mut openings = Vec::new();
    for i in 0..4u8 {
        let (axis, pos, sign, len) = wall(i, room);
        if open_side == Some(i) {
            openings.push(Opening {
                wall: i,
                open_side: true,
                corners: [
                    wall_point(i, room, 0.0, 0.0),
                    wall_point(i, room, len, 0.0),
                    wall_point(i, room, len, room.y),
                    wall_point(i, room, 0.0, room.y),
                ],
            });
            continue;
        }
        let mut panels = Vec::new();
        if windows[i as usize] {
            let width = uniform(rng, 0.6, (len - 0.6).min(2.5));
            let centre = uniform(rng, 0.3 + width / 2.0, len - 0.3 - width / 2.0);
            let (sill, top) = if chance(rng, 0.2) {
                (0.0, (room.y - 0.1).min(uniform(rng, 2.0, 2.3)))
            } else {
                let sill = uniform(rng, 0.3, 1.0);
                (sill, (sill + uniform(rng, 0.8, 1.8)).min(room.y - 0.15))
            };
            let (a0, a1) = (centre - width / 2.0, centre + width / 2.0);
            panels.push(([0.0, 0.0], [a0, room.y]));
            panels.push(([a1, 0.0], [len, room.y]));
            if sill > 0.0 {
                panels.push(([a0, 0.0], [a1, sill]));
            }
            panels.push(([a0, top], [a1, room.y]));
            openings.push(Opening {
                wall: i,
                open_side: false,
                corners: [
                    wall_point(i, room, a0, sill),
                    wall_point(i, room, a1, sill),
                    wall_point(i, room, a1, top),
                    wall_point(i, room, a0, top),
                ],
            });
        } else {
            panels.push(([0.0, 0.0], [len, room.y]));
        }
        for (lo, hi) in panels {
            primitives.push(Primitive {
                shape: rect(axis, pos, lo, hi, sign),
                material: 2,
                shell: true,
            });
        }
    }
    let shell_count = primitives.len();

    // Furniture.
    let wanted = rng.range(2, 10);
    let mut objects: Vec<(String, Aabb, bool)> = Vec::new(); // (kind, box, can support)
    let mut tries = 0;
    let mut groups = Vec::new();
    while objects.len() < wanted && tries < 60 {
        tries += 1;
        let kind = match rng.range(0, 19) {
            0..=6 => "box",
            7..=11 => "table",
            12..=15 => "cylinder",
            _ => "sphere",
        };
        let (sx, sy, sz) = match kind {
            "box" => {
                let tall = chance(rng, 0.2);
                (
                    uniform(rng, 0.3, 1.5),
                    if tall {
                        uniform(rng, 1.2, 2.0)
                    } else {
                        uniform(rng, 0.3, 1.0)
                    },
                    uniform(rng, 0.3, 1.2),
                )
            }
            "table" => (
                uniform(rng, 0.8, 2.0),
                uniform(rng, 0.45, 0.8),
                uniform(rng, 0.5, 1.2),
            ),
            "cylinder" => {
                let r = uniform(rng, 0.1, 0.4);
                (2.0 * r, uniform(rng, 0.2, 1.2), 2.0 * r)
            }
            _ => {
                let r = uniform(rng, 0.1, 0.4);
                (2.0 * r, 2.0 * r, 2.0 * r)
            }
        };
        // Stand on the floor, or on top of an earlier box (not a table: things under it).
        let supports: Vec<usize> = objects
            .iter()
            .enumerate()
            .filter(|(_, (_, b, s))| *s && b.max.x - b.min.x >= sx && b.max.z - b.min.z >= sz)
            .map(|(i, _)| i)
            .collect();
        let support = if !supports.is_empty() && chance(rng, 0.35) {
            Some(supports[rng.range(0, supports.len() - 1)])
        } else {
            None
        };
        let (lo, hi, y0) = match support {
            Some(s) => {
                let b = objects[s].1;
                (
                    Vec2::new(b.min.x, b.min.z),
                    Vec2::new(b.max.x - sx, b.max.z - sz),
                    b.max.y,
                )
            }
            None => (
                Vec2::splat(0.05),
                Vec2::new(room.x - sx - 0.05, room.z - sz - 0.05),
                0.0,
            ),
        };
        if hi.x < lo.x || hi.y < lo.y || y0 + sy > room.y - 0.6 {
            continue;
        }
        let x0 = uniform(rng, lo.x, hi.x);
        let z0 = uniform(rng, lo.y, hi.y);
        let bb = Aabb {
            min: Vec3::new(x0, y0, z0),
            max: Vec3::new(x0 + sx, y0 + sy, z0 + sz),
        };
        let clash = objects.iter().enumerate().any(|(i, (_, o, _))| {
            let margin = if Some(i) == support { 0.0 } else { 0.02 };
            bb.overlaps(o, margin)
        });
        if clash {
            continue;
        }
        let m = materials.len();
        let first = primitives.len();
        let name = format!("{kind} {}", objects.len() + 1);
        materials.push(random_material(rng, m as u16 + 1, name, tex, assets)?);
        let mut add = |shape| {
            primitives.push(Primitive {
                shape,
                material: m,
                shell: false,
            })
        };
        match kind {
            "box" => add(Shape::Cuboid {
                min: bb.min,
                max: bb.max,
            }),
            "table" => {
                let top = uniform(rng, 0.03, 0.06);
                let leg = uniform(rng, 0.04, 0.08);
                add(Shape::Cuboid {
                    min: Vec3::new(bb.min.x, bb.max.y - top, bb.min.z),
                    max: bb.max,
                });
                for (fx, fz) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
                    let x = bb.min.x + fx * (sx - leg);
                    let z = bb.min.z + fz * (sz - leg);
                    add(Shape::Cuboid {
                        min: Vec3::new(x, bb.min.y, z),
                        max: Vec3::new(x + leg, bb.max.y - top, z + leg),
                    });
                }
            }
            "cylinder" => add(Shape::Cylinder {
                base: Vec3::new(x0 + sx / 2.0, y0, z0 + sz / 2.0),
                radius: sx / 2.0,
                height: sy,
            }),
            _ => add(Shape::Sphere {
                center: bb.min + Vec3::splat(sx / 2.0),
                radius: sx / 2.0,
            }),
        }
        groups.push((bb, first - shell_count..primitives.len() - shell_count));
        objects.push((kind.to_string(), bb, kind == "box"));
    }

    let shapes: Vec<Shape> = primitives.iter().map(|p| p.shape).collect();
    let occluders = shapes[shell_count..].to_vec();

    // Camera: inside the room, clear of every object by 0.4 m (so the near plane never
    // clips), and not staring at a surface closer than 1.2 m.
    let clearance = 0.4;
    // The view kind: drawn only for `Views::Wide`, so `Room` makes the draws it always made.
    let view = match config.views {
        Views::Room => View::Room,
        Views::Wide => {
            let u = rng.f64();
            if u < 0.5 {
                View::Room
            } else if u < 0.75 {
                View::Down
            } else {
                View::Close
            }
        }
    };
    let mut camera = None;
    for _ in 0..500 {
        let p = Vec3::new(
            uniform(rng, clearance, room.x - clearance),
            uniform(rng, 1.0, 2.0f32.min(room.y - clearance)),
            uniform(rng, clearance, room.z - clearance),
        );
        // Look roughly towards the room's centre (±75°) so most views show the room.
        let to_centre = Vec3::new(room.x / 2.0, p.y, room.z / 2.0) - p;
        let yaw = (-to_centre.x).atan2(-to_centre.z) + uniform(rng, -75.0, 75.0).to_radians();
        let b = view.bounds();
        // Drawn in this order (pitch, roll, field of view; then any heading), so room views make
        // the draws they always made.
        let pitch = uniform(rng, b.pitch[0], b.pitch[1]).to_radians();
        let roll = uniform(rng, -b.roll, b.roll).to_radians();
        let fov = uniform(rng, b.fov[0], b.fov[1]).to_radians();
        // Down and close views look any way (a wall close ahead is one the room's centre is behind).
        let yaw = if b.any_heading {
            uniform(rng, -180.0, 180.0).to_radians()
        } else {
            yaw
        };
        if objects.iter().any(|(_, b, _)| b.distance(p) < clearance) {
            continue;
        }
        let cam = Camera::new(p, yaw, pitch, roll, fov);
        let forward = cam.rotation * Vec3::NEG_Z;
        if nearest(&shapes, p, forward, 0.0, b.free).is_some() {
            continue;
        }
        if b.reach
            .is_some_and(|r| nearest(&shapes, p, forward, b.free, r).is_none())
        {
            continue;
        }
        camera = Some(cam);
        break;
    }
    // Every draw failed (a crowded room; a close-up with nothing in reach): an eye-level view.
    let view = if camera.is_some() { view } else { View::Room };
    // Take the point of a grid at 1.5 m height
    // farthest from all objects, looking horizontally along the room's longer side.
    let camera = camera.unwrap_or_else(|| {
        let mut best = (
            f32::NEG_INFINITY,
            Vec3::new(room.x / 2.0, 1.5, room.z / 2.0),
        );
        for i in 0..=10 {
            for j in 0..=10 {
                let p = Vec3::new(
                    clearance + (room.x - 2.0 * clearance) * i as f32 / 10.0,
                    1.5f32.min(room.y - clearance),
                    clearance + (room.z - 2.0 * clearance) * j as f32 / 10.0,
                );
                let d = objects
                    .iter()
                    .map(|(_, b, _)| b.distance(p))
                    .fold(f32::INFINITY, f32::min);
                if d > best.0 {
                    best = (d, p);
                }
            }
        }
        let yaw = if room.x > room.z {
            std::f32::consts::FRAC_PI_2
        } else {
            0.0
        };
        Camera::new(best.1, yaw, 0.0, 0.0, 60f32.to_radians())
    });

    // Lamps under the ceiling.
    let n_lamps = rng.range(1, 3);
    let mut lamps = Vec::new();
    for _ in 0..n_lamps {
        let position = Vec3::new(
            uniform(rng, 0.5, room.x - 0.5),
            room.y - uniform(rng, 0.15, 0.45),
            uniform(rng, 0.5, room.z - 0.5),
        );
        let colour = Vec3::new(1.0, uniform(rng, 0.8, 0.95), uniform(rng, 0.6, 0.9));
        lamps.push(Lamp {
            position,
            radius: uniform(rng, 0.03, 0.15),
            intensity: colour,
        });
    }

    let (sky, sky_info) = random_sky(rng, 2 * config.sky_height, config.sky_height, assets)?;

    // Lamp strength relative to the daylight entering through the openings: the
    // lamps' total flux 4π·I is a random factor (0.3–3, log-uniform) times the
    // flux through the openings (area × π × mean sky radiance above the horizon).
    let sky_up = upper_mean_radiance(&sky);
    let opening_area: f32 = openings.iter().map(Opening::area).sum();
    let daylight = opening_area * std::f32::consts::PI * sky_up.dot(Vec3::splat(1.0 / 3.0));
    let ratio = uniform(rng, 0.3f32.ln(), 3.0f32.ln()).exp();
    let per_lamp = ratio * daylight.max(1e-3) / (4.0 * std::f32::consts::PI * lamps.len() as f32);
    for l in &mut lamps {
        l.intensity *= per_lamp;
    }

    Ok(Scene {
        seed,
        index,
        config,
        room,
        primitives,
        shapes,
        occluders,
        occluder_groups: groups,
        materials,
        openings,
        lamps,
        camera,
        view,
        sky,
        sky_info,
        objects: objects.into_iter().map(|(k, b, _)| (k, b)).collect(),
    })
}

/// Mean radiance of the upper hemisphere of an environment map (solid-angle weighted).
pub fn upper_mean_radiance(env: &EnvMap) -> Vec3 {
    let (h, w) = (env.height(), env.width());
    let mut sum = glam::DVec3::ZERO;
    let mut omega = 0.0;
    for row in 0..h / 2 {
        let s = picker_nets::conventions::pixel_solid_angle(row, h, w);
        for col in 0..w {
            sum += env.get(row, col).as_dvec3() * s;
            omega += s;
        }
    }
    if omega > 0.0 {
        (sum / omega).as_vec3()
    } else {
        Vec3::ZERO
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn most_frequent_is_the_fullest_bin() {
        let a = Vec3::new(0.5, 0.2, 0.1);
        let b = Vec3::new(0.05, 0.6, 0.9);
        let mut data = vec![a; 60];
        data.extend(vec![b; 40]);
        // Slightly different values in the same bin average together.
        data[0] = a * 1.001;
        let m = most_frequent(&data);
        assert!((m - a).length() < 1e-3, "{m}");
        assert_eq!(most_frequent(&[b]), b);
        assert_eq!(most_frequent(&[]), Vec3::ZERO);
    }

    #[test]
    fn scene_seeds_differ() {
        assert_ne!(scene_seed(1, 0), scene_seed(1, 1));
        assert_ne!(scene_seed(1, 0), scene_seed(2, 0));
        assert_eq!(scene_seed(7, 3), scene_seed(7, 3));
    }

    #[test]
    fn camera_axes() {
        let c = Camera::new(Vec3::ZERO, 0.0, 0.0, 0.0, 1.0);
        let d = c.pixel_direction(1, 1, 3, 3);
        assert!((d - Vec3::NEG_Z).length() < 1e-6);
        // Top-left pixel looks up and left.
        let d = c.pixel_direction(0, 0, 3, 3);
        assert!(d.x < 0.0 && d.y > 0.0);
        // Yaw π/2 turns −z towards −x.
        let c = Camera::new(Vec3::ZERO, std::f32::consts::FRAC_PI_2, 0.0, 0.0, 1.0);
        assert!((c.rotation * Vec3::NEG_Z - Vec3::NEG_X).length() < 1e-6);
    }
}
