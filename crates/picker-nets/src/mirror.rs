//! Test-time mirror averaging: a network run on the photo and on its
//! left–right mirror image, the outputs that follow the mirror averaged.
//!
//! An indoor scene mirrored left to right is as plausible a scene as the
//! original, so a network trained on such scenes gives, for the mirrored
//! photo, a second estimate of every output that mirrors with the image: the
//! albedos, the glossiness and the segmentation mirrored back, the normals and
//! view vectors mirrored back with their x component negated (camera space,
//! +x right), the environment map mirrored in longitude (`φ → −φ` is column
//! `j → W − 1 − j`, [`crate::conventions`]). The two estimates' errors are
//! partly independent, and their mean is the better estimate: with the
//! embedded `lite` networks, over three sets of 40 synthetic scenes, the
//! albedo error fell on every set (RMSE 0.1268 → 0.1253, 0.1169 → 0.1156,
//! 0.1150 → 0.1141) and so did the normals' (27.61° → 26.78°, 24.46° →
//! 23.92°, 26.57° → 25.91°); see the README's `picker extract`.
//!
//! Not every output has a mirror relation ([`MirrorRule::Keep`]): texture
//! coordinates (a mirrored texture is another texture: its UVs are not the
//! original's mirrored), the MSN's material embedding (a learned space in
//! which only distances mean anything; the mean of the two passes' points
//! moved the mask IoU by −0.0045, −0.0011 and +0.0015 on three sets: no
//! gain) and any output this module does not know keep the first pass's
//! values.

use crate::config::NetKind;
use crate::conventions as conv;
use crate::error::{Error, Result};
use crate::nets::{EnvMapOutput, IrnOutput, MsnOutput, NetOutput};
use picker_tensor::Tensor;

/// How one network output follows a left–right mirror of the input.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MirrorRule {
    /// The output mirrors with the image: the mean of the first pass and the
    /// second pass mirrored back (raw values; their decodings are linear).
    Mean,
    /// A camera-space direction field (raw values, renormalised when
    /// decoded): as [`MirrorRule::Mean`] with the second pass's x component
    /// (channel 0) negated.
    MeanDirection,
    /// The EnvMap's radiance (raw values in its log encoding): the mean of
    /// the decoded radiances, the second pass mirrored back, encoded again, so
    /// that the mean keeps the light's energy.
    MeanRadiance,
    /// No mirror relation: the first pass's values.
    Keep,
}

/// The rule for output `name` of a `kind` network.
pub fn rule(kind: NetKind, name: &str) -> MirrorRule {
    match (kind, name) {
        (NetKind::Irn, conv::DIFFUSE_ALBEDO | conv::SPECULAR_ALBEDO | conv::GLOSSINESS) => {
            MirrorRule::Mean
        }
        (NetKind::Irn, conv::NORMALS | conv::VIEW_VECTOR) => MirrorRule::MeanDirection,
        (NetKind::Msn, conv::SEGMENTATION) => MirrorRule::Mean,
        (NetKind::EnvMap, conv::ENVMAP) => MirrorRule::MeanRadiance,
        _ => MirrorRule::Keep,
    }
}

/// Output `name`'s first-pass values `a` merged with `mirrored`, the same
/// output of the network run on the input mirrored left to right
/// ([`Tensor::mirror_w`]), by `rule`.
///
/// # Errors
/// [`Error::Output`] when the two tensors' shapes differ, or a direction
/// field has fewer than 3 channels.
pub fn merge(name: &str, rule: MirrorRule, a: Tensor, mirrored: &Tensor) -> Result<Tensor> {
    if a.shape() != mirrored.shape() {
        return Err(Error::Output {
            name: name.to_string(),
            reason: format!(
                "the mirrored pass gave shape {:?}, the first {:?}",
                mirrored.shape(),
                a.shape()
            ),
        });
    }
    let [n, c, h, w] = a.shape();
    if rule == MirrorRule::MeanDirection && c < 3 {
        return Err(Error::Output {
            name: name.to_string(),
            reason: format!("a direction field needs 3 channels, it has {c}"),
        });
    }
    if rule == MirrorRule::Keep {
        return Ok(a);
    }
    let back = mirrored.mirror_w();
    let mut out = a;
    let hw = h * w;
    for ni in 0..n {
        for ci in 0..c {
            let o = (ni * c + ci) * hw;
            let sign = if rule == MirrorRule::MeanDirection && ci == 0 {
                -1.0
            } else {
                1.0
            };
            let b = &back.data()[o..o + hw];
            for (v, &m) in out.data_mut()[o..o + hw].iter_mut().zip(b) {
                *v = match rule {
                    MirrorRule::MeanRadiance => conv::encode_radiance(
                        0.5 * (conv::decode_radiance(*v) + conv::decode_radiance(m)),
                    ),
                    _ => 0.5 * (*v + sign * m),
                };
            }
        }
    }
    Ok(out)
}

