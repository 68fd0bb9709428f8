"""The D(R,O) network: hand cloud + object cloud + instruction -> hand-object distance matrix.

The hand is only a point cloud here (its fixed surface points at the first stage's wrist with
the fingers open), so one network serves every hand. Both clouds go through a DGCNN encoder
(static kNN graph on xyz, EdgeConv layers, per-point features); the instruction's sentence
embedding scales and shifts both (FiLM); one cross-attention block each way lets hand and
object features see each other (psi = phi + T(phi, other)); the kernel is an MLP on each pair
[psi_R_i, psi_O_j] through softplus (not symmetrised: see `kernel`). Its first layer on
a concatenation is a sum of two per-point projections, so those are computed per point and
broadcast-added: the N x 512 pairs cost one small hidden layer each. The pair also gets a
geometric feature: the distance from where the hand point is predicted to go (its position in
the input, where the open hand already sits at the grasp's wrist, plus an offset read from its
features) to the object point. A one-hidden-layer kernel cannot compute a distance from two
feature vectors well (runs without this feature stalled at 13 mm on near pairs), while this
costs one cdist.

Distances are predicted in centimetres inside (softplus output) and returned in metres.
Weights are one safetensors file with the config in its header (learned.weights).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch
from torch import nn

from learned import weights as store
from learned.multilateration import RigidGroups, multilaterate, rigid_fit
from learned.threads import one_thread
from models.errors import DrograspError

TEXT_DIM = 384  # learned.text.EMBED_DIM; fixed here so the network imports no text model
WEIGHTS = store.weights_path("dro")
FORMAT = "drograsp-dro/1"  # the header's format tag (learned.weights)
# the ablation without anchors (DROConfig.anchors False), for eval.benchmark's no_anchors
NO_ANCHOR_WEIGHTS = WEIGHTS.with_name("dro_no_anchors.safetensors")
# the shipped weights: the first 17 blocks of data/grasps_v2 (its rows then), 3831 steps
RETRAIN = (
    "drograsp train dro --data data/grasps_v2 --blocks 17 --out runs/dro --epochs 8 "
    "--steps 3831 --install"
)


@dataclass(frozen=True)
class DROConfig:
    """Network sizes; the defaults are sized for a 2-core CPU (see DESIGN.md, Performance)."""

    k: int = 16  # kNN graph neighbours of the DGCNN encoders
    edge_widths: tuple[int, ...] = (32, 32, 64)
    feature_dim: int = 64
    heads: int = 4
    kernel_hidden: int = 32
    text_dim: int = TEXT_DIM
    input_scale: float = 10.0  # xyz (m) x 10: decimetres, inputs of order 1
    unit: float = 0.01  # metres per unit of the kernel's output: cm
    # a kernel feature: the distance from where each hand point is predicted to go (its input
    # position plus a learned offset) to the object point
    input_distance: bool = True
    # the object input is sampled by the anchors' contact map (learned.contact_map); False: the
    # paper's ablation without anchors (uniform farthest point samples, Omega 0)
    anchors: bool = True

    def to_json(self) -> dict:
        return asdict(self)

    @classmethod
    def from_json(cls, data: dict) -> DROConfig:
        return cls(**{**data, "edge_widths": tuple(data["edge_widths"])})


def knn(xyz: torch.Tensor, k: int) -> torch.Tensor:
    """(B, N, k) indices of each point's k nearest neighbours (itself included)."""
    d = torch.cdist(xyz, xyz)
    return torch.topk(d, min(k, xyz.shape[1]), dim=2, largest=False).indices


