"""Interaction model: object cloud + instruction + hand -> wrist poses and four contact anchors.

The design's first learned stage (issue 24). A DDPM over x = [wrist translation (3), rotation
(6-D: the first two columns of the matrix, continuous unlike quaternions), 4 anchors (4 x 3)]
= 21 numbers, denoised by a small transformer whose five tokens (wrist, four anchors) attend to
PointNet++ tokens of the object, PointNet++ tokens of the hand's fixed surface points at its
open pose (so any hand, a user's URDF too, is an input rather than a class id) and the sentence
embedding of the instruction. Text is dropped in training so that sampling can use
classifier-free guidance.

Frames: everything happens in a canonical frame of the cloud: centred on its mean and turned
about the vertical (z) axis so that the horizontal principal axis is x (its sign by the third
moment). Turning the input about z or moving it therefore turns and moves the output exactly;
tilts (up to 30 degrees) and scale (+-10%) are learned from augmentation. Coordinates inside
the network are in decimetres (SCALE) so that they are of order one.

    wrists, anchors = sample(cloud, "Use a mug by handle", "shadow", n=8)
"""

from __future__ import annotations

import math
import threading
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation
from torch import nn
from torch.nn import functional as F

from learned.pointnet import Grouping, LevelConfig, PointNet2Encoder, grouping
from learned.threads import one_thread
from learned.weights import WeightsError, load_weights, save_weights, weights_path
from models.errors import DrograspError, ObjectError

SCALE = 10.0  # network units per metre
X_DIM = 21  # translation 3 + rotation 6 + anchors 12
NAME = "interaction"
RETRAIN = "drograsp train interaction --data data/grasps_v2 --out runs/interaction --install"
# the ablation of direct diffusion (the paper's Scene-Diffuser comparison): the same encoders,
# text and data, but the model draws [wrist, joints] and no solver follows
DIRECT_NAME = "direct"
DIRECT_RETRAIN = (
    "drograsp train interaction --target joints --data data/grasps_v2 --blocks 17 --out "
    "runs/direct --steps 7065 --minutes 120 --install"
)
TARGETS = ("anchors", "joints")
FRAME_SIGNS = ("profile", "moment")