/// Merges every `(name, tensor)` of `a` with the same output of `mirrored`
/// by its [`rule`] for `kind`.
fn merge_all(
    kind: NetKind,
    a: Vec<(String, Tensor)>,
    mirrored: &[(String, Tensor)],
) -> Result<Vec<(String, Tensor)>> {
    a.into_iter()
        .map(|(name, t)| {
            let r = rule(kind, &name);
            if r == MirrorRule::Keep {
                return Ok((name, t));
            }
            let m = mirrored
                .iter()
                .find(|(n, _)| *n == name)
                .map(|(_, m)| m)
                .ok_or_else(|| Error::Output {
                    name: name.clone(),
                    reason: "the mirrored pass has no such output".into(),
                })?;
            let t = merge(&name, r, t, m)?;
            Ok((name, t))
        })
        .collect()
}

/// A network's outputs that can take in those of a second pass on the input
/// mirrored left to right.
pub trait MergeMirrored: Sized {
    /// These outputs merged with `mirrored`, the same network's outputs for
    /// the input mirrored left to right ([`Tensor::mirror_w`]), each output by
    /// its [`rule`].
    ///
    /// # Errors
    /// As [`merge`]; or when `mirrored` lacks an output that is merged, or
    /// comes from another network.
    fn merge_mirrored(self, mirrored: &Self) -> Result<Self>;
}

/// `forward(x)`, and, when `mirrored` (the input mirrored left to right) is
/// given, `forward(mirrored)` merged into it ([`MergeMirrored`]).
///
/// # Errors
/// Those of `forward` and of the merge.
pub fn forward_mirrored<T: MergeMirrored>(
    x: &Tensor,
    mirrored: Option<&Tensor>,
    forward: impl Fn(&Tensor) -> Result<T>,
) -> Result<T> {
    let out = forward(x)?;
    match mirrored {
        Some(xm) => out.merge_mirrored(&forward(xm)?),
        None => Ok(out),
    }
}

impl crate::nets::Irn {
    /// [`forward_mirrored`] for the IRN, whose mirrored pass runs only the
    /// heads that are merged ([`Irn::forward_heads`](crate::nets::Irn::forward_heads):
    /// the texture coordinates' tower, whose second output would be thrown
    /// away, is not run).
    ///
    /// # Errors
    /// Those of the passes and of the merge.
    pub fn forward_mirrored(&self, x: &Tensor, mirrored: Option<&Tensor>) -> Result<IrnOutput> {
        Ok(self.forward_mirrored_measured(x, mirrored)?.0)
    }
}

/// How far the IRN's two passes disagree at each pixel: a measure of how
/// sure the network is, which the mean of the passes does not show.
#[derive(Clone, Debug)]
pub struct IrnDisagreement {
    /// `[N, 1, H, W]`: the mean over the channels of `|ρd₁ − ρd₂|`, the
    /// decoded diffuse albedos (linear) of the first pass and of the second
    /// mirrored back.
    pub albedo: Tensor,
    /// `[N, 1, H, W]`: the angle in degrees between the decoded normals of
    /// the first pass and of the second mirrored back (its x negated); 0
    /// where either is zero.
    pub normals_deg: Tensor,
}

