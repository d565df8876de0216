"""Node encoders: SCE (coordinates), LSE (line segments), PE (pixels), and the +R CNN."""

from __future__ import annotations

import torch
from torch import Tensor, nn

from strl_pyg.data.sampling import sample_bilinear
from strl_pyg.nn.layout import DenseLayout
from strl_pyg.nn.mlp import mlp, reset_mlp

__all__ = [
    "SpatialCoordinateEncoder",
    "flow_features",
    "parallax_features",
    "INPUT_MODES",
    "LineSegmentEncoder",
    "PixelEncoder",
    "ImageEncoder",
    "sample_at_pixels",
]


class _MLPEncoder(nn.Module):
    in_features: int

    def __init__(self, in_features: int, out_channels: int, hidden: list[int]) -> None:
        super().__init__()
        self.in_features = in_features
        self.out_channels = out_channels
        self.mlp = mlp([in_features, *hidden, out_channels])
        self.reset_parameters()

    def reset_parameters(self) -> None:
        reset_mlp(self.mlp)

    def forward(self, x: Tensor) -> Tensor:
        return self.mlp(x)

    def __repr__(self) -> str:
        return f"{self.__class__.__name__}({self.in_features}, {self.out_channels})"


#: Node inputs of the Spatial Coordinate Encoder: ``"paper"``, the four normalised coordinates
#: ``[x0, y0, x1, y1]`` of the paper; ``"flow"``, those plus the displacement ``u = x1 - x0``
#: and its first-order flow products ``x0 . u`` (divergence: expansion / contraction under
#: forward motion) and ``x0 x u`` (curl: rotation about the optical axis), each feature
#: standardised with fixed per-feature statistics (buffers, stored in the checkpoint);
#: ``"flow2"``, the ``"flow"`` features plus two second-order products that a small rotation
#: about the x and y axes leaves in the flow (:func:`flow_features` with ``order=2``);
#: ``"parallax"``, the ``"flow"`` features plus the motion parallax of each node against its
#: image neighbours and the products whose mean is the epipole's least-squares system
#: (:func:`parallax_features`).
INPUT_MODES = ("paper", "flow", "flow2", "parallax")
#: Neighbours of a node in image 0 whose median displacement :func:`parallax_features`
#: subtracts.
PARALLAX_NEIGHBOURS = 8

#: Per-feature ``(mean, std)`` of the ``"flow"`` inputs before a training set's own statistics
#: are fitted (:meth:`SpatialCoordinateEncoder.fit_standardisation`, which training does): the
#: statistics fitted on the front-end matches of the ``lines_small`` training pairs with image
#: swap (``benchmarks/studies/study_pose_recipe.py``, run ``fe-both-s0``), rounded.
FLOW_DEFAULT_STATS = (
    (-0.013, -0.004, -0.013, -0.004, 0.0, 0.0, -0.012, 0.0),
    (0.307, 0.228, 0.307, 0.228, 0.143, 0.066, 0.059, 0.035),
)
#: The same for the two more features of ``"flow2"`` (fitted likewise: the first 128 training
#: pairs of the Table 3 protocol, 2026-12-04).
FLOW2_EXTRA_STATS = ((0.0, 0.0), (0.080, 0.171))
#: Placeholders for the eight more features of ``"parallax"`` (zero mean, unit scale) until a
#: training set's statistics are fitted, which training always does.
PARALLAX_EXTRA_STATS = ((0.0,) * 8, (1.0,) * 8)


def flow_features(coords: Tensor, order: int = 1) -> Tensor:
    r"""``[x0, y0, x1, y1, u_x, u_y, x0 \cdot u, x0 \times u]`` of ``[N, 4]`` coordinates
    ``[x0, y0, x1, y1]`` (normalised), with ``u = x1 - x0``; ``[N, 8]``.

    With ``order=2`` also :math:`r_x = xy\,u_x + (1 + y^2)\,u_y` and :math:`r_y = -(1 +
    x^2)\,u_x - xy\,u_y` (``x, y`` of image 0); ``[N, 10]``. A small rotation
    :math:`\boldsymbol\omega` moves a point by :math:`A(\mathbf{x})\boldsymbol\omega` with
    :math:`A = \begin{bmatrix} xy & -(1+x^2) & y \\ 1+y^2 & -xy & -x \end{bmatrix}`;
    :math:`(r_x, r_y, -\mathbf{x}_0 \times \mathbf{u})` is :math:`A^\top \mathbf{u}`, whose
    mean over the matches is the right-hand side of the least-squares rotation, while a
    translation parallel to the image moves every point alike (``u`` itself)."""
    x0, x1 = coords[:, :2], coords[:, 2:]
    u = x1 - x0
    div = (x0 * u).sum(-1, keepdim=True)
    curl = x0[:, :1] * u[:, 1:] - x0[:, 1:] * u[:, :1]
    parts = [coords, u, div, curl]
    if order == 2:
        x, y = x0[:, :1], x0[:, 1:]
        ux, uy = u[:, :1], u[:, 1:]
        parts += [x * y * ux + (1 + y * y) * uy, -(1 + x * x) * ux - x * y * uy]
    elif order != 1:
        raise ValueError(f"Expected order 1 or 2 (got {order!r})")
    return torch.cat(parts, dim=-1)