@dataclass
class InteractionConfig:
    """Sizes and settings. Defaults fit a 2-core CPU; scale widths, layers and points for a GPU."""

    points: int = 2048  # object cloud points the encoder sees
    object_levels: tuple[tuple[int, int, tuple[int, ...]], ...] = (
        (256, 16, (32, 64)),
        (48, 16, (96, 128)),
    )
    hand_levels: tuple[tuple[int, int, tuple[int, ...]], ...] = (
        (64, 16, (32, 64)),
        (16, 8, (96, 128)),
    )
    offset_scales: tuple[float, float] = (0.2, 0.5)  # network units (2 cm, 5 cm)
    width: int = 128
    heads: int = 4
    layers: int = 3
    ff: int = 256
    text_dim: int = 384
    diffusion_steps: int = 100  # T of the fixed cosine beta schedule
    # DDIM steps at sampling. 25 against 10 (weights of 2026-12-04, test split): part accuracy
    # 97.0 vs 95.6%, with evaluation-only paraphrases 92.0 vs 90.0%; 8 samples 71 vs 37 ms
    sample_steps: int = 25
    guidance: float = 2.0  # classifier-free guidance scale (1 = conditional only)
    text_dropout: float = 0.15  # share of training samples with the text dropped
    anchor_weight: float = 1.0  # loss weight of the anchor dimensions vs the wrist's
    # each block's norms scaled and shifted by (time + object, hand and text summary), so the
    # instruction acts at every layer, not only through one token (configs without it: off)
    film: bool = True
    # what is drawn beside the wrist: "anchors" (4 contact points: the pipeline's first stage)
    # or "joints" (the hand's joint values scaled to [-1, 1] by its limits, zero-padded to
    # joint_slots: the direct-diffusion ablation)
    target: str = "anchors"
    joint_slots: int = 24
    # condition on whether the grasp meets its instruction's intent definition (the dataset's
    # intent_ok): training learns every row that holds on its part, each with its flag, and
    # sampling asks for flag 1, so grasps that miss their intent still teach where the parts
    # are without being drawn as what the intent asks (configs without it: off)
    intent_flag: bool = False
    # how the canonical frame tells one end of the object from the other (`canonical_frame`):
    # "profile" (where the cross-sections are large) reads a completed single view as it reads
    # the whole object; "moment" (the points' third moment, configs without the option) flips
    # for completed knives and spray bottles, whose seen sides are sampled densely
    frame_sign: str = "profile"

    def __post_init__(self) -> None:
        if self.target not in TARGETS:
            raise ValueError(f"unknown target {self.target!r}; one of {TARGETS}")
        if self.frame_sign not in FRAME_SIGNS:
            raise ValueError(f"unknown frame_sign {self.frame_sign!r}; one of {FRAME_SIGNS}")

    @property
    def x_dim(self) -> int:
        """Numbers per sample: wrist (9) and the target."""
        return 9 + (12 if self.target == "anchors" else self.joint_slots)

    @property
    def name(self) -> str:
        """The weights' file name: interaction, or direct for the joints target."""
        return NAME if self.target == "anchors" else DIRECT_NAME

    def levels(self, which: str) -> tuple[LevelConfig, LevelConfig]:
        raw = self.object_levels if which == "object" else self.hand_levels
        a, b = (LevelConfig(int(c), int(k), tuple(int(w) for w in ws)) for c, k, ws in raw)
        return a, b

    def to_json(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> InteractionConfig:
        known = {f for f in cls.__dataclass_fields__}
        kw = {k: v for k, v in data.items() if k in known}
        kw.setdefault("film", False)  # written before the option existed
        kw.setdefault("frame_sign", "moment")  # likewise
        for key in ("object_levels", "hand_levels"):
            if key in kw:
                kw[key] = tuple((int(c), int(k), tuple(int(w) for w in ws)) for c, k, ws in kw[key])
        if "offset_scales" in kw:
            kw["offset_scales"] = tuple(float(s) for s in kw["offset_scales"])
        return cls(**kw)


# ---- frames ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Frame:
    """canonical = rot @ (p - centre): the cloud's centroid, yaw fixed by its shape."""

    centre: np.ndarray  # (3,)
    rot: np.ndarray  # (3, 3), a rotation about z

    def to_canonical(self, p: np.ndarray) -> np.ndarray:
        return (np.asarray(p) - self.centre) @ self.rot.T

    def from_canonical(self, p: np.ndarray) -> np.ndarray:
        return np.asarray(p) @ self.rot + self.centre


def profile_skew(along: np.ndarray, across: np.ndarray, z: np.ndarray, bins: int = 24) -> float:
    """Third moment of the object's bulk along an axis: slices across it, each weighted by its
    cross-section's bounding box (width x height), so sparse or dense sampling of a side does
    not move it (a completed single view is sampled densely where the camera saw)."""
    lo, span = along.min(), max(float(np.ptp(along)), 1e-9)
    idx = np.minimum(((along - lo) / span * bins).astype(int), bins - 1)
    count = np.bincount(idx, minlength=bins)
    extent = []
    for v in (across, z):
        top, bottom = np.full(bins, -np.inf), np.full(bins, np.inf)
        np.maximum.at(top, idx, v)
        np.minimum.at(bottom, idx, v)
        extent.append(np.where(count > 0, top - bottom, 0.0) + 1e-4)
    weight = np.where(count >= 3, extent[0] * extent[1], 0.0)
    centres = lo + (np.arange(bins) + 0.5) * span / bins
    x = centres - np.sum(weight * centres) / weight.sum()
    return float(np.sum(weight * x**3) / weight.sum())


def canonical_frame(points: np.ndarray, sign: str = "profile") -> Frame:
    """Centroid and a yaw from the horizontal principal axis, pointed to the object's heavier
    end (e.g. a mug's handle to +x): by the bulk's profile (`profile_skew`) or, as models
    trained before it, by the points' third moment. For shapes round about z the yaw is
    arbitrary, as it may be: their grasps are too."""
    pts = np.asarray(points, dtype=np.float64)
    centre = pts.mean(axis=0)
    xy = pts[:, :2] - centre[:2]
    vals, vecs = np.linalg.eigh(xy.T @ xy / len(xy))
    axis = vecs[:, 1]
    along = xy @ axis
    if sign == "profile":
        heavier = profile_skew(along, xy @ np.array([-axis[1], axis[0]]), pts[:, 2])
    elif sign == "moment":
        heavier = float(np.sum(along**3))
    else:
        raise ValueError(f"unknown frame sign {sign!r}; one of {FRAME_SIGNS}")
    if heavier < 0:
        axis = -axis
    c, s = axis
    rot = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    return Frame(centre, rot)


def rot6_from_matrix(m: np.ndarray) -> np.ndarray:
    """(..., 3, 3) -> (..., 6): the first two columns."""
    return np.concatenate([m[..., :, 0], m[..., :, 1]], axis=-1)


def matrix_from_rot6(r6: np.ndarray) -> np.ndarray:
    """(..., 6) -> (..., 3, 3) by Gram-Schmidt (the nearest rotation for any 6 numbers)."""
    a, b = r6[..., :3], r6[..., 3:]
    x = a / np.maximum(np.linalg.norm(a, axis=-1, keepdims=True), 1e-9)
    b = b - np.sum(x * b, axis=-1, keepdims=True) * x
    flat = np.linalg.norm(b, axis=-1) < 1e-6  # b along a: any perpendicular will do
    if flat.any():
        helper = np.where(np.abs(x[..., :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
        b = np.where(flat[..., None], np.cross(x, helper), b)
    y = b / np.maximum(np.linalg.norm(b, axis=-1, keepdims=True), 1e-9)
    z = np.cross(x, y)
    return np.stack([x, y, z], axis=-1)


def encode_x(wrist: np.ndarray, anchors: np.ndarray, frame: Frame) -> np.ndarray:
    """Grasps in the input frame -> (n, 21) in the canonical frame, network units (unnormalised).

    wrist (n, 7) [x, y, z, qw, qx, qy, qz]; anchors (n, 4, 3)."""
    wrist = np.asarray(wrist, dtype=np.float64).reshape(-1, 7)
    anchors = np.asarray(anchors, dtype=np.float64).reshape(-1, 4, 3)
    t = frame.to_canonical(wrist[:, :3]) * SCALE
    rm = Rotation.from_quat(wrist[:, 3:], scalar_first=True).as_matrix()
    r6 = rot6_from_matrix(frame.rot @ rm)
    a = frame.to_canonical(anchors) * SCALE
    return np.concatenate([t, r6, a.reshape(-1, 12)], axis=1)


def decode_wrist(x: np.ndarray, frame: Frame) -> np.ndarray:
    """(n, 9+) canonical network units -> wrists (n, 7) in the input frame."""
    x = np.asarray(x, dtype=np.float64)
    t = frame.from_canonical(x[:, :3] / SCALE)
    rm = frame.rot.T @ matrix_from_rot6(x[:, 3:9])
    q = Rotation.from_matrix(rm).as_quat(scalar_first=True)
    q *= np.where(q[:, :1] < 0, -1.0, 1.0)  # qw >= 0, one of the two equal quaternions
    return np.concatenate([t, q], axis=1)


def decode_x(x: np.ndarray, frame: Frame) -> tuple[np.ndarray, np.ndarray]:
    """(n, 21) canonical network units -> wrists (n, 7) and anchors (n, 4, 3) in the input frame."""
    x = np.asarray(x, dtype=np.float64)
    a = frame.from_canonical(x[:, 9:21].reshape(-1, 4, 3) / SCALE)
    return decode_wrist(x, frame), a


def encode_joints(q: np.ndarray, lower: np.ndarray, upper: np.ndarray, slots: int) -> np.ndarray:
    """Joint values (n, dof) -> (n, slots): scaled to [-1, 1] by the limits, zero-padded (the
    same layout for every hand; the hand input says which hand it is)."""
    q = np.asarray(q, dtype=np.float64).reshape(len(q), -1)
    dof = len(lower)
    if dof > slots:
        raise ValueError(f"a hand of {dof} joints needs joint_slots >= {dof} (config has {slots})")
    half = np.maximum((np.asarray(upper) - np.asarray(lower)) / 2, 1e-6)
    out = np.zeros((len(q), slots))
    out[:, :dof] = (q[:, :dof] - (np.asarray(upper) + np.asarray(lower)) / 2) / half
    return out


def decode_joints(z: np.ndarray, hand: Any) -> np.ndarray:
    """(n, slots) -> joint values (n, dof) within the hand's limits and on its couplings (the
    nearest coupled configuration, then clipped: the limits keep the plan ratio)."""
    lower, upper = np.asarray(hand.lower, float), np.asarray(hand.upper, float)
    dof = len(lower)
    q = (upper + lower) / 2 + np.asarray(z, dtype=np.float64)[:, :dof] * (upper - lower) / 2
    basis = hand.coupling_basis
    q = q @ np.linalg.pinv(basis).T @ basis.T
    return np.clip(q, lower, upper)


# ---- inputs ------------------------------------------------------------------------------------
def check_cloud(cloud: object) -> np.ndarray:
    """An (N, 3) cloud in metres, or an ObjectError (empty, NaN, wrong shape, millimetres)."""
    from models.objects.loading import as_array
    from models.objects.validation import check_coordinates

    return check_coordinates(as_array(cloud, "cloud"))


def subsample(points: np.ndarray, n: int, seed: int = 0) -> np.ndarray:
    """n points of the cloud chosen by index (so the choice ignores the cloud's pose)."""
    rng = np.random.default_rng(seed)
    if len(points) == n:
        return points
    return points[rng.choice(len(points), size=n, replace=len(points) < n)]


@dataclass
class Prepared:
    """One cloud made ready for the network: its frame, canonical points and grouping."""

    frame: Frame
    xyz: np.ndarray  # (P, 3) canonical, network units
    groups: Grouping


def prepare_cloud(points: np.ndarray, config: InteractionConfig, seed: int = 0) -> Prepared:
    pts = subsample(np.asarray(points, dtype=np.float64), config.points, seed)
    frame = canonical_frame(pts, config.frame_sign)
    return Prepared(frame, frame.to_canonical(pts) * SCALE, grouping(pts, config.levels("object")))


_hand_cache: dict[str, tuple[np.ndarray, Grouping]] = {}


def hand_points(hand: Any, config: InteractionConfig) -> tuple[np.ndarray, Grouping]:
    """The hand's fixed surface points at its open pose in its root frame (network units) and
    their grouping; cached per hand name and level sizes."""
    from models.hands import HandModel, load_hand

    model = hand if isinstance(hand, HandModel) else load_hand(hand)
    key = f"{model.folder}:{config.hand_levels}"
    if key not in _hand_cache:
        eye = np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0])
        pts = model.surface_points(eye, model.open_pose)[0].detach().cpu().numpy()
        _hand_cache[key] = (pts * SCALE, grouping(pts, config.levels("hand")))
    return _hand_cache[key]


# ---- network -----------------------------------------------------------------------------------
def timestep_embedding(t: torch.Tensor, dim: int) -> torch.Tensor:
    half = dim // 2
    freqs = torch.exp(-math.log(10000.0) * torch.arange(half, dtype=torch.float32) / half)
    args = t.float()[:, None] * freqs[None]
    return torch.cat([torch.sin(args), torch.cos(args)], dim=-1)


class Block(nn.Module):
    """Pre-norm: self-attention among the grasp tokens, cross-attention to the condition, MLP.

    The condition's keys and values are projected once per condition (`memory`) and reused
    at every denoising step: at sampling that is most of the work saved."""

    def __init__(self, d: int, heads: int, ff: int, film: bool = False):
        super().__init__()
        self.heads = heads
        self.film = nn.Linear(d, 4 * d) if film else None
        if self.film is not None:  # starts as the identity
            nn.init.zeros_(self.film.weight)
            nn.init.zeros_(self.film.bias)
        self.n1, self.n2, self.n3 = nn.LayerNorm(d), nn.LayerNorm(d), nn.LayerNorm(d)
        self.self_attn = nn.MultiheadAttention(d, heads, batch_first=True)
        self.cross = nn.MultiheadAttention(d, heads, batch_first=True)
        self.ff = nn.Sequential(nn.Linear(d, ff), nn.GELU(), nn.Linear(ff, d))

    def _split(self, t: torch.Tensor) -> torch.Tensor:
        b, m, d = t.shape
        return t.view(b, m, self.heads, d // self.heads).transpose(1, 2)

    def memory(self, cond: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Keys and values (B, heads, M, d / heads) of the condition tokens."""
        d = cond.shape[-1]
        w, b = self.cross.in_proj_weight, self.cross.in_proj_bias
        k = F.linear(cond, w[d : 2 * d], b[d : 2 * d])
        v = F.linear(cond, w[2 * d :], b[2 * d :])
        return self._split(k), self._split(v)

    def forward(
        self, x: torch.Tensor, memory: tuple[torch.Tensor, torch.Tensor], emb: torch.Tensor
    ) -> torch.Tensor:
        mods = None
        if self.film is not None:
            mods = self.film(emb)[:, None].chunk(4, dim=-1)
        h = self.n1(x)
        if mods is not None:
            h = h * (1 + mods[0]) + mods[1]
        x = x + self.self_attn(h, h, h, need_weights=False)[0]
        d = x.shape[-1]
        w, b = self.cross.in_proj_weight, self.cross.in_proj_bias
        q = self._split(F.linear(self.n2(x), w[:d], b[:d]))
        att = F.scaled_dot_product_attention(q, *memory)
        att = att.transpose(1, 2).reshape(x.shape)
        x = x + self.cross.out_proj(att)
        h = self.n3(x)
        if mods is not None:
            h = h * (1 + mods[2]) + mods[3]
        return x + self.ff(h)


@dataclass
class Condition:
    """Encoded condition per batch row: tokens (B, M, d), a global vector (B, d) and, once
    computed, each block's keys and values of the tokens."""

    tokens: torch.Tensor
    glob: torch.Tensor
    memory: list[tuple[torch.Tensor, torch.Tensor]] | None = None

    def repeat(self, n: int) -> Condition:
        mem = None
        if self.memory is not None:
            mem = [(k.repeat_interleave(n, 0), v.repeat_interleave(n, 0)) for k, v in self.memory]
        return Condition(
            self.tokens.repeat_interleave(n, 0), self.glob.repeat_interleave(n, 0), mem
        )

    @staticmethod
    def cat(a: Condition, b: Condition) -> Condition:
        mem = None
        if a.memory is not None and b.memory is not None:
            mem = [
                (torch.cat([ka, kb]), torch.cat([va, vb]))
                for (ka, va), (kb, vb) in zip(a.memory, b.memory, strict=True)
            ]
        return Condition(torch.cat([a.tokens, b.tokens]), torch.cat([a.glob, b.glob]), mem)


class InteractionNet(nn.Module):
    """Encoders and the noise predictor; x_mean / x_std (buffers) normalise the 21 numbers."""

    def __init__(self, config: InteractionConfig):
        super().__init__()
        self.config = c = config
        d = c.width
        self.object_enc = PointNet2Encoder(c.levels("object"), d, c.offset_scales)
        self.hand_enc = PointNet2Encoder(c.levels("hand"), d, c.offset_scales)
        self.text_proj = nn.Sequential(nn.Linear(c.text_dim, d), nn.GELU(), nn.Linear(d, d))
        self.null_text = nn.Parameter(torch.zeros(c.text_dim))
        self.kind = nn.Parameter(torch.randn(3, d) * 0.02)  # object / hand / text token types
        # added to the text's projection: row 0 misses its intent, row 1 meets it
        self.met = nn.Parameter(torch.randn(2, d) * 0.02) if c.intent_flag else None
        self.time = nn.Sequential(nn.Linear(d, d), nn.GELU(), nn.Linear(d, d))
        self.glob = nn.Linear(3 * d, d)
        self.wrist_in = nn.Linear(9, d)
        self.joints = c.target == "joints"
        if self.joints:  # one token for the whole joint vector
            self.joint_in = nn.Linear(c.joint_slots, d)
            self.joint_out = nn.Linear(d, c.joint_slots)
        else:  # one token per anchor
            self.anchor_in = nn.Linear(3, d)
            self.anchor_out = nn.Linear(d, 3)
        self.slot = nn.Parameter(torch.randn(2 if self.joints else 5, d) * 0.02)
        self.blocks = nn.ModuleList([Block(d, c.heads, c.ff, c.film) for _ in range(c.layers)])
        self.out_norm = nn.LayerNorm(d)
        self.wrist_out = nn.Linear(d, 9)
        self.register_buffer("x_mean", torch.zeros(c.x_dim))
        self.register_buffer("x_std", torch.ones(c.x_dim))
        betas = cosine_betas(c.diffusion_steps)
        self.register_buffer("alphas_bar", torch.cumprod(1.0 - betas, dim=0), persistent=False)

    def encode(
        self,
        obj_xyz: torch.Tensor,
        obj_groups: dict[str, torch.Tensor],
        hand_xyz: torch.Tensor,
        hand_groups: dict[str, torch.Tensor],
        text: torch.Tensor,
        drop_text: torch.Tensor | None = None,
        hand_index: torch.Tensor | None = None,
        met: torch.Tensor | None = None,
    ) -> Condition:
        """Object (B, P, 3), hands (H, 512, 3), text (B, 384) -> condition. Row i uses hand
        hand_index[i] (default: the one hand, H = 1); rows where drop_text is True see the
        learned null text instead (classifier-free guidance). `met` (B,) bool: whether each
        row's grasp meets its intent (models with `intent_flag`; default True, what sampling
        asks for); it is part of the instruction, so dropped with it."""
        b = obj_xyz.shape[0]
        ot, _, og = self.object_enc(obj_xyz, obj_groups)
        ht, _, hg = self.hand_enc(hand_xyz, hand_groups)
        if hand_index is not None:
            ht, hg = ht[hand_index], hg[hand_index]
        elif ht.shape[0] != b:
            ht, hg = ht.expand(b, -1, -1), hg.expand(b, -1)
        if drop_text is not None:
            text = torch.where(drop_text[:, None], self.null_text[None].expand(b, -1), text)
        tt = self.text_proj(text)
        if self.met is not None:
            if met is None:
                met = torch.ones(b, dtype=torch.bool)
            flag = self.met[met.long()]
            if drop_text is not None:
                flag = torch.where(drop_text[:, None], torch.zeros_like(flag), flag)
            tt = tt + flag
        tokens = torch.cat(
            [ot + self.kind[0], ht + self.kind[1], (tt + self.kind[2]).unsqueeze(1)], dim=1
        )
        return Condition(tokens, self.glob(torch.cat([og, hg, tt], dim=-1)))

    def memory(self, cond: Condition) -> list[tuple[torch.Tensor, torch.Tensor]]:
        return [block.memory(cond.tokens) for block in self.blocks]

    def forward(self, x: torch.Tensor, t: torch.Tensor, cond: Condition) -> torch.Tensor:
        """Predicted noise (B, x_dim) for normalised noisy x (B, x_dim) at integer steps t (B,)."""
        emb = self.time(timestep_embedding(t, self.config.width)) + cond.glob
        if self.joints:
            rest = self.joint_in(x[:, None, 9:])
        else:
            rest = self.anchor_in(x[:, 9:].reshape(-1, 4, 3))
        tokens = torch.cat([self.wrist_in(x[:, None, :9]), rest], dim=1)
        h = tokens + self.slot[None] + emb[:, None]
        memory = cond.memory or self.memory(cond)
        for block, mem in zip(self.blocks, memory, strict=True):
            h = block(h, mem, emb)
        h = self.out_norm(h)
        rest = self.joint_out(h[:, 1]) if self.joints else self.anchor_out(h[:, 1:]).flatten(1)
        return torch.cat([self.wrist_out(h[:, 0]), rest], dim=1)

    # ---- diffusion ---------------------------------------------------------------------------
    def loss(self, x0: torch.Tensor, cond: Condition, generator: torch.Generator | None = None):
        """Simple epsilon MSE at uniform random steps; x0 normalised (B, 21)."""
        b = x0.shape[0]
        t = torch.randint(0, self.config.diffusion_steps, (b,), generator=generator)
        eps = torch.randn(x0.shape, generator=generator)
        ab = self.alphas_bar[t][:, None]
        xt = ab.sqrt() * x0 + (1 - ab).sqrt() * eps
        err = (self(xt, t, cond) - eps) ** 2
        w = torch.ones(self.config.x_dim)
        w[9:] = self.config.anchor_weight
        return (err * w).sum(1).mean() / w.sum()

    @torch.no_grad()
    def ddim(
        self,
        cond: Condition,
        uncond: Condition | None,
        n: int,
        steps: int,
        guidance: float,
        generator: torch.Generator | None = None,
    ) -> torch.Tensor:
        """n normalised samples per condition row (deterministic DDIM, eta = 0): (B * n, x_dim)."""
        cond.memory = self.memory(cond)
        c = cond.repeat(n)
        guided = uncond is not None and guidance != 1.0
        if guided:
            uncond.memory = self.memory(uncond)
            c = Condition.cat(c, uncond.repeat(n))
        rows = cond.tokens.shape[0] * n
        x = torch.randn((rows, self.config.x_dim), generator=generator)
        T = self.config.diffusion_steps
        ts = torch.linspace(T - 1, 0, steps).round().long().tolist()
        for i, t in enumerate(ts):
            tt = torch.full((rows,), t, dtype=torch.long)
            if guided:
                e_c, e_u = self(torch.cat([x, x]), torch.cat([tt, tt]), c).chunk(2)
                eps = e_u + guidance * (e_c - e_u)
            else:
                eps = self(x, tt, c)
            ab = self.alphas_bar[t]
            x0 = (x - (1 - ab).sqrt() * eps) / ab.sqrt()
            x0 = x0.clamp(-6, 6)  # far outside the data's spread: keep the step consistent
            eps = (x - ab.sqrt() * x0) / (1 - ab).sqrt()
            ab_prev = self.alphas_bar[ts[i + 1]] if i + 1 < len(ts) else torch.tensor(1.0)
            x = ab_prev.sqrt() * x0 + (1 - ab_prev).sqrt() * eps
        return x


def cosine_betas(steps: int, s: float = 0.008) -> torch.Tensor:
    """The fixed cosine schedule (Nichol and Dhariwal), betas capped at 0.999."""
    t = torch.linspace(0, steps, steps + 1, dtype=torch.float64) / steps
    f = torch.cos((t + s) / (1 + s) * math.pi / 2) ** 2
    ab = f / f[0]
    return (1 - ab[1:] / ab[:-1]).clamp(max=0.999).float()


# ---- the model as a whole ----------------------------------------------------------------------
@dataclass
class InteractionModel:
    """A network with its config and provenance; `sample` is the public entry point."""

    net: InteractionNet
    config: InteractionConfig
    info: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def new(cls, config: InteractionConfig | None = None, seed: int = 0) -> InteractionModel:
        torch.manual_seed(seed)
        config = config or InteractionConfig()
        return cls(InteractionNet(config), config)

    def save(self, folder: str, name: str | None = None) -> Path:
        name = name or self.config.name
        cfg = {
            "config": self.config.to_json(),
            "info": self.info,
            "format": "drograsp-interaction/1",
        }
        return save_weights(weights_path(name, folder), self.net.state_dict(), cfg)

    @classmethod
    def load(cls, folder: str | None = None, name: str = NAME) -> InteractionModel:
        retrain = DIRECT_RETRAIN if name == DIRECT_NAME else RETRAIN
        path = weights_path(name, folder)
        state, cfg = load_weights(path, retrain, f"{name} model")
        if cfg.get("format") != "drograsp-interaction/1" or "config" not in cfg:
            raise WeightsError(
                f"{path} does not hold an interaction model (format {cfg.get('format')!r}); "
                f"remake it with `{retrain}`"
            )
        try:
            config = InteractionConfig.from_json(cfg["config"])
            net = InteractionNet(config)
            net.load_state_dict(state)
        except (TypeError, ValueError, RuntimeError, KeyError) as err:
            raise WeightsError(
                f"{path} does not fit the model's code ({type(err).__name__}: "
                f"{str(err)[:300]}); remake it with `{retrain}`"
            ) from None
        net.eval()
        return cls(net, config, cfg.get("info", {}))

    def condition(
        self,
        prepared: list[Prepared],
        hand: Any,
        text_vecs: np.ndarray,
        drop: bool = False,
        met: bool = True,
    ) -> Condition:
        """The encoded condition of prepared clouds with the hand and text embeddings; `drop`:
        the null text (guidance's unconditional half); `met`: a model with `intent_flag` is
        asked for grasps that meet (True) or miss their intent."""
        hxyz, hgroups = hand_points(hand, self.config)
        obj = torch.from_numpy(np.stack([p.xyz for p in prepared])).float()
        groups = {
            k: torch.stack([torch.from_numpy(getattr(p.groups, k)) for p in prepared])
            for k in ("centres1", "nbrs1", "centres2", "nbrs2")
        }
        hgt = {k: v[None] for k, v in hgroups.tensors().items()}
        txt = torch.from_numpy(np.asarray(text_vecs, dtype=np.float32))
        dropped = torch.full((len(prepared),), drop) if drop else None
        flags = torch.full((len(prepared),), met)
        return self.net.encode(
            obj, groups, torch.from_numpy(hxyz).float()[None], hgt, txt, dropped, met=flags
        )

    @one_thread
    @torch.no_grad()
    def sample_prepared(
        self,
        prepared: Prepared,
        text_vec: np.ndarray,
        hand: Any,
        n: int,
        guidance: float | None = None,
        steps: int | None = None,
        seed: int | None = 0,
    ) -> np.ndarray:
        """(n, 21) canonical network-unit samples for one prepared cloud."""
        self.net.eval()
        g = None if seed is None else torch.Generator().manual_seed(seed)
        guidance = self.config.guidance if guidance is None else float(guidance)
        cond = self.condition([prepared], hand, text_vec[None])
        uncond = (
            self.condition([prepared], hand, text_vec[None], drop=True) if guidance != 1.0 else None
        )
        x = self.net.ddim(cond, uncond, n, steps or self.config.sample_steps, guidance, g)
        return (x * self.net.x_std + self.net.x_mean).numpy().astype(np.float64)

    def sample(
        self,
        cloud: object,
        text: str,
        hand: Any,
        n: int = 8,
        guidance: float | None = None,
        steps: int | None = None,
        seed: int | None = 0,
        snap: bool = True,
    ) -> tuple[np.ndarray, np.ndarray]:
        """n wrist poses (n, 7) [x, y, z, qw, qx, qy, qz] and anchors (n, 4, 3) in the cloud's
        frame; anchors snapped to the nearest cloud points unless snap=False."""
        pts, prepared, x = self._draw(cloud, text, hand, n, guidance, steps, seed, "anchors")
        wrists, anchors = decode_x(x, prepared.frame)
        if snap:
            anchors = snap_to_cloud(anchors, pts)
        return wrists, anchors

    def sample_configurations(
        self,
        cloud: object,
        text: str,
        hand: Any,
        n: int = 8,
        guidance: float | None = None,
        steps: int | None = None,
        seed: int | None = 0,
    ) -> tuple[np.ndarray, np.ndarray]:
        """A joints-target model's n wrist poses (n, 7) and joint values (n, dof) in the
        cloud's frame, within the hand's limits and couplings."""
        from models.hands import HandModel, load_hand

        model = hand if isinstance(hand, HandModel) else load_hand(hand)
        _, prepared, x = self._draw(cloud, text, model, n, guidance, steps, seed, "joints")
        return decode_wrist(x, prepared.frame), decode_joints(x[:, 9:], model)

    def _draw(self, cloud, text, hand, n, guidance, steps, seed, target: str):
        from learned.text import encode

        if self.config.target != target:
            raise SamplingError(
                f"this model draws {self.config.target}, not {target}: use "
                f"{'sample' if self.config.target == 'anchors' else 'sample_configurations'}"
            )
        if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
            raise SamplingError(f"n must be a positive integer, got {n!r}")
        pts = check_cloud(cloud)
        vec = encode([text])[0]
        prepared = prepare_cloud(pts, self.config)
        return (
            pts,
            prepared,
            self.sample_prepared(prepared, vec, hand, int(n), guidance, steps, seed),
        )


class SamplingError(DrograspError, ValueError):
    """A sampling argument out of range (a user's error: the CLI prints it without a
    traceback)."""


def snap_to_cloud(anchors: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Each anchor moved to its nearest cloud point."""
    idx = cKDTree(points).query(anchors.reshape(-1, 3))[1]
    return points[idx].reshape(anchors.shape)


_loaded: dict[str, InteractionModel] = {}
_load_lock = threading.Lock()


def load_model(folder: str | None = None, name: str = NAME) -> InteractionModel:
    """The named model from `folder` (default: the package's shipped weights), loaded once."""
    key = f"{folder}:{name}"
    with _load_lock:
        if key not in _loaded:
            _loaded[key] = InteractionModel.load(folder, name)
        return _loaded[key]


def sample(
    cloud: object,
    text: str,
    hand: Any,
    n: int = 8,
    guidance: float | None = None,
    steps: int | None = None,
    seed: int | None = 0,
    model: InteractionModel | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """n wrist poses (n, 7) [x, y, z, qw, qx, qy, qz] and contact anchors (n, 4, 3), in the
    cloud's frame, for the instruction and hand (a name, a folder, or a HandModel); drawn in one
    batch by the shipped model unless `model` is given."""
    if not isinstance(cloud, np.ndarray | list | tuple) and not hasattr(cloud, "detach"):
        raise ObjectError(
            f"cannot use {type(cloud).__name__} as a cloud: give an (N, 3) array in metres"
        )
    return (model or load_model()).sample(cloud, text, hand, n, guidance, steps, seed)