/// The disagreement of the IRN's first pass `first` and its pass on the
/// mirrored input `mirrored` ([`IrnDisagreement`]); `None` when either lacks
/// the diffuse albedo or the normals.
///
/// # Errors
/// [`Error::Output`] when the two passes' heads differ in shape, or a head
/// has other than 3 channels.
pub fn irn_disagreement(
    first: &IrnOutput,
    mirrored: &IrnOutput,
) -> Result<Option<IrnDisagreement>> {
    fn heads(o: &IrnOutput) -> Option<(&Tensor, &Tensor)> {
        o.get(conv::DIFFUSE_ALBEDO).zip(o.get(conv::NORMALS))
    }
    let (Some((a1, n1)), Some((a2, n2))) = (heads(first), heads(mirrored)) else {
        return Ok(None);
    };
    for (name, p, q) in [(conv::DIFFUSE_ALBEDO, a1, a2), (conv::NORMALS, n1, n2)] {
        if p.shape() != q.shape() || p.c() != 3 {
            return Err(Error::Output {
                name: name.to_string(),
                reason: format!(
                    "the passes' shapes {:?} and {:?} (3 channels needed)",
                    p.shape(),
                    q.shape()
                ),
            });
        }
    }
    if a1.shape() != n1.shape() {
        return Err(Error::Output {
            name: conv::NORMALS.to_string(),
            reason: format!("shape {:?}, the albedo's {:?}", n1.shape(), a1.shape()),
        });
    }
    let (a2, n2) = (a2.mirror_w(), n2.mirror_w());
    let [n, _, h, w] = a1.shape();
    let hw = h * w;
    let mut albedo = Tensor::zeros([n, 1, h, w]);
    let mut normals_deg = Tensor::zeros([n, 1, h, w]);
    for ni in 0..n {
        let o = ni * 3 * hw;
        let (p, q) = (&a1.data()[o..o + 3 * hw], &a2.data()[o..o + 3 * hw]);
        let (u, v) = (&n1.data()[o..o + 3 * hw], &n2.data()[o..o + 3 * hw]);
        for i in 0..hw {
            let d: f32 = (0..3)
                .map(|c| {
                    (conv::unit_from_tanh(p[c * hw + i]) - conv::unit_from_tanh(q[c * hw + i]))
                        .abs()
                })
                .sum();
            albedo.data_mut()[ni * hw + i] = d / 3.0;
            let a = [u[i], u[hw + i], u[2 * hw + i]];
            let b = [-v[i], v[hw + i], v[2 * hw + i]];
            let (la, lb) = (
                a.iter().map(|x| x * x).sum::<f32>().sqrt(),
                b.iter().map(|x| x * x).sum::<f32>().sqrt(),
            );
            normals_deg.data_mut()[ni * hw + i] = if la > 0.0 && lb > 0.0 {
                let dot: f32 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
                (dot / (la * lb)).clamp(-1.0, 1.0).acos().to_degrees()
            } else {
                0.0
            };
        }
    }
    Ok(Some(IrnDisagreement {
        albedo,
        normals_deg,
    }))
}

impl crate::nets::Irn {
    /// As [`Irn::forward_mirrored`](crate::nets::Irn::forward_mirrored),
    /// also giving the two passes' disagreement ([`irn_disagreement`];
    /// `None` without a mirrored input, or without the heads it reads).
    ///
    /// # Errors
    /// Those of the passes, of the merge and of [`irn_disagreement`].
    pub fn forward_mirrored_measured(
        &self,
        x: &Tensor,
        mirrored: Option<&Tensor>,
    ) -> Result<(IrnOutput, Option<IrnDisagreement>)> {
        let out = self.forward(x)?;
        match mirrored {
            Some(xm) => {
                let merged = |n: &str| rule(NetKind::Irn, n) != MirrorRule::Keep;
                let second = self.forward_heads(xm, merged)?;
                let dis = irn_disagreement(&out, &second)?;
                Ok((out.merge_mirrored(&second)?, dis))
            }
            None => Ok((out, None)),
        }
    }
}

/// The IRN: head by head ([`rule`]; the texture coordinates and unknown
/// heads are kept).
impl MergeMirrored for IrnOutput {
    fn merge_mirrored(self, mirrored: &IrnOutput) -> Result<IrnOutput> {
        Ok(IrnOutput {
            heads: merge_all(NetKind::Irn, self.heads, &mirrored.heads)?,
        })
    }
}

/// The MSN: the segmentation averaged, the material embedding kept
/// ([`rule`]).
impl MergeMirrored for MsnOutput {
    fn merge_mirrored(self, mirrored: &MsnOutput) -> Result<MsnOutput> {
        Ok(MsnOutput {
            segmentation: merge(
                conv::SEGMENTATION,
                rule(NetKind::Msn, conv::SEGMENTATION),
                self.segmentation,
                &mirrored.segmentation,
            )?,
            embedding: self.embedding,
        })
    }
}

/// The EnvMap: the mean radiance, the second pass mirrored back in
/// longitude ([`MirrorRule::MeanRadiance`]).
impl MergeMirrored for EnvMapOutput {
    fn merge_mirrored(self, mirrored: &EnvMapOutput) -> Result<EnvMapOutput> {
        Ok(EnvMapOutput {
            envmap: merge(
                conv::ENVMAP,
                MirrorRule::MeanRadiance,
                self.envmap,
                &mirrored.envmap,
            )?,
        })
    }
}

