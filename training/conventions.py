"""How network inputs are encoded and outputs decoded (docs: design.md §2; the Rust side mirrors these).

All network outputs are tanh values y ∈ [-1, 1], channels on axis -3 ([N, C, H, W] or [C, H, W]).

=================  ===========================================================================
input              x = 2·srgb − 1, sRGB values in [0, 1]
inpaint input      [texture planes, mask]: x = 2·srgb − 1 at known texels, 0 at unknown ones; mask plane
                   +1 known, −1 unknown (:func:`inpaint_input`)
inpainted          the whole texture, sRGB (y + 1) / 2 (known texels are kept from the input by callers)
diffuse/specular   linear RGB albedo (y + 1) / 2
glossiness         g = (y + 1) / 2 ∈ [0, 1]; Phong exponent n = 2^(13·g) ∈ [1, 8192]
normals            y renormalised to unit length; camera space: +x right, +y up, +z towards the
                   camera (OpenGL view space); written to images as (n + 1) / 2
view vector        unit vector from the surface point towards the camera, same axes and decoding
uv                 channels (u, v, t), each (y + 1) / 2; u, v wrapped to [0, 1); t = 1 textured,
                   t = 0 single-colour material
segmentation       RGB (y + 1) / 2
environment map    linear HDR radiance L = expm1(ln(1 + 1000) · (y + 1) / 2): y = −1 → 0, y = 1 → 1000
=================  ===========================================================================

The ``encode_*`` functions are the exact inverses, for building training targets.
"""

import math

import torch

GLOSS_EXPONENT_LOG2_MAX = 13.0
"""Phong exponent n = 2^(GLOSS_EXPONENT_LOG2_MAX · g)."""

ENV_RADIANCE_MAX = 1000.0
"""Radiance decoded from y = 1 (y = −1 decodes to 0)."""

_ENV_LOG_SCALE = math.log1p(ENV_RADIANCE_MAX)
_UNIT_EPS = 1e-12


def encode_input(srgb):
    """Network input x = 2·srgb − 1 from sRGB values in [0, 1]."""
    return 2.0 * srgb - 1.0


INPAINT_KNOWN = 1.0
"""Mask-plane value of a known texel in the inpainter's input."""

INPAINT_UNKNOWN = -1.0
"""Mask-plane value of an unknown texel (its texture planes are 0)."""


def inpaint_input(srgb, known):
    """The inpainter's input [N, C + 1, H, W] from sRGB values [N, C, H, W] in [0, 1] and a boolean mask
    ``known`` [H, W] (or broadcastable to [N, 1, H, W]): texture planes 2·srgb − 1 where known, 0 elsewhere;
    then the mask plane, +1 known / −1 unknown."""
    known = torch.as_tensor(known, dtype=torch.bool, device=srgb.device)
    known = known.expand(srgb.shape[0], 1, *srgb.shape[-2:])
    texture = torch.where(known, encode_input(srgb), torch.zeros((), dtype=srgb.dtype))
    mask = torch.where(known, INPAINT_KNOWN, INPAINT_UNKNOWN).to(srgb.dtype)
    return torch.cat([texture, mask], dim=1)


def to_unit(y):
    """Maps y ∈ [-1, 1] to [0, 1]: albedos (linear RGB), glossiness g, segmentation colours."""
    return (y + 1.0) / 2.0


def from_unit(v):
    """Inverse of :func:`to_unit`."""
    return 2.0 * v - 1.0


def phong_exponent(y):
    """Phong exponent n = 2^(13·g) with g = (y + 1) / 2 from the glossiness head."""
    return torch.exp2(GLOSS_EXPONENT_LOG2_MAX * to_unit(y))


def encode_phong_exponent(n):
    """Inverse of :func:`phong_exponent` (n ∈ [1, 8192])."""
    return from_unit(torch.log2(n) / GLOSS_EXPONENT_LOG2_MAX)


def unit_vectors(y):
    """Normals and view vectors: the 3 channels renormalised to unit length (camera space, +z to camera)."""
    return y / torch.linalg.vector_norm(y, dim=-3, keepdim=True).clamp_min(_UNIT_EPS)


def texture_coords(y):
    """(u, v, t) from the uv head: each (y + 1) / 2, with u and v wrapped to [0, 1)."""
    uvt = to_unit(y)
    uv, t = uvt[..., :2, :, :], uvt[..., 2:, :, :]
    return torch.cat([uv - torch.floor(uv), t], dim=-3)


def env_radiance(y):
    """Linear HDR radiance L = expm1(ln(1 + 1000) · (y + 1) / 2) ∈ [0, 1000]."""
    return torch.expm1(_ENV_LOG_SCALE * to_unit(y))


def encode_env_radiance(radiance):
    """Inverse of :func:`env_radiance` (radiance ∈ [0, 1000])."""
    return from_unit(torch.log1p(radiance) / _ENV_LOG_SCALE)