class EdgeConv(nn.Module):
    """DGCNN's edge convolution max_j act(W [x_i, x_j - x_i]) over the kNN graph.

    With one linear layer per edge (as in DGCNN) and a monotone activation, the max over the
    neighbours can be taken before the activation: max_j (A x_i + B (x_j - x_i)) = A x_i - B x_i
    + max_j B x_j. So only the per-point projection B x is gathered over the graph (k times
    less work than a per-edge layer; the encoders were 80% of a training step before). Both
    max and min are kept, as a normalisation with a negative scale would pick the min."""

    def __init__(self, cin: int, cout: int):
        super().__init__()
        self.centre = nn.Linear(cin, cout)
        self.edge = nn.Linear(cin, cout, bias=False)
        self.mix = nn.Linear(2 * cout, cout)
        self.norm = nn.LayerNorm(cout)

    def forward(self, x: torch.Tensor, idx: torch.Tensor) -> torch.Tensor:
        e = self.edge(x)
        rows = torch.arange(idx.shape[0], device=idx.device)[:, None, None]
        neigh = e[rows, idx]  # (B, N, k, C); its backward scatters into (B, N, C) only
        base = self.centre(x) - e
        h = torch.cat([base + neigh.max(dim=2).values, base + neigh.min(dim=2).values], dim=-1)
        return nn.functional.leaky_relu(self.norm(self.mix(h)), 0.2)


class DGCNN(nn.Module):
    """Per-point features from a cloud (B, N, C) whose first 3 channels are xyz."""

    def __init__(self, cin: int, cfg: DROConfig):
        super().__init__()
        layers, prev = [], cin
        for w in cfg.edge_widths:
            layers.append(EdgeConv(prev, w))
            prev = w
        self.layers = nn.ModuleList(layers)
        self.head = nn.Sequential(
            nn.Linear(sum(cfg.edge_widths), cfg.feature_dim),
            nn.LeakyReLU(0.2),
            nn.Linear(cfg.feature_dim, cfg.feature_dim),
        )
        self.k = cfg.k

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        idx = knn(x[..., :3], self.k)
        outs = []
        for layer in self.layers:
            x = layer(x, idx)
            outs.append(x)
        return self.head(torch.cat(outs, dim=-1))


class CrossBlock(nn.Module):
    """psi = phi + T(phi, other): cross-attention then a feed-forward layer, pre-norm."""

    def __init__(self, dim: int, heads: int):
        super().__init__()
        self.nq, self.nkv, self.nff = nn.LayerNorm(dim), nn.LayerNorm(dim), nn.LayerNorm(dim)
        self.attn = nn.MultiheadAttention(dim, heads, batch_first=True)
        self.ff = nn.Sequential(nn.Linear(dim, 2 * dim), nn.GELU(), nn.Linear(2 * dim, dim))

    def forward(self, x: torch.Tensor, other: torch.Tensor) -> torch.Tensor:
        kv = self.nkv(other)
        x = x + self.attn(self.nq(x), kv, kv, need_weights=False)[0]
        return x + self.ff(self.nff(x))