/// Any network's outputs, each by its [`rule`] for the network.
impl MergeMirrored for NetOutput {
    fn merge_mirrored(self, mirrored: &NetOutput) -> Result<NetOutput> {
        if self.kind != mirrored.kind {
            return Err(Error::Output {
                name: format!("{}", self.kind),
                reason: format!("the mirrored pass came from a {} network", mirrored.kind),
            });
        }
        Ok(NetOutput {
            kind: self.kind,
            tensors: merge_all(self.kind, self.tensors, &mirrored.tensors)?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use picker_tensor::Rng;

    fn random(rng: &mut Rng, shape: [usize; 4]) -> Tensor {
        let len = shape.iter().product();
        let v = rng
            .normal_vec(len, 0.5)
            .into_iter()
            .map(f32::tanh)
            .collect();
        Tensor::new(shape, v).unwrap()
    }

    /// What an exactly mirror-equivariant network gives for the mirrored
    /// input: the output mirrored, a direction field's x negated.
    fn exact_mirror(t: &Tensor, direction: bool) -> Tensor {
        let mut m = t.mirror_w();
        if direction {
            let [n, c, h, w] = m.shape();
            for ni in 0..n {
                let o = ni * c * h * w;
                for v in &mut m.data_mut()[o..o + h * w] {
                    *v = -*v;
                }
            }
        }
        m
    }

    /// An output that mirrors exactly merges to itself under every rule
    /// (the radiance's round trip to float precision), at edge shapes too.
    #[test]
    fn an_exactly_mirrored_pass_changes_nothing() {
        let mut rng = Rng::new(4);
        for shape in [[1, 3, 1, 1], [1, 3, 4, 7], [2, 3, 5, 1], [1, 1, 3, 6]] {
            let a = random(&mut rng, shape);
            for r in [MirrorRule::Mean, MirrorRule::MeanRadiance, MirrorRule::Keep] {
                let out = merge("x", r, a.clone(), &exact_mirror(&a, false)).unwrap();
                let err = out.max_abs_diff(&a).unwrap();
                assert!(err <= 1e-5, "{shape:?} {r:?}: {err}");
            }
            if shape[1] == 3 {
                let m = exact_mirror(&a, true);
                let out = merge("n", MirrorRule::MeanDirection, a.clone(), &m).unwrap();
                assert!(out.max_abs_diff(&a).unwrap() <= 1e-6, "{shape:?}");
            }
        }
    }

    /// The merged values, pixel by pixel, against a plain evaluation of each
    /// rule's formula on seeded random passes.
    #[test]
    fn merges_follow_their_formulas() {
        let mut rng = Rng::new(8);
        let shape = [2, 3, 3, 5];
        let (a, m) = (random(&mut rng, shape), random(&mut rng, shape));
        let [n, c, h, w] = shape;
        for r in [
            MirrorRule::Mean,
            MirrorRule::MeanDirection,
            MirrorRule::MeanRadiance,
            MirrorRule::Keep,
        ] {
            let out = merge("x", r, a.clone(), &m).unwrap();
            for ni in 0..n {
                for ci in 0..c {
                    for y in 0..h {
                        for x in 0..w {
                            let (p, q) = (a.at(ni, ci, y, x), m.at(ni, ci, y, w - 1 - x));
                            let want = match r {
                                MirrorRule::Mean => 0.5 * (p + q),
                                MirrorRule::MeanDirection if ci == 0 => 0.5 * (p - q),
                                MirrorRule::MeanDirection => 0.5 * (p + q),
                                MirrorRule::MeanRadiance => conv::encode_radiance(
                                    0.5 * (conv::decode_radiance(p) + conv::decode_radiance(q)),
                                ),
                                MirrorRule::Keep => p,
                            };
                            let got = out.at(ni, ci, y, x);
                            assert!(
                                (got - want).abs() <= 1e-6,
                                "{r:?} ({ni},{ci},{y},{x}): {got} vs {want}"
                            );
                        }
                    }
                }
            }
        }
    }

    /// Each known output gets its rule; texture coordinates, the embedding
    /// and unknown outputs are kept; the typed merges apply them (the IRN's
    /// UVs and the MSN's embedding are the first pass's, bit for bit).
    #[test]
    fn outputs_get_their_rules() {
        use MirrorRule::*;
        assert_eq!(rule(NetKind::Irn, conv::DIFFUSE_ALBEDO), Mean);
        assert_eq!(rule(NetKind::Irn, conv::SPECULAR_ALBEDO), Mean);
        assert_eq!(rule(NetKind::Irn, conv::GLOSSINESS), Mean);
        assert_eq!(rule(NetKind::Irn, conv::NORMALS), MeanDirection);
        assert_eq!(rule(NetKind::Irn, conv::VIEW_VECTOR), MeanDirection);
        assert_eq!(rule(NetKind::Irn, conv::UV), Keep);
        assert_eq!(rule(NetKind::Irn, "depth"), Keep);
        assert_eq!(rule(NetKind::Msn, conv::SEGMENTATION), Mean);
        assert_eq!(rule(NetKind::Msn, conv::EMBEDDING), Keep);
        assert_eq!(rule(NetKind::EnvMap, conv::ENVMAP), MeanRadiance);
        assert_eq!(rule(NetKind::Msn, conv::DIFFUSE_ALBEDO), Keep);

        let mut rng = Rng::new(2);
        let s = [1, 3, 4, 6];
        let heads = |rng: &mut Rng| {
            vec![
                (conv::DIFFUSE_ALBEDO.to_string(), random(rng, s)),
                (conv::NORMALS.to_string(), random(rng, s)),
                (conv::UV.to_string(), random(rng, s)),
            ]
        };
        let (a, m) = (
            IrnOutput {
                heads: heads(&mut rng),
            },
            IrnOutput {
                heads: heads(&mut rng),
            },
        );
        let out = a.clone().merge_mirrored(&m).unwrap();
        assert!(out.get(conv::UV).unwrap() == a.get(conv::UV).unwrap());
        let albedo = merge(
            conv::DIFFUSE_ALBEDO,
            Mean,
            a.heads[0].1.clone(),
            &m.heads[0].1,
        )
        .unwrap();
        assert!(out.get(conv::DIFFUSE_ALBEDO).unwrap() == &albedo);
        let generic = NetOutput::from(a.clone())
            .merge_mirrored(&NetOutput::from(m.clone()))
            .unwrap();
        assert_eq!(generic.tensors.len(), 3);
        assert!(generic.get(conv::NORMALS).unwrap() == out.get(conv::NORMALS).unwrap());

        let (seg, emb) = (random(&mut rng, s), random(&mut rng, s));
        let msn = MsnOutput {
            segmentation: seg.clone(),
            embedding: Some(emb.clone()),
        };
        let other = MsnOutput {
            segmentation: random(&mut rng, s),
            embedding: Some(random(&mut rng, s)),
        };
        let out = msn.merge_mirrored(&other).unwrap();
        assert!(out.embedding.unwrap() == emb);
        assert!(out.segmentation == merge("s", Mean, seg, &other.segmentation).unwrap());
    }

    /// `forward_mirrored` runs once without a mirrored input, and merges the
    /// second pass by the rules with one: an identity "network" (an MSN whose
    /// segmentation is its input) is mirror-equivariant and gives its input
    /// back; one that weights each column by its index is not, and gives the
    /// mean of the two passes.
    #[test]
    fn forward_mirrored_runs_and_merges_the_two_passes() {
        let mut rng = Rng::new(6);
        let x = random(&mut rng, [1, 3, 4, 5]);
        let calls = std::cell::Cell::new(0);
        let identity = |t: &Tensor| {
            calls.set(calls.get() + 1);
            Ok(NetOutput {
                kind: NetKind::Msn,
                tensors: vec![(conv::SEGMENTATION.to_string(), t.clone())],
            })
        };
        let once = forward_mirrored(&x, None, identity).unwrap();
        assert_eq!(calls.get(), 1);
        assert!(once.get(conv::SEGMENTATION).unwrap() == &x);
        let xm = x.mirror_w();
        let twice = forward_mirrored(&x, Some(&xm), identity).unwrap();
        assert_eq!(calls.get(), 3);
        assert!(
            twice
                .get(conv::SEGMENTATION)
                .unwrap()
                .max_abs_diff(&x)
                .unwrap()
                == 0.0
        );
        let ramp = |t: &Tensor| {
            let mut o = t.clone();
            let w = o.w();
            for (i, v) in o.data_mut().iter_mut().enumerate() {
                *v *= (i % w) as f32;
            }
            Ok(NetOutput {
                kind: NetKind::Msn,
                tensors: vec![(conv::SEGMENTATION.to_string(), o)],
            })
        };
        let merged = forward_mirrored(&x, Some(&xm), ramp).unwrap();
        let (a, b) = (ramp(&x).unwrap(), ramp(&xm).unwrap());
        let want = merge(
            "s",
            MirrorRule::Mean,
            a.tensors[0].1.clone(),
            &b.tensors[0].1,
        )
        .unwrap();
        assert!(merged.get(conv::SEGMENTATION).unwrap() == &want);
    }

    /// The disagreement against its formulas: 0 for an exactly mirrored
    /// pass; the mean absolute difference of the decoded albedos and the
    /// angle between the normals otherwise; `None` without the heads.
    #[test]
    fn the_disagreement_follows_its_formulas() {
        let mut rng = Rng::new(12);
        let s = [1, 3, 3, 4];
        let heads = |a: Tensor, n: Tensor| IrnOutput {
            heads: vec![
                (conv::DIFFUSE_ALBEDO.to_string(), a),
                (conv::NORMALS.to_string(), n),
            ],
        };
        let (a, n) = (random(&mut rng, s), random(&mut rng, s));
        let first = heads(a.clone(), n.clone());
        let exact = heads(exact_mirror(&a, false), exact_mirror(&n, true));
        let d = irn_disagreement(&first, &exact).unwrap().unwrap();
        assert!(d.albedo.data().iter().all(|&v| v == 0.0));
        assert!(
            d.normals_deg.data().iter().all(|&v| v < 0.05),
            "{:?}",
            d.normals_deg.data()
        );
        let (b, m) = (random(&mut rng, s), random(&mut rng, s));
        let d = irn_disagreement(&first, &heads(b.clone(), m.clone()))
            .unwrap()
            .unwrap();
        let (bm, mm) = (b.mirror_w(), m.mirror_w());
        for y in 0..3 {
            for x in 0..4 {
                let want: f32 = (0..3)
                    .map(|c| ((a.at(0, c, y, x) - bm.at(0, c, y, x)) / 2.0).abs())
                    .sum::<f32>()
                    / 3.0;
                assert!((d.albedo.at(0, 0, y, x) - want).abs() < 1e-6);
                let u = [n.at(0, 0, y, x), n.at(0, 1, y, x), n.at(0, 2, y, x)];
                let v = [-mm.at(0, 0, y, x), mm.at(0, 1, y, x), mm.at(0, 2, y, x)];
                let dot = u.iter().zip(&v).map(|(p, q)| f64::from(p * q)).sum::<f64>();
                let l = |w: &[f32; 3]| w.iter().map(|p| f64::from(p * p)).sum::<f64>().sqrt();
                let deg = (dot / (l(&u) * l(&v))).clamp(-1.0, 1.0).acos().to_degrees();
                assert!(
                    (f64::from(d.normals_deg.at(0, 0, y, x)) - deg).abs() < 0.05,
                    "{deg}"
                );
            }
        }
        let no_normals = IrnOutput {
            heads: vec![(conv::DIFFUSE_ALBEDO.to_string(), a.clone())],
        };
        assert!(irn_disagreement(&no_normals, &no_normals)
            .unwrap()
            .is_none());
        let other = heads(
            random(&mut rng, [1, 3, 3, 5]),
            random(&mut rng, [1, 3, 3, 5]),
        );
        assert!(irn_disagreement(&first, &other).is_err());
    }

    /// Mismatched passes are refused with the output's name.
    #[test]
    fn mismatched_passes_are_refused() {
        let mut rng = Rng::new(1);
        let a = random(&mut rng, [1, 3, 4, 4]);
        let b = random(&mut rng, [1, 3, 4, 5]);
        let e = merge("normals", MirrorRule::Mean, a.clone(), &b).unwrap_err();
        assert!(e.to_string().contains("normals"), "{e}");
        let g = random(&mut rng, [1, 1, 4, 4]);
        assert!(merge("n", MirrorRule::MeanDirection, g.clone(), &g).is_err());
        let irn = IrnOutput {
            heads: vec![(conv::NORMALS.to_string(), a.clone())],
        };
        let empty = IrnOutput { heads: vec![] };
        let e = irn.merge_mirrored(&empty).unwrap_err();
        assert!(e.to_string().contains("no such output"), "{e}");
        let env = NetOutput {
            kind: NetKind::EnvMap,
            tensors: vec![],
        };
        let msn = NetOutput {
            kind: NetKind::Msn,
            tensors: vec![],
        };
        assert!(env.merge_mirrored(&msn).is_err());
    }
}