def parallax_features(coords: Tensor, batch: Tensor | None = None,
                      k: int = PARALLAX_NEIGHBOURS, layout: DenseLayout | None = None) -> Tensor:
    r"""Motion parallax of each node against its neighbours in image 0, and the products
    whose mean over the nodes is the epipole's least-squares system; ``[N, 8]`` of ``[N, 4]``
    normalised coordinates ``[x0, y0, x1, y1]`` (``batch``: the graph of each node, ``None``
    for one graph).

    Under a small motion a point moves by :math:`\mathbf{u} = \rho\,(\mathbf{x} t_z -
    \mathbf{t}_{xy}) + A(\mathbf{x})\boldsymbol\omega` (:math:`\rho` its inverse depth). The
    rotation's part varies slowly across the image, so the difference
    :math:`\mathbf{d}` between a node's displacement and the median displacement of its ``k``
    nearest neighbours in image 0 keeps the translation's part alone: it is parallel to
    :math:`\mathbf{x} t_z - \mathbf{t}_{xy}` (Rieger and Lawton, 1985), i.e.
    :math:`\mathbf{a}^\top \mathbf{t} = 0` with :math:`\mathbf{a} = (d_y, -d_x, y d_x - x
    d_y)`. The features are :math:`(d_x, d_y)` and the six products :math:`a_i a_j, i \le j`:
    their mean over the nodes is :math:`\sum \mathbf{a}\mathbf{a}^\top`, whose smallest
    eigenvector is the translation's direction (up to sign), whatever the rotation. The
    handheld pairs that the flow inputs leave unresolved (a small translation beside a
    rotation) are what it is for.

    A node's copies (all four coordinates equal: the fixed-size resampling repeats a sparse
    pair's matches) are not its neighbours, but the copies of other nodes are, so on a pair
    sparser than the resampling the ``k`` slots hold fewer distinct positions, weighted by
    their repetitions. A graph with ``k`` or fewer others uses them all; a node with none
    gets zeros. Equal distances at the ``k``-th place are broken by ``topk`` (positions on a
    pixel lattice can tie). ``k`` is fixed for the mode (:data:`PARALLAX_NEIGHBOURS`; not
    stored in checkpoints). Per graph the distances are dense ``[n, n]`` blocks (nodes of
    one pair, not edges: ~n^2 floats, 0.4 GB at 10k matches), in the model's
    :class:`~strl_pyg.nn.layout.DenseLayout` (``layout``; built from ``batch`` when not given,
    one host read; nodes in any order). Half precision is computed in float32."""
    if coords.dim() != 2 or coords.shape[1] != 4:
        raise ValueError(f"Expected [N, 4] coordinates (got {tuple(coords.shape)})")
    if layout is None:
        layout = DenseLayout.from_batch(batch, coords.shape[0])
    out_dtype = coords.dtype
    if coords.dtype in (torch.float16, torch.bfloat16):  # no half cdist; near points would tie
        coords = coords.float()
    dense_c = layout.to_dense(coords)  # [B, n, 4]
    mask = layout.mask if layout.mask is not None else \
        torch.ones(1, coords.shape[0], dtype=torch.bool, device=coords.device)
    dense_x, dense_u = dense_c[..., :2], dense_c[..., 2:] - dense_c[..., :2]
    B, n = dense_x.shape[:2]
    kk = min(k, n - 1)
    if kk < 1:
        d = coords.new_zeros(coords.shape[0], 2)
    else:
        # [B, n, n], one pair's nodes per block; computed directly (not by a matrix product),
        # so a node and its copies are exactly 0 apart. A copy (the same match repeated by the
        # fixed-size resampling: all four coordinates equal) is never a neighbour: it would
        # pull the parallax to 0. Distinct matches sharing an image-0 point stay neighbours.
        dist = torch.cdist(dense_x, dense_x, compute_mode="donot_use_mm_for_euclid_dist")
        copy = torch.cdist(dense_c, dense_c, compute_mode="donot_use_mm_for_euclid_dist") == 0
        dist = dist.masked_fill(copy | ~mask[:, None, :], float("inf"))
        nbr = dist.topk(kk, dim=-1, largest=False).indices  # [B, n, kk]
        valid = torch.gather(torch.isfinite(dist), -1, nbr)  # neighbours that exist
        nu = torch.gather(dense_u[:, None].expand(B, n, n, 2), 2,
                          nbr[..., None].expand(B, n, kk, 2))  # [B, n, kk, 2]
        # median over the existing neighbours: missing ones sorted to the end, then the
        # middle of the valid count (a graph with fewer than k + 1 nodes)
        big = torch.finfo(nu.dtype).max
        nu = torch.where(valid[..., None], nu, torch.full_like(nu, big)).sort(dim=2).values
        cnt = valid.sum(-1).clamp_min(1)  # [B, n]
        lo = ((cnt - 1) // 2)[..., None, None].expand(B, n, 1, 2)
        hi = (cnt // 2)[..., None, None].expand(B, n, 1, 2)
        med = 0.5 * (torch.gather(nu, 2, lo) + torch.gather(nu, 2, hi))[:, :, 0]
        d = torch.where(valid.any(-1)[..., None], dense_u - med, torch.zeros_like(med))
        d = layout.from_dense(d)
    x0 = coords[:, :2]
    a = torch.stack([d[:, 1], -d[:, 0], x0[:, 1] * d[:, 0] - x0[:, 0] * d[:, 1]], -1)
    i, j = torch.triu_indices(3, 3, device=a.device)
    return torch.cat([d, a[:, i] * a[:, j]], dim=-1).to(out_dtype)


class SpatialCoordinateEncoder(_MLPEncoder):
    r"""Spatial Coordinate Encoder (SCE): :math:`\mathbf{f}^0_{i,N} =
    \mathrm{MLP}([x_0 \Vert y_0 \Vert x_1 \Vert y_1])` on the normalised coordinates of a match
    (point or line endpoint) in image 0 and image 1 (``inputs="paper"``).

    With ``inputs="flow"`` (beyond the paper, the package's default) the MLP reads
    :math:`[x_0, y_0, x_1, y_1, \mathbf{u}, \mathbf{x}_0 \cdot \mathbf{u},
    \mathbf{x}_0 \times \mathbf{u}]` with :math:`\mathbf{u} = \mathbf{x}_1 - \mathbf{x}_0`
    (:func:`flow_features`), each feature standardised by the buffers ``feature_mean`` /
    ``feature_std`` (not trained; :meth:`fit_standardisation` sets them from a training set).
    The displacement that carries the translation is ~0.1 of a normalised image, and a mean
    pool cannot tell expansion from contraction unless a node already holds a product such as
    :math:`\mathbf{x}_0 \cdot \mathbf{u}`.

    Args:
        out_channels (int): Output size :math:`C`.
        inputs (str, optional): ``"paper"``, ``"flow"``, ``"flow2"`` (``"flow"`` and the
            two rotation products of :func:`flow_features`) or ``"parallax"`` (``"flow"`` and
            :func:`parallax_features`, which needs each node's graph). (default: :obj:`"paper"`)

    Shapes:
        - **input:** :math:`(N, 4)` ``[pos0 || pos1]``, normalised coordinates; ``batch``
          :math:`(N,)` or the model's ``layout`` (``"parallax"`` only; neither: one graph)
        - **output:** :math:`(N, C)`
    """

    def __init__(self, out_channels: int, inputs: str = "paper") -> None:
        if inputs not in INPUT_MODES:
            raise ValueError(f"Expected inputs in {INPUT_MODES} (got {inputs!r})")
        self.inputs = inputs
        super().__init__({"paper": 4, "flow": 8, "flow2": 10, "parallax": 16}[inputs],
                         out_channels, [out_channels // 2, out_channels])
        if inputs != "paper":
            extra = {"flow": ((), ()), "flow2": FLOW2_EXTRA_STATS,
                     "parallax": PARALLAX_EXTRA_STATS}[inputs]
            stats = tuple(a + b for a, b in zip(FLOW_DEFAULT_STATS, extra, strict=True))
            mean, std = (torch.tensor(v, dtype=torch.float32) for v in stats)
            self.register_buffer("feature_mean", mean)
            self.register_buffer("feature_std", std)
        else:
            self.feature_mean = self.feature_std = None

    @torch.no_grad()
    def fit_standardisation(self, coords: Tensor, symmetric: bool = True,
                            batch: Tensor | None = None) -> None:
        """Sets ``feature_mean`` / ``feature_std`` from ``[N, 4]`` node coordinates of a
        training set (``inputs="flow"``, ``"flow2"`` or ``"parallax"``; ``batch``: the pair of
        each node, which ``"parallax"`` needs). With ``symmetric`` (training with image swap),
        the statistics are those of the nodes and their swapped copies."""
        if self.inputs == "paper":
            raise ValueError(f"Expected an encoder with inputs='flow', 'flow2' or 'parallax' "
                             f"(got {self.inputs!r})")
        if coords.dim() != 2 or coords.shape[1] != 4 or coords.shape[0] < 2 \
                or not bool(torch.isfinite(coords).all()):
            raise ValueError(f"Expected finite [N >= 2, 4] coordinates "
                             f"(got {tuple(coords.shape)})")
        if batch is not None and tuple(batch.shape) != (coords.shape[0],):
            raise ValueError(f"Expected a batch vector of {coords.shape[0]} entries "
                             f"(got {tuple(batch.shape)})")
        if batch is None and self.inputs == "parallax":
            raise ValueError("Expected the pair (batch vector) of each node for "
                             "inputs='parallax' (got None): neighbours must not cross pairs")
        if symmetric:
            coords = torch.cat([coords, coords[:, [2, 3, 0, 1]]])
            if batch is not None:  # the swapped copy of a pair is a pair of its own
                batch = torch.cat([batch, batch + int(batch.max()) + 1])
        f = self.features(coords.double(), batch)
        assert self.feature_mean is not None and self.feature_std is not None
        self.feature_mean.copy_(f.mean(0))
        self.feature_std.copy_(f.std(0).clamp_min(1e-6))

    def features(self, x: Tensor, batch: Tensor | None = None,
                 layout: DenseLayout | None = None) -> Tensor:
        """The encoder's input features before standardisation (``[N, 4]`` for ``"paper"``;
        ``batch`` / ``layout``: the nodes' graphs, read by ``"parallax"`` only)."""
        if self.inputs == "paper":
            return x
        f = flow_features(x, self._order)
        if self.inputs == "parallax":
            f = torch.cat([f, parallax_features(x, batch, layout=layout)], dim=-1)
        return f

    def forward(self, x: Tensor, batch: Tensor | None = None,
                layout: DenseLayout | None = None) -> Tensor:
        if self.inputs != "paper":
            assert self.feature_mean is not None and self.feature_std is not None
            x = (self.features(x, batch, layout) - self.feature_mean.to(x)) \
                / self.feature_std.to(x)
        return self.mlp(x)

    @property
    def _order(self) -> int:
        return 2 if self.inputs == "flow2" else 1

    def __repr__(self) -> str:
        return f"{self.__class__.__name__}({self.out_channels}, inputs={self.inputs!r})"


class LineSegmentEncoder(_MLPEncoder):
    r"""Line Segment Encoder (LSE): :math:`\mathbf{f}^0_{i,L} = \mathrm{MLP}([x_0 \Vert
    y_0 \Vert \Delta x_0 \Vert \Delta y_0 \Vert x_1 \Vert y_1 \Vert \Delta x_1 \Vert
    \Delta y_1])` on the ``line_feat`` of an endpoint (its normalised coordinates and the offset
    to the other endpoint, in both images).

    Args:
        out_channels (int): Output size :math:`C_L`.

    Shapes:
        - **input:** :math:`(N, 8)`
        - **output:** :math:`(N, C_L)`
    """

    def __init__(self, out_channels: int) -> None:
        super().__init__(8, out_channels, [out_channels])


class PixelEncoder(_MLPEncoder):
    r"""Pixel Encoder (PE): :math:`\mathbf{f}^0_{i,V} =
    \mathrm{MLP}([\mathrm{pixel}(x_0, y_0) \Vert \mathrm{pixel}(x_1, y_1)])` on the pixel
    values (a :math:`p \times p` patch of :math:`c` channels, flattened) sampled at the node in
    both images.

    Args:
        patch_features (int): Features per node and image, :math:`P = c\,p^2`.
        out_channels (int): Output size :math:`C`.

    Shapes:
        - **input:** :math:`(N, 2P)` ``[patch0 || patch1]``
        - **output:** :math:`(N, C)`
    """

    def __init__(self, patch_features: int, out_channels: int) -> None:
        super().__init__(2 * patch_features, out_channels, [out_channels])


def sample_at_pixels(fmap: Tensor, kpts: Tensor, batch: Tensor | None,
                     image_size: tuple[int, int], layout: DenseLayout | None = None) -> Tensor:
    r"""Bilinearly samples per-graph feature maps at node pixel coordinates.

    Pixel convention: OpenCV's, the centre of the top-left pixel of the *image* is ``(0, 0)``;
    the feature map may have a lower resolution and covers the same field of view (the
    package's one sampler, :func:`strl_pyg.data.sampling.sample_bilinear`).

    Args:
        fmap: feature maps, shape :math:`(B, C, h, w)`.
        kpts: pixel coordinates ``(x, y)`` in the image, shape :math:`(N, 2)`.
        batch: graph id of each node, shape :math:`(N)`, sorted, or :obj:`None` (one graph).
        image_size: ``(H, W)`` of the image the coordinates refer to.
        layout: the :class:`~strl_pyg.nn.DenseLayout` of the nodes, in place of ``batch``
            (no host synchronisation); ``None``: built from ``batch``.

    Returns:
        sampled features, shape :math:`(N, C)`; zeros padding outside the image.
    """
    B = fmap.shape[0]
    if kpts.shape[0] == 0:
        return fmap.new_zeros(0, fmap.shape[1])
    if layout is None:
        if batch is None:
            batch = kpts.new_zeros(kpts.shape[0], dtype=torch.long)
        layout = DenseLayout.from_batch(batch, kpts.shape[0], B)
    if layout.num_graphs != B:
        raise ValueError(f"Expected one feature map per graph (got {B} maps for "
                         f"{layout.num_graphs} graphs)")
    out = sample_bilinear(fmap, layout.to_dense(kpts), image_size, padding="zeros")  # [B, C, L]
    return layout.from_dense(out.transpose(1, 2))


class ImageEncoder(nn.Module):
    r"""A small convolutional image encoder for the ``+R`` ablation rows.

    The paper's ``+R`` rows use an ImageNet-pretrained ResNet-34. Pretrained weights cannot be
    downloaded in this project's environment, so this is a randomly initialised 4-stage CNN
    (stride 8 overall, ``3x3`` convolutions, GroupNorm, ReLU) trained end to end with the rest
    of the model. Its output is sampled bilinearly at the node pixels of both images
    (:func:`sample_at_pixels`) and embedded by an MLP into the visual stream. Expect ``+R``
    figures to differ from the paper's for this reason.

    Args:
        in_channels (int): Image channels :math:`c`.
        out_channels (int): Node feature size :math:`C`.
        width (int, optional): Channels of the first stage, doubled per stride-2 stage.
            (default: :obj:`32`)

    Shapes:
        - **input:** images :math:`(B, c, H, W)`
        - **output:** feature maps :math:`(B, C_f, \lceil H/8 \rceil, \lceil W/8 \rceil)` with
          :math:`C_f` = ``feature_channels``
    """

    def __init__(self, in_channels: int, out_channels: int, width: int = 32) -> None:
        super().__init__()
        self.in_channels = in_channels
        self.out_channels = out_channels
        self.width = width
        chans = [in_channels, width, width, 2 * width, 4 * width]
        strides = [1, 2, 2, 2]
        layers: list[nn.Module] = []
        for i, s in enumerate(strides):
            layers += [
                nn.Conv2d(chans[i], chans[i + 1], 3, stride=s, padding=1),
                nn.GroupNorm(8, chans[i + 1]),
                nn.ReLU(inplace=True),
            ]
        self.cnn = nn.Sequential(*layers)
        self.feature_channels = chans[-1]
        self.embed = mlp([2 * self.feature_channels, out_channels, out_channels])
        self.reset_parameters()

    def reset_parameters(self) -> None:
        reset_mlp(self.cnn)
        reset_mlp(self.embed)

    def forward(self, image: Tensor) -> Tensor:
        return self.cnn(image)

    def encode_nodes(self, image0: Tensor, image1: Tensor, kpts0: Tensor, kpts1: Tensor,
                     batch: Tensor | None, layout: DenseLayout | None = None) -> Tensor:
        """Node features :math:`(N, C)` from images :math:`(B, c, H, W)` and the nodes' pixel
        coordinates :math:`(N, 2)` in image 0 and image 1 (``layout``: see
        :func:`sample_at_pixels`)."""
        size0 = (int(image0.shape[-2]), int(image0.shape[-1]))
        size1 = (int(image1.shape[-2]), int(image1.shape[-1]))
        f0 = sample_at_pixels(self(image0), kpts0, batch, size0, layout)
        f1 = sample_at_pixels(self(image1), kpts1, batch, size1, layout)
        return self.embed(torch.cat([f0, f1], dim=-1))

    def __repr__(self) -> str:
        return f"{self.__class__.__name__}({self.in_channels}, {self.out_channels})"