class DRONet(nn.Module):
    """D(R,O): `forward(hand_xyz, obj, text)` -> (B, N, M) predicted distances in metres."""

    def __init__(self, cfg: DROConfig | None = None):
        super().__init__()
        self.cfg = cfg = cfg or DROConfig()
        f = cfg.feature_dim
        self.hand_enc = DGCNN(3, cfg)
        self.obj_enc = DGCNN(4, cfg)
        self.film = nn.Linear(cfg.text_dim, 4 * f)  # gamma, beta for hand and object
        nn.init.zeros_(self.film.weight)
        nn.init.zeros_(self.film.bias)
        self.hand_cross = CrossBlock(f, cfg.heads)
        self.obj_cross = CrossBlock(f, cfg.heads)
        self.pair_r = nn.Linear(f, cfg.kernel_hidden)
        self.pair_o = nn.Linear(f, cfg.kernel_hidden, bias=False)
        # not zero: with both this and the offset head at zero, neither gets a gradient to
        # start from (the interim weights were trained so: their offsets stayed small)
        self.pair_d = nn.Parameter(0.1 * torch.randn(cfg.kernel_hidden))
        # where each hand point is headed (cm from its input position), zero at the start
        self.offset = nn.Linear(f, 3)
        nn.init.zeros_(self.offset.weight)
        nn.init.zeros_(self.offset.bias)
        self.pair_out = nn.Linear(cfg.kernel_hidden, 1)
        nn.init.constant_(self.pair_out.bias, 2.0)  # start near a few cm, not near zero

    def encode(
        self, hand_xyz: torch.Tensor, obj: torch.Tensor, text: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Per-point features psi_R (B, N, f) and psi_O (B, M, f)."""
        s = self.cfg.input_scale
        phi_r = self.hand_enc(hand_xyz * s)
        phi_o = self.obj_enc(torch.cat([obj[..., :3] * s, obj[..., 3:]], dim=-1))
        g_r, b_r, g_o, b_o = self.film(text)[:, None].chunk(4, dim=-1)
        phi_r = phi_r * (1 + g_r) + b_r
        phi_o = phi_o * (1 + g_o) + b_o
        return self.hand_cross(phi_r, phi_o), self.obj_cross(phi_o, phi_r)

    def kernel(
        self,
        psi_r: torch.Tensor,
        psi_o: torch.Tensor,
        input_distance: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """(B, N, M) distances (m) for every pair of the given point features.

        Hand and object points come from different encoders, so the kernel is not made
        symmetric: a first layer shared by both sides (symmetric by construction) sees only
        A psi_R + A psi_O, from which a distance, a function of their difference, cannot be
        read, and the first interim run stalled at 13 mm; the original's symmetrisation by
        averaging both orders would double the kernel, which dominates inference."""
        a, b = self.pair_r(psi_r), self.pair_o(psi_o)
        w, bias = self.pair_out.weight[0], self.pair_out.bias[0]
        h = a[:, :, None] + b[:, None]  # (B, N, M, H): the pairs' hidden layer
        # w . leaky_relu(h) = 0.2 w . h + 0.8 w . relu(h), and w . h is a sum of per-point
        # terms: only relu(h) needs the pairs, computed in place (the kernel dominates
        # inference: three passes over the pairs instead of five)
        linear = (a @ w)[:, :, None] + (b @ w)[:, None]
        if input_distance is not None and self.cfg.input_distance:
            scaled = input_distance / self.cfg.unit
            h.addcmul_(scaled[..., None], self.pair_d)
            linear = linear + scaled * (self.pair_d @ w)
        z = 0.2 * linear + 0.8 * (h.relu_() @ w) + bias
        return nn.functional.softplus(z) * self.cfg.unit

    def forward(
        self,
        hand_xyz: torch.Tensor,
        obj: torch.Tensor,
        text: torch.Tensor,
        hand_index: torch.Tensor | None = None,
        obj_index: torch.Tensor | None = None,
        return_headed: bool = False,
    ) -> torch.Tensor | tuple[torch.Tensor, torch.Tensor]:
        """hand_xyz (B, N, 3) m, obj (B, M, 4) xyz + Omega, text (B, 384) -> D (B, N', M') m
        for the hand points `hand_index` (B, N') and object points `obj_index` (B, M')
        (default: all): the encoders always see whole clouds, only the kernel is subsampled.
        With `return_headed`, also where each of those hand points is headed (B, N', 3): the
        input position plus the learned offset behind the kernel's distance feature."""
        psi_r, psi_o = self.encode(hand_xyz, obj, text)
        xyz_r, xyz_o = hand_xyz, obj[..., :3]
        if hand_index is not None:
            psi_r = _take(psi_r, hand_index)
            xyz_r = _take(xyz_r, hand_index)
        if obj_index is not None:
            psi_o = _take(psi_o, obj_index)
            xyz_o = _take(xyz_o, obj_index)
        if self.cfg.input_distance:
            xyz_r = xyz_r + self.offset(psi_r) * self.cfg.unit
        d = self.kernel(psi_r, psi_o, torch.cdist(xyz_r, xyz_o))
        return (d, xyz_r) if return_headed else d


def _take(x: torch.Tensor, idx: torch.Tensor) -> torch.Tensor:
    return torch.gather(x, 1, idx[..., None].expand(-1, -1, x.shape[-1]))


@dataclass
class Checkpoint:
    """What a weights file holds: the network and how it was trained."""

    net: DRONet
    meta: dict = field(default_factory=dict)


def save_weights(net: DRONet, path: str | Path, meta: dict | None = None) -> Path:
    """The network's parameters as safetensors, with its config (and `meta`) in the header."""
    config = {"format": FORMAT, "config": net.cfg.to_json(), "meta": meta or {}}
    return store.save_weights(path, net.state_dict(), config)


def load_weights(path: str | Path | None = None) -> Checkpoint:
    """The network stored at `path` (default: the shipped weights; a bare name such as
    "dro_no_anchors" is a file of learned/weights/). WeightsError naming the file and the
    retraining command when it is missing, damaged or does not fit."""
    path = Path(path) if path is not None else WEIGHTS
    if path.parent == Path(".") and not path.suffix:
        path = store.weights_path(path.name)
    state, header = store.load_weights(path, RETRAIN, "D(R,O) network")
    try:
        if header.get("format") != FORMAT:
            raise ValueError(f"format {header.get('format')!r}, not {FORMAT!r}")
        cfg = DROConfig.from_json(header["config"])
        net = DRONet(cfg)
        net.load_state_dict(state)
    except (KeyError, ValueError, TypeError, RuntimeError) as err:
        raise store.WeightsError(
            f"D(R,O) weights {path} are of another network "
            f"({type(err).__name__}: {str(err)[:200]}); retrain with `{RETRAIN}`"
        ) from None
    net.eval()
    return Checkpoint(net, header.get("meta", {}))


# ---- from D to hand point targets ----------------------------------------------------------
def input_hand_points(
    hand, wrist: np.ndarray, rng: np.random.Generator | None = None, joint_noise: float = 0.0
) -> np.ndarray:
    """(B, 512, 3) the hand's surface points at `wrist` (B, 7) with the fingers at the open
    pose (plus Gaussian joint noise within the limits, for training): the hand input."""
    wrist = np.asarray(wrist, dtype=np.float64).reshape(-1, 7)
    q = np.repeat(hand.open_pose[None], len(wrist), axis=0).astype(np.float64)
    if rng is not None and joint_noise > 0:
        q = np.clip(q + rng.normal(scale=joint_noise, size=q.shape), hand.lower, hand.upper)
    return hand.surface_points(wrist, q).numpy().astype(np.float32)


_GROUPS: dict[str, RigidGroups] = {}


def rigid_groups(name: str) -> RigidGroups:
    """The named hand's rigid bodies (cached per hand)."""
    if name not in _GROUPS:
        from models.hands import load_hand

        _GROUPS[name] = RigidGroups.of_hand(load_hand(name))
    return _GROUPS[name]


def closeness(d_min: torch.Tensor) -> torch.Tensor:
    """Confidence of a multilaterated point from its smallest predicted distance (m): 1 at
    contact, e^-1 at 1 cm. A far point's neighbours are all predicted about equally far (the
    loss clips distances), so its position is guesswork and should weigh little."""
    return torch.exp(-d_min / 0.01)


def place_hand(
    names: list[str],
    obj_xyz: torch.Tensor,
    d: torch.Tensor,
    index: np.ndarray,
    neighbours: int = 128,
    prior: torch.Tensor | None = None,
    prior_weight: float = 0.01,
    far: float = 0.05,
) -> torch.Tensor:
    """(B, 512, 3) every hand point from the predicted rows d (B, P, M) of the hand points
    `index` (names: each row's hand): multilateration (regularised toward `prior` (B, P, 3),
    the points' input positions, where given), then per-body Kabsch weighted by closeness.
    Bodies with no estimated point are NaN."""
    est = multilaterate(obj_xyz, d, neighbours, prior, prior_weight, far)
    weight = closeness(d.min(dim=-1).values) + 1e-6
    out = torch.empty(len(names), 512, 3, dtype=est.dtype)
    for name in sorted(set(names)):
        sel = np.flatnonzero(np.array(names) == name)
        out[sel] = rigid_fit(rigid_groups(name), est[sel], index, weight[sel])
    return out


# `surface_targets`: the predicted-nearest object points a hand point's target averages, and how
# sharply the average favours the nearest (m: a softmin temperature on predicted distances)
SURFACE_NEIGHBOURS = 8
SURFACE_TEMPERATURE = 0.002
PLACEMENTS = ("multilateration", "surface")


def surface_targets(
    obj_xyz: torch.Tensor,
    obj_normals: torch.Tensor,
    d: torch.Tensor,
    neighbours: int = SURFACE_NEIGHBOURS,
    temperature: float = SURFACE_TEMPERATURE,
) -> torch.Tensor:
    """(B, N, 3) each hand point placed at the object points it is predicted nearest (a
    softmin over its `neighbours` smallest predicted distances d (B, N, M)), pushed out along
    their outward normals (B, M, 3) by the predicted distance.

    The alternative to multilateration (`place_hand`) that eval.dro measures: this network
    overestimates contact distances (true contacts, 6.5 mm median, are predicted 23-26 mm away)
    and blurs them over a patch, so solving for a position from the distances throws contact
    points far; where a row's minimum lies is better known than how far. On 60 test grasps per
    hand (the dataset's wrist and anchors) the closeness-weighted error of the targets the grasp
    program gets fell from 31/35/23 mm to 23/23/18 mm (allegro/leap/shadow), but the grasps
    held at the first try no more often (82/87/68% against 85/87/72%), so the planner keeps
    multilateration (docs/learned_log.md, "Surface targets")."""
    near, idx = torch.topk(d, min(neighbours, d.shape[-1]), dim=-1, largest=False)
    w = torch.softmax(-near / temperature, dim=-1)  # (B, N, k)
    b, n, k = idx.shape
    flat = idx.reshape(b, n * k, 1).expand(-1, -1, 3)
    o = torch.gather(obj_xyz, 1, flat).reshape(b, n, k, 3)
    nrm = torch.gather(obj_normals.to(obj_xyz.dtype), 1, flat).reshape(b, n, k, 3)
    offset = (w * near).sum(-1, keepdim=True)
    return (w[..., None] * o).sum(2) + (w[..., None] * nrm).sum(2) * offset


@dataclass
class Prediction:
    """D(R,O) for one grasp and the hand point targets it implies."""

    distances: np.ndarray  # (512, 512) m, hand point x object input point
    targets: np.ndarray  # (512, 3) every hand point's target (`predict`'s placement)
    closeness: np.ndarray  # (512,) confidence of each target (see `closeness`)
    headed: np.ndarray  # (512, 3) the network's own guess of each point (`DRONet.forward`)
    forward_time: float  # s, network forward only
    total_time: float  # s, hand input + forward + multilateration + Kabsch


@one_thread
@torch.no_grad()
def predict(
    net: DRONet,
    hand,
    wrist: np.ndarray,
    obj_features: np.ndarray,
    text_embedding: np.ndarray,
    obj_normals: np.ndarray | None = None,
    placement: str = "multilateration",
    neighbours: int = 128,
) -> Prediction:
    """The distance matrix and hand point targets for `hand` (models.hands.HandModel) at the
    first stage's `wrist` (7,), the object input (512, 4) (learned.contact_map.object_input)
    and the instruction's embedding (384,) (learned.text.encode). `placement`:
    "multilateration" (`place_hand`: multilateration over `neighbours` object points + per-body
    Kabsch, D(R,O) Grasp's way; what the planner uses) or "surface" (`surface_targets`, needs
    the object input's outward normals `obj_normals` (512, 3): nearer the truth, no more grasps
    held; eval.dro --placement)."""
    if placement not in PLACEMENTS:
        raise DrograspError(f"unknown D(R,O) placement {placement!r}; use one of {PLACEMENTS}")
    if placement == "surface" and obj_normals is None:
        raise DrograspError(
            'placement "surface" needs the object input\'s normals (obj_normals); give them or '
            'use placement "multilateration"'
        )
    start = time.perf_counter()
    hand_in = torch.from_numpy(input_hand_points(hand, wrist))
    obj = torch.as_tensor(np.asarray(obj_features, dtype=np.float32))[None]
    text = torch.as_tensor(np.asarray(text_embedding, dtype=np.float32)).reshape(1, -1)
    t0 = time.perf_counter()
    d, headed = net(hand_in, obj, text, return_headed=True)
    forward = time.perf_counter() - t0
    xyz, dd = obj[..., :3].double(), d.double()
    if placement == "surface":
        normals = torch.as_tensor(np.asarray(obj_normals, dtype=np.float64))[None]
        placed = surface_targets(xyz, normals, dd)
    else:
        placed = place_hand([hand.name], xyz, dd, np.arange(512), neighbours, hand_in.double())
    return Prediction(
        distances=d[0].numpy(),
        targets=placed[0].numpy(),
        closeness=closeness(d[0].min(dim=-1).values).double().numpy(),
        headed=headed[0].double().numpy(),
        forward_time=forward,
        total_time=time.perf_counter() - start,
    )
