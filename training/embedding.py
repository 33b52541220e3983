"""The MSN's material embedding: extra output channels trained to tell materials apart.

The thesis' MSN outputs one colour per material, (ρd + ρs)/2 of that material. Two materials whose mean
albedos are alike get alike colours, and a network's soft transition between them leaves no edge to cut a
mask at; the pick masks read those colours and that is where most of their error was (docs/model-card.md).
An MSN with ``out_channels`` > 3 gives, after the three colour channels, an *embedding*: per pixel a point in
[−1, 1]^k (tanh) trained with the discriminative loss of De Brabandere, Neven and Van Gool (2017, "Semantic
Instance Segmentation with a Discriminative Loss Function"): within each material of an image the pixels are
pulled to within :data:`DELTA_V` of the material's mean, the means of different materials are pushed at least
``2·``:data:`DELTA_D` apart, and a small term keeps the means near the origin. Which point a material gets is
free (the loss depends only on distances), so the channels carry no convention but "same material, near".

The materials of a training image are read off the target segmentation: every pixel of one material has the
material's colour (synth writes it exactly; the reduction keeps blocks, never averages), so each colour held by at
least :data:`MIN_PIXELS` pixels of surface is one material; other pixels (the sky, the few pixels the
renderer's pixel filter mixed at an edge) are ignored. Two materials of exactly the same colour count as one:
the loss then asks nothing about their border, as the colours cannot either.
"""

import torch
import torch.nn.functional as F

DELTA_V = 0.1
"""Pull margin: a pixel within this distance of its material's mean costs nothing."""

DELTA_D = 0.4
"""Push margin: two materials' means at least ``2·DELTA_D`` apart cost nothing."""

REG_WEIGHT = 0.001
"""Weight of the mean distance of the material means from the origin."""

MIN_PIXELS = 8
"""Fewest pixels of one target colour that make a material (fewer: ignored pixels)."""


def labels_of(segmentation, surface):
    """Material labels [N, H, W] (int64, −1 = ignored) of a batch's target ``segmentation`` [N, 3, H, W]
    (tanh space) and ``surface`` [N, 1, H, W] (0/1): one label per target colour with at least
    :data:`MIN_PIXELS` surface pixels, numbered per image."""
    n, c, h, w = segmentation.shape
    if c != 3 or surface.shape != (n, 1, h, w):
        raise ValueError(f"segmentation {tuple(segmentation.shape)} / surface {tuple(surface.shape)}: "
                         "expected [N, 3, H, W] and [N, 1, H, W]")
    # Colours as exact keys: 12 bits per channel is finer than the float16 the packs store.
    q = torch.round((segmentation.detach().float().clamp(-1, 1) + 1) * 2047.5).long()
    key = (q[:, 0] * 4096 + q[:, 1]) * 4096 + q[:, 2]
    on = surface[:, 0] > 0.5
    out = torch.full((n, h, w), -1, dtype=torch.long, device=segmentation.device)
    for i in range(n):
        k = key[i][on[i]]
        if k.numel() == 0:
            continue
        u, inv, cnt = torch.unique(k, return_inverse=True, return_counts=True)
        keep = cnt >= MIN_PIXELS
        relabel = torch.cumsum(keep.long(), 0) - 1
        lab = torch.where(keep[inv], relabel[inv], torch.full_like(inv, -1))
        out[i][on[i]] = lab
    return out


def discriminative_loss(embedding, labels):
    """(pull, push, regulariser) of an ``embedding`` [N, K, H, W] under ``labels`` [N, H, W], each the mean
    over the images that have the term (pull and the regulariser: images with a material; push: with two).

    pull: per material the mean of max(0, ‖e − μ‖ − δv)² over its pixels, averaged over materials (each material
    counts the same, whatever its size); push: the mean over ordered pairs of materials of max(0, 2δd − ‖μa − μb‖)²;
    regulariser: the mean ‖μ‖."""
    n, k = embedding.shape[:2]
    if labels.shape != (n, *embedding.shape[2:]):
        raise ValueError(f"labels {tuple(labels.shape)} do not fit the embedding {tuple(embedding.shape)}")
    pulls, pushes, regs = [], [], []
    for i in range(n):
        lab = labels[i].reshape(-1)
        on = lab >= 0
        if not bool(on.any()):
            continue
        e = embedding[i].reshape(k, -1)[:, on].T.float()  # [P, K]
        _, lab = torch.unique(lab[on], return_inverse=True)
        m = int(lab.max()) + 1
        count = torch.bincount(lab, minlength=m).to(e.dtype)
        mu = torch.zeros(m, k, dtype=e.dtype, device=e.device).index_add(0, lab, e) / count[:, None]
        d = (e - mu[lab]).norm(dim=1)
        per = torch.zeros(m, dtype=e.dtype, device=e.device).index_add(0, lab, F.relu(d - DELTA_V) ** 2)
        pulls.append((per / count).mean())
        if m > 1:
            dist = torch.cdist(mu[None], mu[None])[0]
            off = ~torch.eye(m, dtype=torch.bool, device=e.device)
            pushes.append((F.relu(2 * DELTA_D - dist[off]) ** 2).mean())
        regs.append(mu.norm(dim=1).mean())
    zero = embedding.sum() * 0.0

    def mean(v):
        return torch.stack(v).mean() if v else zero

    return mean(pulls), mean(pushes), mean(regs)


def embedding_loss(embedding, segmentation, surface):
    """The embedding's training loss: pull + push + :data:`REG_WEIGHT` · regulariser, materials from the target
    ``segmentation`` and ``surface`` (:func:`labels_of`)."""
    pull, push, reg = discriminative_loss(embedding, labels_of(segmentation, surface))
    return pull + push + REG_WEIGHT * reg
